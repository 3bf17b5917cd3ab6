"""scipy's compiled kernels without the packages around them (import what a
command needs).

Importing ``scipy.signal`` costs 1–3 s of CPU (it pulls in scipy.stats, optimize, spatial,
…) and ``scipy.optimize`` 0.4–0.8 s (scipy.linalg, sparse, …), each for one compiled loop
that takes milliseconds: the IIR filter behind ``scipy.signal.lfilter``
(``scipy/signal/_sigtools``) and Brent's root finder behind ``scipy.optimize.brentq``
(``scipy/optimize/_zeros``). Those extension modules need numpy at most, so each is loaded on
its own, from scipy's own folder: the same code, the same bits. The callers fall back to the
public functions where scipy's layout differs (:func:`extension` gives None).
"""

from __future__ import annotations

import functools
import importlib.machinery
import importlib.util
from pathlib import Path


@functools.cache
def extension(subpackage: str, name: str):
    """scipy's compiled module ``scipy.<subpackage>.<name>`` loaded by itself (its package's
    ``__init__`` not run), or None when this scipy has no such file. scipy's own
    ``__init__`` is not run either (its version checks and configuration: 15 ms of CPU); an
    extension that needs the package imports it itself."""
    spec = importlib.util.find_spec("scipy")
    if spec is None or not spec.submodule_search_locations:
        return None  # pragma: no cover (no scipy: a dependency)
    folder = Path(spec.submodule_search_locations[0]) / subpackage
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        path = folder / f"{name}{suffix}"
        if path.is_file():
            spec = importlib.util.spec_from_file_location(f"scipy.{subpackage}.{name}", path)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            return module
    return None  # pragma: no cover (another scipy layout)
