"""The geometry stage's compiled kernel, or None.

``setup.py`` builds :mod:`nurbscnc.geometry._kernels` from ``_kernels.c`` where a C compiler
is found (optional: without one the package installs anyway). Each of its kernels, the
point-to-segments distance (:func:`nurbscnc.geometry.distance.segment_distances`), the
B-spline basis derivatives (:func:`nurbscnc.geometry.bspline.basis_derivatives`), the step
of the PH quintics' safeguarded Newton iteration (:func:`nurbscnc.geometry.ph.bracketed_newton`),
the PH quintics' foot points (:meth:`nurbscnc.geometry.ph.PHQuintic.closest_param`) and the
NURBS derivatives (:meth:`nurbscnc.geometry.nurbs.NurbsCurve.derivatives`) and the
spiral arcs' arc-length inversion (:func:`nurbscnc.geometry.segments.spiral_t_at_length`),
keeps its Python reference implementation, which gives the same numbers bit for bit and runs
where ``kernels`` is None (tests/test_plan_kernels.py compares the two). A module of its own,
apart from :mod:`nurbscnc.plan.compiled`, so that geometry imports nothing of the plan."""

try:
    from nurbscnc.geometry import _kernels as kernels
except ImportError:  # pragma: no cover - a build without a C compiler
    kernels = None

#: The kernels this source expects: a module built from an older ``_kernels.c`` (a checkout
#: updated without ``make install``) lacks some, and is then not used at all.
KERNELS = (
    "segment_distances",
    "basis_derivatives",
    "newton_step",
    "ph_closest",
    "nurbs_derivatives",
    "nurbs_derivatives_at",
    "powerform_speed",
    "spiral_t",
)
if kernels is not None and not all(hasattr(kernels, name) for name in KERNELS):
    kernels = None
