"""Stream benchmark: line use at 1 kHz / 3 axes / 115200 baud, and the fault matrix.

Usage::

    .venv/bin/python bench/stream_bench.py --out bench/stream_results.json
    .venv/bin/python bench/stream_bench.py --quick          # a short program, a few seconds
    .venv/bin/python bench/stream_bench.py --matrix-only --seeds 20   # only the fault matrix
    .venv/bin/python bench/stream_bench.py --planning PROGRAM.ngc     # streaming while planning

Four parts:

1. **Computed** from the codec's frame sizes (frames actually encoded, not a formula): bytes
   per period sent to the card for several batch sizes, and the share of a 115200-baud 8N1 line
   (10 bits per byte, 11 520 bytes/s) that 1 kHz periods need; also the return direction (an
   ACK per batch, a STATUS every 16 periods).
2. **Measured as fast as possible**: a planned program (``programs/butterfly.nc``, ~10 s of
   motion) is streamed over a pseudo-terminal to the card simulator executing periods as fast
   as they arrive; the bytes the card received per executed period give the line use at 1 kHz.
   Repeated with 1 % and 10 % frame corruption (both directions): retransmissions cost bytes,
   the executed log must still equal the sent pulses exactly.
3. **Real time on an emulated line**: the simulator runs at 1 kHz and paces both directions at
   115200 baud (``Wire``); with 0 % and 10 % corruption the stream must finish without an
   underrun, and the measured line use is bytes × 10 / (115200 × duration).
4. **Fault matrix** in virtual time (:func:`~nurbscnc.output.stream.simlink.simulate`: sender
   and real-time card over a 115200-baud line, relays flipping 1–4 bits of a frame or losing
   frames / runs of bytes in both directions): corrupt 0.1–5 %, drop 0.1–2 %, several seeds.
   Every stream must end with the card's executed pulses equal to the plan, or fail with the
   card stopped having run a prefix of it; at ≤ 2 % corruption every stream must complete.

``--planning PROGRAM`` (issue 14, :func:`planning_ahead`): the wall time from the start to
the program validated (parse, interpret, the checks before work), to the first cut window
planned and to the first period the card executes (the job streaming to the card simulator),
against the time the whole plan takes (the planner thread left to finish); and, for a card
running in real time from that first period, the margin by which each later window is ready
before the card reaches it (negative: the card would wait at rest that long).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from nurbscnc.cli.stream import load_pulse_program  # noqa: E402
from nurbscnc.output.stream import protocol as p  # noqa: E402
from nurbscnc.output.stream.card import (  # noqa: E402
    CardConfig,
    CardSim,
    Faults,
    PtyEndpoint,
    serve,
)
from nurbscnc.output.stream.quantise import quantise  # noqa: E402
from nurbscnc.output.stream.sender import Sender, SenderOptions, open_port  # noqa: E402
from nurbscnc.output.stream.simlink import Relay, simulate  # noqa: E402

BAUD = 115200
RATE_HZ = 1000.0
AXES = 3
LINE_BYTES_S = BAUD / p.BITS_PER_BYTE_8N1


def computed(batch_sizes=(1, 2, 4, 8, 16, 32, 80)) -> list[dict]:
    """Bytes per period and line use from encoded frames (int8 counts, 3 axes)."""
    rows = []
    status = len(p.encode_message(p.Status(2, 0, 0, 0, 0, 0, (0,) * AXES)))
    ack = len(p.encode_message(p.Ack(0, 0)))
    for b in batch_sizes:
        frame = len(p.encode_message(p.Batch(np.full((b, AXES), 58), (0,) * AXES)))
        per_period = frame / b
        use = per_period * RATE_HZ / LINE_BYTES_S
        back = (ack / b + status / 16.0) * RATE_HZ / LINE_BYTES_S
        rows.append(
            {
                "batch_periods": b,
                "frame_bytes": frame,
                "bytes_per_period": per_period,
                "line_use": use,
                "spare": 1.0 - use,
                "return_line_use": back,
            }
        )
    return rows


def run_once(pulses, config: CardConfig, baud: int | None, seed: int = 1) -> dict:
    """Stream ``pulses`` to a card on a pty; return the measured numbers."""
    card = CardSim(config, seed=seed)
    endpoint = PtyEndpoint()
    stop = threading.Event()
    thread = threading.Thread(
        target=serve, args=(card, endpoint, stop), kwargs={"baud": baud}, daemon=True
    )
    thread.start()
    try:
        port = open_port(endpoint.path, baud=BAUD)
        sender = Sender(port, SenderOptions(timeout_s=5.0))
        t0 = time.perf_counter()
        report = sender.stream(pulses)
        wall = time.perf_counter() - t0
        port.close()
    finally:
        stop.set()
        thread.join(5.0)
        endpoint.close()
    exact = bool(np.array_equal(card.executed_pulses(), pulses.pulses))
    per_period = card.bytes_received / pulses.periods
    return {
        "periods": pulses.periods,
        "wall_s": wall,
        "periods_per_s": pulses.periods / wall,
        "bytes_to_card": card.bytes_received,
        "bytes_from_card": report.bytes_received,
        "bytes_per_period": per_period,
        "line_use_at_1kHz": per_period * RATE_HZ / LINE_BYTES_S,
        "spare_at_1kHz": 1.0 - per_period * RATE_HZ / LINE_BYTES_S,
        "measured_line_use": card.bytes_received / (LINE_BYTES_S * wall),
        "frames_sent": report.frames_sent,
        "retransmits": report.retransmits,
        "timeouts": report.timeouts,
        "naks": report.naks_received,
        "card_crc_errors": card.crc_errors,
        "card_corrupted_in": card.corrupted_in,
        "card_corrupted_out": card.corrupted_out,
        "alarm": card.alarm.name,
        "executed_equals_sent": exact,
        "final_position_ok": report.final_position_steps == tuple(pulses.end_steps),
    }


CORRUPT_RATES = (0.001, 0.005, 0.01, 0.02, 0.05)
DROP_RATES = (0.001, 0.005, 0.02)


def matrix(pulses, seeds: int) -> dict:
    """The fault matrix: outcome counts per corruption rate (all drop rates and seeds)."""
    rows = {}
    t0 = time.perf_counter()
    for corrupt in CORRUPT_RATES:
        row = {
            "streams": 0,
            "completed": 0,
            "failed_cleanly": 0,
            "unclean": 0,
            "retransmits": 0,
            "virtual_s": 0.0,
            "errors": [],
        }
        for drop in DROP_RATES:
            for seed in range(seeds):
                r = simulate(
                    pulses,
                    CardConfig(speed=1.0),
                    to_card=Relay(corrupt, drop, seed),
                    to_host=Relay(corrupt, drop, 10_000 + seed),
                    seed=seed,
                )
                row["streams"] += 1
                row["virtual_s"] += r.elapsed_s
                row["retransmits"] += r.link.count.retransmits
                if r.completed and r.exact(pulses):
                    row["completed"] += 1
                elif not r.completed and r.stopped_cleanly(pulses):
                    row["failed_cleanly"] += 1
                    row["errors"].append(
                        f"drop {drop:g} seed {seed}: {r.error.message} (card "
                        f"{r.state_at_end.name} when the sender ended)"
                    )
                else:
                    row["unclean"] += 1
                    row["errors"].append(f"UNCLEAN drop {drop:g} seed {seed}: {r.error}")
        rows[f"corrupt_{corrupt:g}"] = row
    return {
        "corrupt_rates": CORRUPT_RATES,
        "drop_rates": DROP_RATES,
        "seeds": seeds,
        "periods": pulses.periods,
        "rows": rows,
        "wall_s": time.perf_counter() - t0,
    }


STRESS = ((0.1, 0.05, 48), (0.2, 0.1, 256), (0.3, 0.2, 64), (0.5, 0.3, 256))


def stress(seeds: int = 25) -> dict:
    """Far past the matrix: (corrupt, drop, buffer) cells where streams may fail; every failure
    must leave the card stopped having run a prefix of the program (no wrong pulse)."""
    t = np.arange(501) * 1e-3  # a 10 mm circle at ≈ 31 mm/s, 500 periods
    pts = np.column_stack([10 * np.sin(np.pi * t), 10 * np.cos(np.pi * t) - 10, 0.01 * t])
    pulses = quantise(pts, (1000.0,) * 3, 1e-3)
    out = {}
    for corrupt, drop, buffer in STRESS:
        row = {"streams": 0, "completed": 0, "failed_cleanly": 0, "unclean": 0}
        for seed in range(seeds):
            r = simulate(
                pulses,
                CardConfig(speed=1.0, buffer_periods=buffer, start_fill_periods=buffer // 2),
                to_card=Relay(corrupt, drop, seed),
                to_host=Relay(corrupt, drop, 1000 + seed),
                seed=seed,
            )
            row["streams"] += 1
            key = (
                "completed"
                if r.completed and r.exact(pulses)
                else "failed_cleanly"
                if not r.completed and r.stopped_cleanly(pulses)
                else "unclean"
            )
            row[key] += 1
        out[f"corrupt_{corrupt:g}_drop_{drop:g}_buffer_{buffer}"] = row
    return out


def print_matrix(m: dict) -> bool:
    print(
        f"\nfault matrix ({m['periods']} periods, real-time card, 115200 baud, drop rates "
        f"{', '.join(f'{d:.1%}' for d in m['drop_rates'])} × {m['seeds']} seeds each, "
        f"{m['wall_s']:.1f} s):"
    )
    print(
        f"  {'corrupt':>7} {'streams':>7} {'done':>5} {'failed cleanly':>14} {'unclean':>7} "
        f"{'retransmits/stream':>18}"
    )
    ok = True
    for name, r in m["rows"].items():
        rate = float(name.split("_")[1])
        print(
            f"  {rate:>7.1%} {r['streams']:>7} {r['completed']:>5} {r['failed_cleanly']:>14} "
            f"{r['unclean']:>7} {r['retransmits'] / r['streams']:>18.1f}"
        )
        for e in r["errors"][:3]:
            print(f"          {e}")
        ok = ok and r["unclean"] == 0 and (rate > 0.02 or r["completed"] == r["streams"])
    print(f"  every stream exact or stopped cleanly, all complete at ≤ 2 %: {ok}")
    return ok


class _FirstPeriod(Exception):
    """Raised from the simulation's hook once the card has executed its first period."""


