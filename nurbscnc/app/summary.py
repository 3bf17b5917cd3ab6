"""The summaries of a command as data: the plan summary of a run, its JSON text, the
machine-profile and error objects of the JSON output (docs/json.md), and the summary's
figures as text."""

from __future__ import annotations

import json


def machine_json(mach) -> dict:
    """``{"machine_profile": {path, found_by, contour_check}}`` for a command's JSON."""
    from nurbscnc.machine.profile import profile_info

    return {"machine_profile": profile_info(mach)}


def error_json(exc) -> dict:
    """The JSON of a :class:`~nurbscnc.errors.NurbsCncError` (its position, if any)."""
    pos = exc.pos
    entry = {
        "line": pos.line if pos else None,
        "column": pos.column if pos else None,
        "message": exc.message,
    }
    return {"ok": False, "errors": [entry]}


def usage_error_json(message: str) -> dict:
    """The JSON of an option error (docs/json.md): the shape of a program error, without a
    position."""
    return {"ok": False, "errors": [{"line": None, "column": None, "message": message}]}


def summary_of(prog, mach, run, stats=None, lower_bound: bool = True) -> dict:
    """The plan summary of a run (:func:`nurbscnc.plan.report.plan_summary`). ``stats``: the
    :class:`~nurbscnc.plan.report.SampleStats` gathered while the points were written (None:
    gathered here, window by window, without whole arrays); a baseline is simulated on its
    whole samples. ``lower_bound``: with the kinematic lower bound (the JSON has it)."""
    from nurbscnc.plan.report import SampleStats, plan_summary

    if run.rest_s is not None:  # no motion
        rest = with_rotary(
            rest_summary(prog, mach, run),
            prog.rotary_axes,
            _end_abc_deg(prog),
        )
        return {**rest, **machine_json(mach)}
    samples = run.samples if run.plan is None else stats
    if samples is None:
        samples = SampleStats(run.plan)
        for window in run.chunks():
            samples.add(window)
    summary = plan_summary(
        prog,
        mach,
        samples,
        run.plan,
        run.check,
        run.algorithm,
        run.cycle_time_s,
        lower_bound,
        run.columns,
    )
    if getattr(run, "precompensation", None) is not None:  # --precompensate
        summary["precompensation"] = run.precompensation.as_json()
    summary = with_rotary(summary, prog.rotary_axes, _end_abc_deg(prog))
    return {**summary, **machine_json(mach)}


def _end_abc_deg(prog) -> tuple:
    """Where the program leaves A B C [deg] (:func:`~nurbscnc.program.columns.end_abc_deg`;
    imported here: the CLI loads this module without numpy)."""
    from nurbscnc.program.columns import end_abc_deg

    return end_abc_deg(prog.segments, prog.start_abc_deg)


def rotary_note(rotary_axes) -> str:
    """What the contour check does not see when the program's ``rotary_axes`` (e.g.
    ``("b",)``) turn the part (``rotary.note``), in the words of its first axis: an error
    of δ° on it is an arc of r·δ·π/180 mm at radius r."""
    letter = rotary_axes[0].upper()
    return (
        "the contour check covers X Y Z only: it does not see the tool's position on a rotated "
        f"part (an error of δ° on {letter} is r·δ·π/180 mm at radius r)"
    )


def with_rotary(summary: dict, rotary_axes, abc_deg) -> dict:
    """``summary`` with its ``rotary`` object (docs/json.md) when the program uses rotary
    axes: ``axes`` (e.g. ``["a"]``), ``final_abc_deg`` (``{"a": 90.0}``: each axis used at
    the end [deg], ``abc_deg`` (3,) A B C), ``contour_check`` ``"xyz"`` and the ``note``
    saying what that check does not see; the planner's own entries of the object, when it
    made one, are kept. A program without rotary axes: ``summary`` as it is."""
    if not rotary_axes:
        return summary
    rotary = dict(summary.get("rotary") or {})
    rotary.setdefault("axes", list(rotary_axes))
    rotary["final_abc_deg"] = {a: float(abc_deg["abc".index(a)]) for a in rotary_axes}
    rotary.setdefault("contour_check", "xyz")
    rotary.setdefault("note", rotary_note(rotary_axes))
    return {**summary, "rotary": rotary}


def rotary_text(summary: dict) -> str | None:
    """The human line of a summary with a ``rotary`` object (None without): the axes, where
    they end, the rotary-only moves when the planner counted them, and what the contour
    check does not see. The check measures the X Y Z reference against the X Y Z path; on
    a part the rotary axes turn, an error of δ degrees on an axis moves the surface under the
    tool by r·δ·π/180 mm at radius r (the tool's position on the rotated part is not
    checked)."""
    rotary = summary.get("rotary")
    if not rotary:
        return None
    ends = " ".join(f"{a.upper()}{v:g}°" for a, v in rotary["final_abc_deg"].items())
    moves = ""
    if "rotate_moves" in rotary:
        count = rotary["rotate_moves"]
        noun = "move" if count == 1 else "moves"
        moves = f"{count} rotary-only {noun}, {rotary['rotate_time_s']:.4f} s; "
    names = " ".join(a.upper() for a in rotary["axes"])
    return f"  rotary axes {names} (end at {ends}): {moves}{rotary['note']}"


