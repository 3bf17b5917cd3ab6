"""The package is a pipeline: every import points down it, and there is no import cycle.

Every module's imports are read from its source (``ast``, module level and inside
functions alike), so a late import inside a function counts too. Layers, lowest first:

    errors, scipy_ext → machine → geometry → program, servo → plan → precompensation
    → interpolate → studies, output → pipeline → app → cli

A module may import its own layer or a lower one. Within a layer, modules of different
packages (program and servo; studies and output) do not import each other. Nothing imports
``cli`` but ``cli`` itself and the ``python -m nurbscnc`` entry point.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "nurbscnc"

#: Rank of each top-level part of the package; lower ranks never import higher ones.
RANK = {
    "errors": 0,
    "scipy_ext": 0,  # scipy's compiled kernels loaded alone; imports nothing of nurbscnc
    "machine": 1,
    "geometry": 2,
    "program": 3,
    "servo": 3,
    "plan": 4,
    "precompensation": 4.5,  # the stage after planning: applies servo's inverse to a plan
    "interpolate": 5,
    "studies": 6,
    "output": 6,
    "controller": 6.5,  # runs a job: drives output's link and card, quantises with output
    "pipeline": 7,
    "app": 7.5,  # the application layer: loading, planning and reports for the commands
    "cli": 8,
    "__main__": 9,
    "__init__": 0,
}


def module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def imports_of(path: Path, module: str = "nurbscnc.x") -> set[str]:
    """The nurbscnc modules the source ``path`` of ``module`` imports (absolute names;
    relative imports resolved against ``module``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    here = module.split(".")
    package = here if path.name == "__init__.py" else here[:-1]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[: len(package) - node.level + 1] + ([base] if base else []))
            found.add(base)
            found.update(f"{base}.{a.name}" for a in node.names)
    return {m for m in found if m == "nurbscnc" or m.startswith("nurbscnc.")}


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def existing(name: str) -> str | None:
    """The module a dotted import name refers to (``a.b.c`` may be the name ``c`` in ``a.b``)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def part(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


GRAPH = {
    m: {t for t in map(existing, imports_of(p, m)) if t and t != m} for m, p in MODULES.items()
}


def test_every_part_has_a_rank():
    assert {part(m) for m in MODULES} <= set(RANK)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_point_down_the_pipeline(module):
    mine = part(module)
    for target in sorted(GRAPH[module]):
        theirs = part(target)
        if theirs in ("__init__",) or theirs == mine:
            continue
        assert RANK[theirs] < RANK[mine], f"{module} imports {target} ({mine} → {theirs})"


def test_no_import_cycles():
    """Depth-first search for a back edge; the cycle is reported if found."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for t in sorted(GRAPH[m]):
            if state.get(t) == 1:
                cycle = stack[stack.index(t) :] + [t]
                pytest.fail("import cycle: " + " → ".join(cycle))
            if t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(MODULES):
        if m not in state:
            visit(m)


def test_the_rule_catches_an_upward_import(tmp_path):
    """The reader sees imports inside functions and relative imports (a test of the test)."""
    src = tmp_path / "x.py"
    src.write_text(
        "def f():\n    from nurbscnc.interpolate.sample import Samples\n"
        "from ..interpolate import taylor\n"
    )
    found = {existing(m) for m in imports_of(src, "nurbscnc.plan.x")}
    assert found == {
        "nurbscnc.interpolate.sample",
        "nurbscnc.interpolate.taylor",
        "nurbscnc.interpolate",
    }
    assert RANK[part("nurbscnc.interpolate.sample")] > RANK[part("nurbscnc.plan.x")]
