"""The package stays decomposed: one job per file, one step per function.

Read from the sources (``ast``), so the limits hold for every module, new ones included:
no module over 700 lines (the look-ahead loop under 400, each command module under 400), no
function over 120 lines, no private name imported from another top-level package, and no
reflection over callables in ``plan/`` (the reference sampler is an explicit interface).
Cyclomatic complexity (≤ 25 per function) is ruff's ``C901`` rule, run by ``make lint``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "nurbscnc"
SOURCES = sorted(PACKAGE.rglob("*.py"))

MAX_FILE_LINES = 700
MAX_FUNCTION_LINES = 120
#: Modules whose job is narrower than a file's: the planner's loop and the commands.
NARROW = {"plan/lookahead.py": 400}
NARROW_DIRS = {"cli": 400}


def rel(path: Path) -> str:
    return path.relative_to(PACKAGE).as_posix()


def line_limit(path: Path) -> int:
    name = rel(path)
    if name in NARROW:
        return NARROW[name]
    top = name.split("/")[0]
    return NARROW_DIRS.get(top, MAX_FILE_LINES)


@pytest.mark.parametrize("path", SOURCES, ids=rel)
def test_module_length(path):
    lines = path.read_text(encoding="utf-8").count("\n")
    assert lines <= line_limit(path), f"{rel(path)}: {lines} lines (limit {line_limit(path)})"


def test_c_sources_length():
    for path in sorted(PACKAGE.rglob("*.[ch]")):
        lines = path.read_text(encoding="utf-8").count("\n")
        assert lines <= MAX_FILE_LINES, f"{rel(path)}: {lines} lines"


@pytest.mark.parametrize("path", SOURCES, ids=rel)
def test_function_length(path):
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    long = [
        f"{node.name} (line {node.lineno}): {node.end_lineno - node.lineno + 1} lines"
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and node.end_lineno - node.lineno + 1 > MAX_FUNCTION_LINES
    ]
    assert not long, f"{rel(path)}: " + "; ".join(long)


def absolute(node: ast.ImportFrom, path: Path) -> str:
    """The absolute module name of a ``from … import`` in ``path``."""
    if not node.level:
        return node.module or ""
    here = ["nurbscnc", *path.relative_to(PACKAGE).with_suffix("").parts]
    package = here[:-1]
    base = package[: len(package) - node.level + 1]
    return ".".join(base + ([node.module] if node.module else []))


def top(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


@pytest.mark.parametrize("path", SOURCES, ids=rel)
def test_no_private_name_across_packages(path):
    mine = rel(path).split("/")[0].removesuffix(".py")
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.ImportFrom):
            continue
        module = absolute(node, path)
        if not module.startswith("nurbscnc.") or top(module) == mine:
            continue
        private = [p for p in module.split(".") if p.startswith("_") and not p.startswith("__")]
        private += [
            a.name for a in node.names if a.name.startswith("_") and not a.name.startswith("__")
        ]
        found += [f"{module}: {name}" for name in private]
    assert not found, f"{rel(path)} imports private names of another package: {found}"


@pytest.mark.parametrize("path", sorted((PACKAGE / "plan").rglob("*.py")), ids=rel)
def test_plan_does_not_probe_callables(path):
    """The planner calls its sampler through the declared interface: no ``inspect``, no
    attributes looked up or set on a function by name."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import | ast.ImportFrom):
            names = [a.name for a in node.names] + [getattr(node, "module", None) or ""]
            assert "inspect" not in names, f"{rel(path)}:{node.lineno} imports inspect"
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) in ("getattr", "hasattr"):
            target = node.args[0]
            assert not (isinstance(target, ast.Name) and "sampler" in target.id), (
                f"{rel(path)}:{node.lineno} probes the sampler by name"
            )


MAX_COMPLEXITY = 25


@pytest.mark.parametrize("path", SOURCES, ids=rel)
def test_cyclomatic_complexity(path):
    """McCabe's complexity as radon counts it (each branch, loop, handler, boolean operator
    and comprehension condition adds one), at most 25 per function or method."""
    from radon.complexity import cc_visit

    blocks = cc_visit(path.read_text(encoding="utf-8"))
    functions = [b for b in blocks if hasattr(b, "is_method")]
    functions += [m for b in blocks for m in getattr(b, "methods", ())]
    over = sorted(
        {
            f"{f.name} (line {f.lineno}): {f.complexity}"
            for f in functions
            if f.complexity > MAX_COMPLEXITY
        }
    )
    assert not over, f"{rel(path)}: " + "; ".join(over)