def rest_summary(prog, mach, run) -> dict:
    """The summary of a program with no motion (offsets, tool changes, dwells): ``motion``
    false, the tool at rest at its start point for the dwells' time. Nothing moves, so the
    servo, at rest there from the start, follows without error: the contour errors are 0
    exactly (no simulation needed); the cycle time and its kinematic lower bound are the
    dwells' time (the points last till the first servo period at or after it)."""
    t_s = run.rest_s
    return {
        "ok": True,
        "program": prog.name,
        "algorithm": str(run.algorithm),
        "motion": False,
        "rest_position_mm": [float(v) for v in prog.start_mm],
        "cycle_time_s": t_s,
        "samples": run.sample_count,
        "period_s": mach.servo.period_s,
        "feed_max_mm_s": 0.0,
        "lower_bound_s": t_s,
        "lower_bound_ratio": 1.0 if t_s > 0 else None,
        "contour_true_max_um": 0.0,
        "contour_true_rms_um": 0.0,
        "contour_eq29_max_um": 0.0,
    }


def rest_text(summary: dict) -> str:
    """The human line of a program with no motion (:func:`rest_summary`)."""
    x, y, z = summary["rest_position_mm"]
    return (
        f"no motion (offsets, tool changes or dwells only): the tool rests at "
        f"X{x:g} Y{y:g} Z{z:g} mm for {summary['cycle_time_s']:.4f} s "
        f"({summary['samples']} reference points at T_s = {summary['period_s'] * 1000:g} ms)"
    )


def summary_json(summary: dict) -> str:
    """The JSON text of a summary, the cycle collector paused while it is made: a long
    program's 200,000 per-line times make as many strings, which set off full collections
    that walk every object of the run (two, 0.08 s, on the 200k spiral) and find nothing —
    the encoder makes no cycles."""
    from nurbscnc.program.fastlane import pause_cyclic_gc

    with pause_cyclic_gc():
        return json_in_pieces(summary)


#: Entries of a large mapping encoded per ``json.dumps`` call by :func:`json_in_pieces`.
JSON_PIECE = 8192


def json_in_pieces(summary: dict) -> str:
    """``json.dumps(summary)``, the same text, with the large mappings (a long program's
    per-line times) encoded :data:`JSON_PIECE` entries per call: the C encoder holds the
    interpreter lock for a whole call, and ``run`` encodes while its output is being
    finished in the other thread (:func:`nurbscnc.app.output.write_output`), which needs the
    lock now and then. A mapping's text is its entries' joined by ", " inside braces, as
    json.dumps writes it."""

    def encoded(value) -> str:
        if not (isinstance(value, dict) and len(value) > JSON_PIECE):
            return json.dumps(value)
        items = list(value.items())
        return (
            "{"
            + ", ".join(
                json.dumps(dict(items[i : i + JSON_PIECE]))[1:-1]
                for i in range(0, len(items), JSON_PIECE)
            )
            + "}"
        )

    if not all(isinstance(k, str) for k in summary):  # json.dumps's own key conversions
        return json.dumps(summary)
    return "{" + ", ".join(f"{json.dumps(k)}: {encoded(v)}" for k, v in summary.items()) + "}"


def clock_suffix(seconds: float) -> str:
    """`` (h:mm:ss)`` for a time of a minute or more (human summaries only), else ``""``.
    Rounded to whole seconds: 545.4 s → `` (0:09:05)``."""
    if not seconds >= 60.0:
        return ""
    minutes, secs = divmod(int(round(seconds)), 60)
    hours, minutes = divmod(minutes, 60)
    return f" ({hours}:{minutes:02d}:{secs:02d})"


def precompensation_text(summary: dict) -> str | None:
    """The human line of ``--precompensate`` (None without it)."""
    pre = summary.get("precompensation")
    if pre is None:
        return None
    return (
        f"  pre-compensated reference (ZPETC): {pre['reference_deviation_max_um']:.2f} µm "
        f"from the path at most; contour error with a ±10 % model error "
        f"≤ {pre['sensitivity_contour_max_um']:.2f} µm; motion delayed "
        f"{pre['lead_s'] * 1000:g} ms for the inverse's look-ahead, reference settles "
        f"{pre['tail_s'] * 1000:g} ms after the stop"
    )


def scope_words(scope: str) -> str:
    """The words after "contour error" that say which samples it is over (``contour_scope``
    of the JSON): the feed moves (:mod:`nurbscnc.plan.scope`), or every sample."""
    return " on feed moves" if scope == "feed" else " (all samples)"


def rapids_words(rapids_max_um: float | None) -> str:
    """``"; rapids: max … µm (not guaranteed)"`` for the largest contour error [µm] of the
    rapids (and the settle wait after each), or ``""`` without rapids (None or 0)."""
    if not rapids_max_um:
        return ""
    return f"; on rapids: max {rapids_max_um:.2f} µm (not guaranteed)"
