"""The plan stage's compiled kernels, or None.

``setup.py`` builds :mod:`nurbscnc.plan._kernels` from ``_kernels.c`` where a C compiler is
found (optional: without one the package installs anyway). Each module that has a kernel
keeps its Python reference implementation, which gives the same numbers bit for bit and
runs where ``kernels`` is None (tests/test_plan_kernels.py compares the two)."""

try:
    from nurbscnc.plan import _kernels as kernels
except ImportError:  # pragma: no cover - a build without a C compiler
    kernels = None
