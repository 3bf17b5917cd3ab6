"""The plan stage's compiled kernels, or None, and the buffers they read.

``setup.py`` builds :mod:`nurbscnc.plan._kernels` from ``_kernels.c`` (the CPython glue) and
``_kernels_math.h`` (the numerics) where a C compiler is found (optional: without one the
package installs anyway). Each module that has a kernel keeps its Python reference
implementation, which gives the same numbers bit for bit and runs where ``kernels`` is None
(tests/test_plan_kernels.py compares the two)."""

import numpy as np

try:
    from nurbscnc.plan import _kernels as kernels
except ImportError:  # pragma: no cover - a build without a C compiler
    kernels = None

#: The kernels this source expects: a module built from an older ``_kernels.c`` (a checkout
#: updated without ``make install``) lacks some, and is then not used at all.
KERNELS = ("peak_speeds", "gated_rise", "gated_rise_merged", "time_at_length")
if kernels is not None and not all(hasattr(kernels, name) for name in KERNELS):
    kernels = None


def as_float64(x) -> np.ndarray:
    """``x`` as a C-contiguous float64 array (the compiled kernels read its bytes)."""
    return np.ascontiguousarray(x, dtype=np.float64)
