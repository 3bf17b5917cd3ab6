"""The build's one compiled piece: nurbscnc.plan._kernels (nurbscnc/plan/_kernels.c, the
CPython glue, which includes the numerics of nurbscnc/plan/_kernels_math.h), the plan
stage's loops that numpy cannot vectorise (the profile's gated flanks, times at a length
and peak speeds, the check's point-to-segment distances). Optional: where no C
compiler is found the package installs without it and their Python implementations run
(the same numbers, bit for bit; nurbscnc/plan/compiled.py; docs/benchmarks.md gives the
speeds). Everything else is in pyproject.toml."""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "nurbscnc.plan._kernels",
            ["nurbscnc/plan/_kernels.c"],
            depends=["nurbscnc/plan/_kernels_math.h"],  # included by _kernels.c
            # The same IEEE double operations as the Python reference: no fused
            # multiply-add, no reassociation (-ffast-math is never on).
            extra_compile_args=["-O2", "-ffp-contract=off", "-fno-fast-math"],
            optional=True,
        )
    ]
)
