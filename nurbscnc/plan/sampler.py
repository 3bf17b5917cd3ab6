"""The contract between the planner's dynamics check and the reference it simulates
(:class:`ReferenceSampler`): the points a plan's servo samples k0 … k1 − 1 are, whether any
window of them can be made alone, and a hook as each check begins.

The check (:class:`~nurbscnc.plan.check.Checker`) reads :attr:`ReferenceSampler.windowed`
and calls :meth:`ReferenceSampler.check_begins` directly; it never probes a sampler. The
default is the plan's exact reference (:data:`EXACT`); the interpolator's sampler
(:func:`nurbscnc.interpolate.sample.reference_sampler`), the pre-compensated one and a
progress display's wrapper are instances too.
"""

from __future__ import annotations

from collections.abc import Callable

from nurbscnc.plan.options import Interpolator
from nurbscnc.plan.timing import Reference, exact_reference


class ReferenceSampler:
    """A reference sampler: ``sampler(pieces, profile, period_s, k0=0, k1=None)`` →
    :class:`~nurbscnc.plan.timing.Reference`, the reference points of servo samples
    k0 … k1 − 1 of the plan ``pieces``/``profile`` at the period ``period_s`` [s] (default:
    all of them). This base class is the exact sampler
    (:func:`~nurbscnc.plan.timing.exact_reference`).

    ``windowed``: the sampler gives any window [k0, k1) of its samples exactly (the rows of
    the whole reference, bit for bit), so the check may sample a plan window by window; a
    sampler that is not (a sequential recurrence, a non-causal filter) is called once per
    check with k0 = 0, k1 = None. ``interpolator``: how its NURBS points are made
    (:class:`~nurbscnc.plan.options.Interpolator`; None: not an interpolator's).
    ``causal``: a row depends on its own wall time and the plan up to it only (the plan's
    profile and dwells before that time), so a re-plan that changed the plan from some
    time on leaves the rows before it alike and the check may keep them; a sampler whose
    rows see the plan after them (the pre-compensated reference: each cut window inverted
    and optimised as a whole) is not."""

    windowed: bool = True
    interpolator: Interpolator | None = Interpolator.EXACT
    causal: bool = True

    def __call__(
        self, pieces, profile, period_s: float, k0: int = 0, k1: int | None = None
    ) -> Reference:
        return exact_reference(pieces, profile, period_s, k0, k1)

    def check_begins(self, k0: int) -> None:
        """Called as each dynamics check of a plan begins at servo sample ``k0`` (0: the
        whole plan's or the first cut window's; a re-plan may check only from where its
        plan changed). A progress display's hook; nothing here."""


#: The plan's exact reference: the planner's default sampler.
EXACT = ReferenceSampler()


class FunctionSampler(ReferenceSampler):
    """A function ``sample(pieces, profile, period_s, k0, k1)`` → Reference as a
    :class:`ReferenceSampler` that says explicitly whether it is ``windowed``, which
    ``interpolator`` it samples with and whether it is ``causal``."""

    def __init__(
        self,
        sample: Callable[..., Reference],
        windowed: bool,
        interpolator: Interpolator | None = None,
        causal: bool = True,
    ):
        self.sample = sample
        self.windowed = bool(windowed)
        self.interpolator = interpolator
        self.causal = bool(causal)

    def __call__(
        self, pieces, profile, period_s: float, k0: int = 0, k1: int | None = None
    ) -> Reference:
        return self.sample(pieces, profile, period_s, k0, k1)


class ForwardingSampler(ReferenceSampler):
    """The sampler ``inner``, its samples, ``windowed`` and ``interpolator`` passed through;
    ``check_begins(k0)`` calls ``hook`` if given (a progress display), else ``inner``'s."""

    def __init__(self, inner: ReferenceSampler, hook: Callable[[int], None] | None = None):
        self.inner = inner
        self.windowed = inner.windowed
        self.interpolator = inner.interpolator
        self.causal = inner.causal
        self.hook = hook

    def __call__(
        self, pieces, profile, period_s: float, k0: int = 0, k1: int | None = None
    ) -> Reference:
        return self.inner(pieces, profile, period_s, k0, k1)

    def check_begins(self, k0: int) -> None:
        if self.hook is not None:
            self.hook(k0)
        else:
            self.inner.check_begins(k0)


def as_sampler(reference) -> ReferenceSampler:
    """``reference`` as a :class:`ReferenceSampler`: itself if it is one; a plain function
    (pieces, profile, period_s[, k0, k1]) → Reference promises no windows, so it is
    evaluated whole (called as (pieces, profile, period_s))."""
    if isinstance(reference, ReferenceSampler):
        return reference
    return FunctionSampler(
        lambda pieces, profile, period_s, k0=0, k1=None: reference(pieces, profile, period_s),
        windowed=False,
    )
