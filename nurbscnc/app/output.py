"""Writing a run's data to files: reference points (CSV, NPZ, halstreamer) window by window,
the jerk-limited profile of ``plan --dump-profile``, and the output names of a batch."""

from __future__ import annotations

import os

from nurbscnc.errors import ConfigError

#: The format an output suffix names (``run -o``).
SUFFIX_FORMATS = {".csv": "csv", ".npz": "npz", ".hs": "halstreamer"}


def write_output(path: str, fmt: str, run, mach, name: str, then=None):
    """Write the reference points of ``run`` (:class:`~nurbscnc.pipeline.Run`) to ``path``:
    a halstreamer file, or CSV/NPZ by suffix (with the columns of the rotary axes the
    program uses), window by window (:meth:`Run.chunks`), the windows made in a worker
    thread while this one writes them
    (:func:`~nurbscnc.output.background.write_while_making`). ``then(stats)``: run in the
    worker once every window is made, while the writer finishes the file, with the
    :class:`~nurbscnc.plan.report.SampleStats` of the points (the summary). Returns its
    result once the file is complete (None without ``then``)."""
    from nurbscnc.output.background import write_while_making
    from nurbscnc.plan.report import SampleStats

    count = run.sample_count
    if fmt == "halstreamer":
        from nurbscnc.output.halstreamer import write_halstreamer_samples

        def write(windows):
            write_halstreamer_samples(path, windows, count, mach.servo.period_s, name)
    else:
        from nurbscnc.output.files import write_point_windows

        def write(windows):
            write_point_windows(path, windows, count, npz=fmt == "npz" if fmt else None)

    stats = SampleStats(run.plan)
    return write_while_making(
        write, stats.tap(run.chunks()), None if then is None else lambda: then(stats)
    )


def write_profile_dump(path: str, run, mach) -> None:
    """``plan --dump-profile``: t, s, v, a, j and the piece at every servo period (CSV, or
    NPZ by extension) of the look-ahead plan of ``run``; of a program with no motion, the
    tool at rest (all 0) at the times of its points."""
    import numpy as np

    from nurbscnc.output.files import write_profile
    from nurbscnc.plan.timing import servo_clock

    pl = run.plan
    if run.rest_s is not None:
        t = run.samples.t_s
        zero = np.zeros(t.size)
        write_profile(path, t, zero, zero, zero, zero, np.zeros(t.size, dtype=np.int64))
        return
    t, tau = servo_clock(pl.pieces, pl.profile, mach.servo.period_s)
    s, v, a, j, piece = pl.profile.sample(tau)
    write_profile(path, t, s, v, a, j, piece)


def batch_targets(programs, output_dir: str, fmt: str) -> list[str]:
    """``output_dir/<stem>.<fmt>`` for every program. Two programs with one stem (``a/x.nc``
    and ``b/x.nc``, or one file given twice) would write one file: refused before anything is
    planned or written (ConfigError, exit 2, naming both), as is ``-`` (stdin has no name)."""
    seen: dict[str, str] = {}
    targets = []
    for program in programs:
        if program == "-":
            raise ConfigError("a batch (--output-dir) cannot read stdin ('-'); use -o")
        stem = os.path.splitext(os.path.basename(program))[0]
        ext = "hs" if fmt == "halstreamer" else fmt
        target = os.path.join(output_dir, f"{stem}.{ext}")
        if target in seen:
            raise ConfigError(
                f"{seen[target]} and {program} would both write {target}; "
                "rename one or run them separately"
            )
        seen[target] = program
        targets.append(target)
    for program in programs:  # a program that is some program's output (run --output-dir .)
        for target in targets:
            refuse_overwriting(program, target)
    return targets


def refuse_overwriting(program: str, output: str) -> None:
    """ConfigError (exit 2) when ``output`` is the file ``program`` (``run x.nc -o x.nc``, or
    through a link): the points would replace the program they came from."""
    if "-" in (program, output):
        return
    try:
        same = os.path.samefile(program, output)
    except OSError:  # either does not exist (yet): reading the program says why
        return
    if same:
        raise ConfigError(
            f"the output {output} is the program {program} itself: its points "
            "would replace it; give another output file"
        )
