"""The build's compiled pieces: nurbscnc.plan._kernels (nurbscnc/plan/_kernels.c, the
CPython glue, which includes the numerics of nurbscnc/plan/_kernels_math.h), the plan stage's
loops that numpy cannot vectorise (the profile's gated flanks, times at a length and peak
speeds), and nurbscnc.geometry._kernels (nurbscnc/geometry/_kernels.c), the point-to-segment
distances of the contour check. Optional: where no C compiler is found the package installs
without them and their Python implementations run (the same numbers, bit for bit;
nurbscnc/plan/compiled.py, nurbscnc/geometry/compiled.py; docs/benchmarks.md gives the
speeds). Everything else is in pyproject.toml."""

from setuptools import Extension, setup

# The same IEEE double operations as the Python reference: no fused multiply-add, no
# reassociation (-ffast-math is never on).
FLAGS = ["-O2", "-ffp-contract=off", "-fno-fast-math"]

setup(
    ext_modules=[
        Extension(
            "nurbscnc.plan._kernels",
            ["nurbscnc/plan/_kernels.c"],
            depends=["nurbscnc/plan/_kernels_math.h"],  # included by _kernels.c
            extra_compile_args=FLAGS,
            optional=True,
        ),
        Extension(
            "nurbscnc.geometry._kernels",
            ["nurbscnc/geometry/_kernels.c"],
            depends=["nurbscnc/geometry/_kernels_spiral.h"],  # included by _kernels.c
            extra_compile_args=FLAGS,
            optional=True,
        ),
    ]
)
