"""What every benchmark results file records about the run: machine, versions, commit, date.

Also the corpus finder shared by the benchmarks (``$NURBSCNC_CORPUS``, by default
``../shared/corpus`` next to the repository, as the tests find it).
"""

from __future__ import annotations

import datetime as dt
import os
import platform
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _cpu_model() -> str | None:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or None


def _memory_gb() -> float | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return round(int(line.split()[1]) / 1e6, 2)
    except OSError:
        pass
    return None


def _version(module: str) -> str | None:
    try:
        return __import__(module).__version__
    except Exception:  # noqa: BLE001 - a missing module is recorded as None
        return None


def use_bytecode() -> None:
    """Give the benchmark's child processes the bytecode a user's installation has (pip
    compiles a package at install; an editable install writes it on first import): without
    it, under ``PYTHONDONTWRITEBYTECODE`` (set in some shells, and in this workplace's),
    every ``nurbscnc`` process compiled the package's 60 modules again, 0.24 s of each
    measured start. The cache goes to ``out/pycache`` (``PYTHONPYCACHEPREFIX``), filled
    once here by ``compileall``; the children inherit the environment."""
    import sys

    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
    os.environ["PYTHONPYCACHEPREFIX"] = str(ROOT / "out" / "pycache")
    subprocess.run(
        [sys.executable, "-m", "compileall", "-q", str(ROOT / "nurbscnc")],
        check=False,
        capture_output=True,
    )


def git_commit() -> str | None:
    """The checked-out commit (with ``-dirty`` when the tree has changes), or None."""
    try:
        sha = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=ROOT,
            capture_output=True,
            text=True,
        ).stdout.strip()
        return sha + ("-dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return None


def run_info() -> dict:
    """Date (UTC), machine (CPU model, cores, memory, load), versions, git commit."""
    try:
        load = list(os.getloadavg())
    except OSError:
        load = None
    return {
        "date": dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "git_commit": git_commit(),
        "machine": {
            "platform": platform.platform(),
            "cpu": _cpu_model(),
            "cores": os.cpu_count(),
            "memory_gb": _memory_gb(),
            "load_average_1_5_15": load,
        },
        "versions": {
            "python": platform.python_version(),
            "numpy": _version("numpy"),
            "scipy": _version("scipy"),
            "nurbscnc": _version("nurbscnc"),
        },
    }


def corpus_dir() -> Path:
    """The corpus folder (``$NURBSCNC_CORPUS`` or ``../shared/corpus``), resolved."""
    default = ROOT / ".." / "shared" / "corpus"
    return Path(os.environ.get("NURBSCNC_CORPUS") or default).resolve()


def corpus_program(relative: str) -> Path | None:
    """A corpus program by its path below the corpus (e.g. ``general/tort.ngc``), looked up
    directly and then anywhere below the corpus (it may sit under a source folder); None
    when the corpus or the program is absent."""
    corpus = corpus_dir()
    if not corpus.is_dir():
        return None
    direct = corpus / relative
    if direct.is_file():
        return direct
    found = sorted(
        p for p in corpus.rglob(Path(relative).name) if p.as_posix().endswith("/" + relative)
    )
    return found[0] if found else None


def linuxcnc_version() -> str | None:
    """The installed LinuxCNC package and version (``dpkg-query``), None without it."""
    try:
        return subprocess.run(
            ["dpkg-query", "-W", "-f", "${Package} ${Version}", "linuxcnc-uspace"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