def planning_ahead(path: str) -> dict:
    """Time to the first period vs the whole plan while streaming ``path`` (module doc)."""
    from nurbscnc.controller.feed import WindowFeed
    from nurbscnc.controller.job import Job
    from nurbscnc.controller.simulate import simulate_job
    from nurbscnc.machine.profile import load_machine
    from nurbscnc.pipeline import window_plans
    from nurbscnc.program.interpret import interpret_text

    t0 = time.perf_counter()
    mach = load_machine()
    prog = interpret_text(Path(path).read_text())
    windows = window_plans(prog, mach)  # the checks before work run here
    t_valid = time.perf_counter() - t0
    ready: list = []
    cycle = []

    def recorded():
        for w in windows:
            ready.append((w.k0, time.perf_counter() - t0))
            cycle[:] = [w.plan.cycle_time_s]  # the last window's: the whole plan's
            yield w

    feed = WindowFeed(recorded(), clock=time.perf_counter)
    job = Job(None, prog, mach, feed=feed)
    t_first_window = time.perf_counter() - t0
    first = []
    update = job.update

    def hook(link):
        status = link.state.status
        if status is not None and status.executed_periods > 0:
            first.append(time.perf_counter() - t0)
            raise _FirstPeriod
        update(link)

    job.update = hook
    try:
        simulate_job(job, CardConfig(speed=1.0))
    except _FirstPeriod:
        pass
    while not feed.done:  # let the planner finish
        time.sleep(0.05)
        feed.poll()
    t_planned = feed.start_s - t0 + feed.planned_s
    period = mach.servo.period_s
    # A card at 1x from its first period reaches window i's first sample at k0·T later.
    margins = [first[0] + k0 * period - t for k0, t in ready[1:]]
    return {
        "program": Path(path).name,
        "windows": len(ready),
        "motion_s": round(cycle[0], 3),
        "validated_s": round(t_valid, 3),
        "first_window_s": round(t_first_window, 3),
        "first_period_s": round(first[0], 3),
        "whole_plan_s": round(t_planned, 3),
        "margin_min_s": round(min(margins), 3) if margins else None,
        "windows_late": int(sum(m < 0 for m in margins)),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=None, help="write the results as JSON here")
    ap.add_argument("--quick", action="store_true", help="short program (naca2415, ~1.1 s)")
    ap.add_argument("--seeds", type=int, default=4, help="fault matrix: seeds per cell")
    ap.add_argument("--matrix-only", action="store_true", help="only the fault matrix")
    ap.add_argument(
        "--stress",
        action="store_true",
        help="only the stress cells far past the matrix (10-50 %% corruption)",
    )
    ap.add_argument(
        "--planning",
        default=None,
        metavar="PROGRAM",
        help="only: time to the first period vs the whole plan (streaming while planning)",
    )
    args = ap.parse_args()
    if args.planning:
        row = planning_ahead(args.planning)
        row.update(
            date=dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            machine={
                "platform": platform.platform(),
                "cpus": os.cpu_count(),
                "python": platform.python_version(),
                "load_1min": round(os.getloadavg()[0], 2),
            },
        )
        print(json.dumps(row))
        if args.out:
            Path(args.out).write_text(json.dumps(row, indent=2) + "\n")
        return 0
    if args.stress:
        rows = stress()
        for name, row in rows.items():
            print(f"{name}: {row}")
        ok = all(row["unclean"] == 0 for row in rows.values())
        print(f"every failure with the card stopped after a prefix: {ok}")
        return 0 if ok else 1
    program = ROOT / "programs" / ("naca2415.nc" if args.quick else "butterfly.nc")
    pulses, mach = load_pulse_program(str(program), None, ())
    naca, _ = load_pulse_program(str(ROOT / "programs" / "naca2415.nc"), None, ())
    if args.matrix_only:
        m = matrix(naca, args.seeds)
        ok = print_matrix(m)
        if args.out:
            Path(args.out).write_text(json.dumps({"fault_matrix": m, "ok": ok}, indent=2) + "\n")
        return 0 if ok else 1
    results = {
        "date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "machine": {"platform": platform.platform(), "python": platform.python_version()},
        "program": program.name,
        "periods": pulses.periods,
        "peak_pulses": pulses.peak_pulses,
        "baud": BAUD,
        "rate_hz": RATE_HZ,
        "computed": computed(),
        "fast": {},
        "real_time_115200": {},
    }
    for rate in (0.0, 0.01, 0.10):
        faults = Faults(corrupt_rate=rate)
        config = CardConfig(speed=None, faults=faults)
        results["fast"][f"corrupt_{rate:g}"] = run_once(pulses, config, None)
    for rate in (0.0, 0.10):
        faults = Faults(corrupt_rate=rate)
        results["real_time_115200"][f"corrupt_{rate:g}"] = run_once(
            pulses, CardConfig(speed=1.0, faults=faults), BAUD
        )

    print(f"{program.name}: {pulses.periods} periods, peak {pulses.peak_pulses} pulses/period")
    print("\ncomputed (3 axes, int8, 1 kHz, 115200 8N1 = 11520 bytes/s):")
    print(f"  {'batch':>5} {'frame B':>7} {'B/period':>8} {'use':>7} {'spare':>7} {'return':>7}")
    for r in results["computed"]:
        print(
            f"  {r['batch_periods']:>5} {r['frame_bytes']:>7} {r['bytes_per_period']:>8.3f} "
            f"{r['line_use']:>7.1%} {r['spare']:>7.1%} {r['return_line_use']:>7.1%}"
        )
    for part in ("fast", "real_time_115200"):
        print(f"\n{part}:")
        for name, r in results[part].items():
            wire = f", line busy {r['measured_line_use']:.1%} of the run" if part != "fast" else ""
            print(
                f"  {name:>12}: {r['bytes_per_period']:.3f} B/period → use "
                f"{r['line_use_at_1kHz']:.1%}, spare {r['spare_at_1kHz']:.1%}{wire}; "
                f"{r['periods_per_s']:,.0f} periods/s; retransmits {r['retransmits']}; "
                f"alarm {r['alarm']}; exact {r['executed_equals_sent']}"
            )
    ok = all(
        r["executed_equals_sent"] and r["final_position_ok"] and r["alarm"] == "NONE"
        for part in ("fast", "real_time_115200")
        for r in results[part].values()
    )
    ok = ok and results["fast"]["corrupt_0"]["spare_at_1kHz"] >= 0.30
    results["fault_matrix"] = matrix(naca, args.seeds)
    ok = print_matrix(results["fault_matrix"]) and ok
    results["ok"] = ok
    print(f"\nspare ≥ 30 % at 1 kHz and every run exact: {ok}")
    if args.out:
        Path(args.out).write_text(json.dumps(results, indent=2) + "\n")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
