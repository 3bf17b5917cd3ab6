"""Fuzzing the command line: no input ever makes nurbscnc crash (exit 1 or a traceback).

Three generators feed ``nurbscnc check -`` (and, for mutants that pass and are small enough,
``nurbscnc plan -`` and, with NURBS blocks, ``corners -``) in-process through click's
CliRunner:

- hypothesis with raw bytes;
- hypothesis with grammar-shaped programs (G/M codes, axis words, numbers from tiny to
  hundreds of digits, expressions, parameters, comments, NURBS blocks);
- a mutation fuzzer over real programs (the corpus, ``$NURBSCNC_CORPUS`` or
  ``../shared/corpus``; ``programs/*.nc``; ``tests/bad/*.nc``; ``tests/fuzz/*.nc``): byte
  flips and overwrites, line duplication, deletion and swaps, digit runs inserted into
  numbers, hostile tokens, splices of lines from another program, truncation.
  Deterministic: mutant ``i`` comes from ``random.Random(seed + i)``.

A regression corpus (:data:`REGRESSIONS`) replays, at every budget, the hostile inputs earlier
campaigns found beyond programs: over-long lines, deep or out-of-range machine profiles,
malformed NPZ point files, terminal controls in messages, a stream over a noisy line.

Every outcome must be exit 0, 2 or 3, with a message on stderr for 2 and 3 (bounded in size:
source lines are cut), and never a traceback. Work is bounded: every run has a wall-clock
timeout (SIGALRM), and ``plan`` only sees mutants whose motion is short by an estimate from
``check --json`` (the planner's own limits are another issue; a timeout is counted, not failed).

Budget: ``make test`` runs a small deterministic one (a few seconds);
``make fuzz`` sets ``NURBSCNC_FUZZ_EXAMPLES`` (mutants; hypothesis a twentieth each) and
optionally ``NURBSCNC_FUZZ_SECONDS`` (stop the mutation loop after this long) and writes the
counts to ``$NURBSCNC_FUZZ_REPORT`` (JSON).
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import re
import signal
import time
from collections import Counter
from datetime import timedelta
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nurbscnc.cli.main import main
from nurbscnc.errors import NurbsCncError

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_CORPUS = ROOT / ".." / "shared" / "corpus"

#: Mutants in the small (``make test``) budget; hypothesis runs HYPOTHESIS_SHARE of the budget
#: (at least 30 examples) in each of its two tests.
SMALL_EXAMPLES = 80
HYPOTHESIS_SHARE = 20
EXAMPLES = int(os.environ.get("NURBSCNC_FUZZ_EXAMPLES") or SMALL_EXAMPLES)
LARGE = EXAMPLES > SMALL_EXAMPLES
SECONDS = float(os.environ.get("NURBSCNC_FUZZ_SECONDS") or 0) or None
SEED = int(os.environ.get("NURBSCNC_FUZZ_SEED") or 0)
#: Wall-clock limit of one ``check`` and one ``plan`` run [s].
CHECK_TIMEOUT_S = 20.0
PLAN_TIMEOUT_S = 30.0 if LARGE else 10.0
#: ``plan`` only for mutants that pass ``check`` with an estimated motion time below this [s]
#: (1 ms per point) and at most this many segments, and at most PLAN_MAX of them in a run.
PLAN_MOTION_CAP_S = 20.0 if LARGE else 3.0
PLAN_SEGMENT_CAP = 3000
PLAN_MAX = EXAMPLES if LARGE else 2
#: stderr of a failing run must stay below this (an echoed line is cut to ~120 characters).
STDERR_CAP = 4000

settings.register_profile(
    "nurbscnc-fuzz-small",
    max_examples=30,
    deadline=timedelta(seconds=10),
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
settings.register_profile(
    "nurbscnc-fuzz-large",
    max_examples=max(30, EXAMPLES // HYPOTHESIS_SHARE),
    deadline=timedelta(seconds=30),
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
PROFILE = settings.get_profile("nurbscnc-fuzz-large" if LARGE else "nurbscnc-fuzz-small")

#: Counts over the session: inputs by command, exit codes, timeouts (written to the report).
STATS: Counter = Counter()
FINDINGS: list[dict] = []


# ------------------------------------------------------------------------------ running


class _Timeout(BaseException):
    """Raised by SIGALRM; a BaseException so neither the CLI nor CliRunner swallows it."""


@contextlib.contextmanager
def _alarm(seconds: float):
    def fire(_signum, _frame):
        raise _Timeout

    previous = signal.signal(signal.SIGALRM, fire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def invoke(args: list[str], data: bytes, timeout_s: float):
    """Run ``nurbscnc ARGS`` with ``data`` on stdin; returns the Result or None on timeout."""
    STATS[f"inputs_{args[0]}"] += 1
    try:
        with _alarm(timeout_s):
            result = CliRunner().invoke(main, args, input=data)
    except _Timeout:
        STATS[f"timeouts_{args[0]}"] += 1
        FINDINGS.append({"kind": "timeout", "args": args, "input": _show(data)})
        return None
    STATS[f"exit_{result.exit_code}"] += 1
    return result


def problems_of(result) -> list[str]:
    """What is wrong with an outcome: an exit code outside {0, 2, 3}, a traceback, an
    internal error, a silent failure, an unbounded message."""
    found = []
    code = result.exit_code
    if code not in (0, 2, 3):
        found.append(f"exit {code}")
    exc = result.exception
    if exc is not None and not isinstance(exc, SystemExit):
        found.append(f"uncaught {type(exc).__name__}: {str(exc)[:200]}")
    if "Traceback" in result.output or "internal error" in result.stderr:
        found.append("traceback or internal error: " + result.stderr[-400:])
    if code in (2, 3) and "error" not in result.stderr:
        found.append(f"exit {code} without an error message")
    if len(result.stderr) > STDERR_CAP:
        found.append(f"{len(result.stderr)} characters on stderr")
    return found


def _show(data: bytes, limit: int = 300) -> str:
    text = data.decode("latin-1")
    return text if len(text) <= limit else text[:limit] + f"… ({len(data)} bytes)"


def assert_ok(args, data, result) -> None:
    found = problems_of(result)
    if found:
        STATS["failures"] += 1
        FINDINGS.append({"kind": "crash", "args": args, "problems": found, "input": _show(data)})
    assert not found, f"nurbscnc {' '.join(args)} on {_show(data)!r}: {found}"


_ORDER = {"crash": 0, "timeout": 1, "known": 2}  # the report lists new crashes first


@pytest.fixture(scope="module", autouse=True)
def report():
    """Print (and write to $NURBSCNC_FUZZ_REPORT) how many inputs ran and what they gave."""
    started = time.monotonic()
    yield
    summary = {
        "examples_budget": EXAMPLES,
        "seed": SEED,
        "seconds": time.monotonic() - started,
        "inputs": sum(v for k, v in STATS.items() if k.startswith("inputs_")),
        "exited_1": STATS.get("exit_1", 0),
        **dict(sorted(STATS.items())),
        "findings": sorted(FINDINGS, key=lambda f: _ORDER[f["kind"]])[:50],
    }
    path = os.environ.get("NURBSCNC_FUZZ_REPORT")
    if path:
        Path(path).write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    print(
        f"\nfuzz: {summary['inputs']} inputs in {summary['seconds']:.1f} s, "
        f"{summary['exited_1']} exited 1; {dict(sorted(STATS.items()))}"
    )


# ------------------------------------------------------------------------------ hypothesis


@PROFILE
@given(st.binary(max_size=3000))
def test_check_survives_random_bytes(data):
    result = invoke(["check", "-"], data, CHECK_TIMEOUT_S)
    if result is not None:
        assert_ok(["check", "-"], data, result)


def _number() -> st.SearchStrategy[str]:
    digits = st.text("0123456789", min_size=1, max_size=12)
    return st.one_of(
        st.integers(-1000, 1000).map(str),
        st.floats(-1e4, 1e4, allow_nan=False).map(lambda v: f"{v:.4f}"),
        st.builds(lambda a, b: f"{a}.{b}", digits, digits),
        st.integers(300, 420).map(lambda n: "9" * n),  # beyond a double
        st.integers(300, 340).map(lambda n: "0." + "0" * n + "1"),  # below the smallest normal
        st.sampled_from(
            [
                "-0",
                ".5",
                "-.5",
                "1.",
                "0",
                "1e5",
                "nan",
                "inf",
                "1_0",
                "+-1",
                "[1+2]",
                "[-1]",
                "[1/0]",
                "[SQRT[-1]]",
                "[ACOS[2]]",
                "#1",
                "#<x>",
                "[#1*2]",
                "[2**1024]",
                "[1 MOD 0]",
                "[ATAN[1]/[0]]",
                "[EXP[1000]]",
                "[" * 30 + "1" + "]" * 30,
            ]
        ),
    )


def _word() -> st.SearchStrategy[str]:
    codes = st.sampled_from(
        [
            "G0",
            "G1",
            "G2",
            "G3",
            "G4",
            "G5.2",
            "G5.3",
            "G6.2",
            "G17",
            "G18",
            "G19",
            "G20",
            "G21",
            "G90",
            "G91",
            "G90.1",
            "G91.1",
            "G93",
            "G94",
            "G95",
            "G61",
            "G61.1",
            "G64",
            "G40",
            "G43",
            "G49",
            "G53",
            "G54",
            "G80",
            "G28",
            "G41",
            "G81",
            "G92",
            "M0",
            "M2",
            "M3",
            "M5",
            "M6",
            "M30",
            "M99",
            "O100",
            "G2.2",
        ]
    )
    axis = st.builds(
        lambda letter, n: letter + n, st.sampled_from(list("XYZIJKRPQLFEHTSDNABC")), _number()
    )
    other = st.sampled_from(
        [
            "(comment)",
            "(MSG, hi)",
            "; tail",
            "/",
            "%",
            "#1=5",
            "#<x>=2",
            "#1=[#1+1]",
            "(",
            ")",
            "[",
            "]",
            "(:thumbs_up:)",
            "[/]",
            "\t",
        ]
    )
    return st.one_of(codes, axis, axis, other)


@st.composite
def programs(draw) -> str:
    lines = draw(st.lists(st.lists(_word(), max_size=8).map(" ".join), max_size=25))
    if draw(st.booleans()):  # a NURBS block shape, so the NURBS paths are reached often
        k = draw(st.integers(2, 8))
        lines.insert(
            draw(st.integers(0, len(lines))),
            "\n".join(
                ["G5.2 X0 Y0 P1 L4"]
                + [f"X{draw(_number())} Y{draw(_number())} P{draw(_number())}" for _ in range(k)]
                + ["G5.3"]
            ),
        )
    return "\n".join(["G21 G90 F600", *lines, "M2"]) + "\n"


@PROFILE
@given(programs())
def test_check_survives_grammar_programs(text):
    data = text.encode("utf-8")
    args = ["check", "-", "--json"] if len(text) % 2 else ["check", "-"]
    result = invoke(args, data, CHECK_TIMEOUT_S)
    if result is not None:
        assert_ok(args, data, result)
        if "--json" in args and result.stdout:
            assert json.loads(result.stdout)["ok"] is (result.exit_code == 0)


# ------------------------------------------------------------------------------ mutation


def corpus_dir() -> Path:
    return Path(os.environ.get("NURBSCNC_CORPUS") or DEFAULT_CORPUS).resolve()


def seed_programs() -> dict[str, bytes]:
    """Name → bytes of every seed: the corpus, programs/*.nc and tests/bad/*.nc."""
    seeds = {}
    corpus = corpus_dir()
    for folder, pattern in (
        (corpus, "*.ngc"),
        (ROOT / "programs", "*.nc"),
        (ROOT / "tests" / "bad", "*.nc"),
        (ROOT / "tests" / "fuzz", "*.nc"),
    ):
        if folder.is_dir():
            for path in sorted(folder.rglob(pattern)):
                seeds[str(path.relative_to(folder.parent))] = path.read_bytes()
    return seeds


HOSTILE = [
    b"[",
    b"]",
    b"#",
    b"##",
    b"#1=",
    b"ABS[",
    b"G5.2 ",
    b"G6.2 ",
    b"G5.3\n",
    b"M2\n",
    b"G4 P",
    b"F0.001",
    b"F1e-321",
    b"P1000000000",
    b"1e400",
    b"(",
    b")",
    b"-",
    b"-.",
    b"\n",
    b"\r",
    b"\x00",
    b"\xff",
    b"\xef\xbb\xbf",
    b"%\n",
    b"/",
    b"O1 sub\n",
    b"G28 ",
    b"G91 ",
    b"G20 ",
    b"R-1 ",
    b"(:100:)",
    b"[/]",
    b"\t",
    b"G1 X1000000 ",
]


REPEATED = [b"[", b"]", b"#", b"ABS[", b"[1+", b"-", b"(", b"9", b"X1 ", b"G1 ", b"\n", b";"]


def hostile_value(rng: random.Random) -> bytes:
    """A value for a word: nested or chained expressions of depth 10 to 5000, numbers beyond a
    double or below its smallest subnormal, division by zero, domain errors."""
    n = rng.choice([10, 200, 1000, 5000])
    return rng.choice(
        [
            lambda: b"#" * n + b"1",
            lambda: b"[" + b"1+" * n + b"1]",
            lambda: b"ABS[" * n + b"1" + b"]" * n,
            lambda: b"[" * n + b"1" + b"]" * n,
            lambda: b"[-" + b"-" * n + b"1]",
            lambda: b"9" * rng.choice([20, 309, 400]),
            lambda: b"0." + b"0" * rng.choice([30, 320, 400]) + b"1",
            lambda: b"[1/0]",
            lambda: b"[SQRT[-1]]",
            lambda: b"[EXP[1000]]",
            lambda: b"[2**2000]",
            lambda: b"1e400",
            lambda: b"-0",
            lambda: b"0",
        ]
    )()


def mutate(data: bytes, rng: random.Random, others: list[bytes]) -> bytes:
    """One to four random mutations of ``data`` (module docstring)."""
    buf = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        lines = bytes(buf).split(b"\n")
        op = rng.randrange(11)
        if op == 0 and buf:  # flip one bit
            k = rng.randrange(len(buf))
            buf[k] ^= 1 << rng.randrange(8)
        elif op == 1 and buf:  # overwrite a byte
            buf[rng.randrange(len(buf))] = rng.choice(b"[]#()%;/GXYZIJKPQRLFEN-+.0123456789 \n")
        elif op == 2:  # duplicate a line, up to 50 times
            k = rng.randrange(len(lines))
            lines[k:k] = [lines[k]] * rng.randint(1, 50)
            buf = bytearray(b"\n".join(lines))
        elif op == 3 and len(lines) > 1:  # delete a run of lines
            k = rng.randrange(len(lines))
            del lines[k : k + rng.randint(1, 5)]
            buf = bytearray(b"\n".join(lines))
        elif op == 4:  # digits into a number (huge or over-precise values)
            spots = [m.end() for m in re.finditer(rb"\d", bytes(buf))] or [len(buf)]
            k = rng.choice(spots)
            run = "".join(rng.choice("0123456789") for _ in range(rng.choice([1, 5, 20, 320])))
            buf[k:k] = run.encode()
        elif op == 5:  # a hostile token anywhere
            k = rng.randint(0, len(buf))
            buf[k:k] = rng.choice(HOSTILE)
        elif op == 6 and others:  # splice lines of another program
            donor = rng.choice(others).split(b"\n")
            a = rng.randrange(len(donor))
            k = rng.randrange(len(lines) + 1)
            lines[k:k] = donor[a : a + rng.randint(1, 20)]
            buf = bytearray(b"\n".join(lines))
        elif op == 7 and len(lines) > 1:  # swap two lines
            a, b = rng.randrange(len(lines)), rng.randrange(len(lines))
            lines[a], lines[b] = lines[b], lines[a]
            buf = bytearray(b"\n".join(lines))
        elif op == 8 and buf:  # truncate
            del buf[rng.randrange(len(buf)) :]
        elif op == 9:  # a token repeated: deep nesting, long parameter chains, long lines
            k = rng.randint(0, len(buf))
            buf[k:k] = rng.choice(REPEATED) * rng.choice([2, 50, 1000, 20000])
        elif op == 10:  # a word's value replaced by a hostile one (deep, huge, tiny, bad)
            spots = list(re.finditer(rb"(?<=[A-Za-z])-?[\d.]+", bytes(buf)))
            if spots:
                m = rng.choice(spots)
                buf[m.start() : m.end()] = hostile_value(rng)
    return bytes(buf)


def motion_estimate_s(summary: dict) -> float:
    """A generous time estimate of a checked program [s]: feed moves at the slowest feed,
    rapids at 10 mm/s, 0.2 s per segment for acceleration, plus every dwell."""
    feed = summary["feed_range_mm_s"]["min"]
    time_s = summary["length_mm"] / feed if feed else 0.0
    time_s += summary["rapid_length_mm"] / 10.0 + 0.2 * len(summary["segments"])
    return time_s + summary.get("dwell_s", 0.0)


def dwell_seconds(data: bytes) -> float:
    """Total G4 dwell of a program [s], from the interpreter (check shows no durations)."""
    from nurbscnc.program.interpret import InterpretOptions, interpret_text

    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    try:
        prog = interpret_text(text, InterpretOptions())
    except NurbsCncError:  # cannot happen after check passed; then do not plan it
        return float("inf")
    return float(sum(getattr(s, "seconds", 0.0) for s in prog.segments))


def test_mutation_fuzzer_over_the_corpus():
    seeds = seed_programs()
    if not any(k.startswith(corpus_dir().name) for k in seeds):
        STATS["corpus_missing"] = 1
    assert len(seeds) >= 5, "no seed programs found"
    names = sorted(seeds)
    blobs = [seeds[n] for n in names]
    started = time.monotonic()
    planned = 0
    failures = []
    for i in range(EXAMPLES):
        if SECONDS is not None and time.monotonic() - started > SECONDS:
            break
        rng = random.Random(SEED * 1_000_003 + i)
        k = rng.randrange(len(blobs))
        data = mutate(blobs[k], rng, blobs)
        args = ["check", "-", "--json"] if i % 2 else ["check", "-"]
        result = invoke(args, data, CHECK_TIMEOUT_S)
        if result is None:
            continue
        if problems_of(result):
            failures.append((names[k], i, args, data, problems_of(result)))
            continue
        if result.exit_code != 0 or planned >= PLAN_MAX:
            continue
        # A mutant that passed: plan it if its motion is short (the summary has the lengths).
        if "--json" not in args:
            result = invoke(["check", "-", "--json"], data, CHECK_TIMEOUT_S)
        summary = json.loads(result.stdout)
        if len(summary["segments"]) > PLAN_SEGMENT_CAP:
            continue
        summary["dwell_s"] = dwell_seconds(data)
        if motion_estimate_s(summary) > PLAN_MOTION_CAP_S:
            STATS["plan_skipped_long"] += 1
            continue
        planned += 1
        plan_args = ["plan", "-", "--json", "--dynamics", rng.choice(["off", "local"])]
        if rng.random() < 0.5:
            plan_args.append("--smooth")  # dense runs of lines as splines (plan/smoothing.py)
        plan = invoke(plan_args, data, PLAN_TIMEOUT_S)
        if plan is not None and problems_of(plan):
            failures.append((names[k], i, plan_args, data, problems_of(plan)))
        if summary["counts"].get("nurbs"):  # the corner finder on the same NURBS blocks
            corner_args = ["corners", "-", "--json"]
            corners = invoke(corner_args, data, PLAN_TIMEOUT_S)
            if corners is not None and problems_of(corners):
                failures.append((names[k], i, corner_args, data, problems_of(corners)))
    STATS["mutants"] += i + 1 if EXAMPLES else 0
    unknown = []
    for name, i, args, data, found in failures:
        owner = known_elsewhere(found)
        STATS["known_elsewhere" if owner else "failures"] += 1
        if owner:
            STATS[f"known: {owner}"] += 1
        FINDINGS.append(
            {
                "kind": "known" if owner else "crash",
                "owner": owner,
                "seed_program": name,
                "mutant": i,
                "args": args,
                "problems": found,
                "input": _show(data),
            }
        )
        if not owner:
            unknown.append((name, i, args, data, found))
    assert not unknown, "\n".join(
        f"mutant {i} of {name}: nurbscnc {' '.join(args)}: {found}\n  input: {_show(data)!r}"
        for name, i, args, data, found in unknown[:10]
    )
    if failures:
        owners = Counter(known_elsewhere(f[4]) for f in failures)
        pytest.xfail(
            f"{len(failures)} crashes of known open bugs owned elsewhere: "
            + "; ".join(f"{n}x {o}" for o, n in owners.items())
        )


#: Crash signatures of bugs that are open in code this file's author does not own (issue 15,
#: being fixed in parallel): such a mutant makes the test xfail, visibly, naming the bug;
#: any other crash fails it. Remove an entry when its fix is merged.
KNOWN_ELSEWHERE = {
    "RecursionError": "deep expressions (issue 15, interpreter)",
}


def known_elsewhere(problems: list[str]) -> str | None:
    text = " ".join(problems)
    return next((owner for sig, owner in KNOWN_ELSEWHERE.items() if sig in text), None)


# ------------------------------------------------------------------------------ regressions


def _profile(tmp: Path, key: str, value: str) -> Path:
    """The default profile with ``[limits] key = value``."""
    from nurbscnc.machine.discovery import default_profile_text

    text = re.sub(rf"(?m)^{key} = .*$", f"{key} = {value}", default_profile_text())
    path = tmp / f"{key}.toml"
    path.write_text(text)
    return path


def _npz_bad_directory(tmp: Path) -> Path:
    import numpy as np

    path = tmp / "points.npz"
    t = np.arange(20) * 1e-3
    np.savez(path, t=t, x=t, y=t, z=t, feed=t + 1, piece=0 * t, line=1 + 0 * t)
    data = bytearray(path.read_bytes())
    k = data.rfind(b"PK\x01\x02")
    data[k : k + 4] = b"XXXX"
    path.write_bytes(bytes(data))
    return path


def _npy_renamed(tmp: Path) -> Path:
    import numpy as np

    path = tmp / "array.npz"
    with open(path, "wb") as fh:
        np.save(fh, np.zeros((20, 7)))
    return path


PROGRAM = b"G21 G90\nG1 X1 Y1 F600\nM2\n"

#: name -> (setup(tmp) -> (args, stdin bytes), exit code, words the message must hold, words
#: stdout and stderr must not hold).
REGRESSIONS = {
    "plain_word_line_10_mb": (
        lambda tmp: (["check", "-"], b"G21\nG1 X1 F600 " + b"G1 " * 3_400_000 + b"\nM2\n"),
        2,
        "<stdin>:2:65537: error: line is too long",
        (),
    ),
    "profile_nested_1000_deep": (
        lambda tmp: (
            ["check", "-", "--machine", str(_write(tmp / "deep.toml", _DEEP))],
            PROGRAM,
        ),
        2,
        "nested more than",
        ("RecursionError",),
    ),
    "npz_bad_central_directory": (
        lambda tmp: (["simulate", str(_npz_bad_directory(tmp))], b""),
        2,
        "not a reference-point NPZ file",
        ("BadZipFile",),
    ),
    "npy_renamed_npz": (
        lambda tmp: (["simulate", str(_npy_renamed(tmp))], b""),
        2,
        "a single .npy array",
        ("TypeError",),
    ),
    "msg_with_terminal_controls": (
        lambda tmp: (["check", "-"], (ROOT / "tests" / "fuzz" / "msg_controls.nc").read_bytes()),
        0,
        r"\x1b]0;pwned\x07\x1b[2J",
        ("\x1b", "\x07", "\x9b"),
    ),
    "contour_tolerance_1e-300": (
        lambda tmp: (
            ["plan", "-", "--machine", str(_profile(tmp, "contour_tolerance_um", "1e-300"))],
            PROGRAM,
        ),
        2,
        "limits.contour_tolerance_um must be >= 0.1 and <= 10000",
        (),
    ),
}
_DEEP = "a = " + "[" * 1000 + "]" * 1000 + "\n"


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.mark.parametrize("name", sorted(REGRESSIONS))
def test_regression_corpus(name, tmp_path):
    setup, code, words, absent = REGRESSIONS[name]
    args, data = setup(tmp_path)
    result = invoke(args, data, CHECK_TIMEOUT_S)
    assert result is not None, f"{name}: timed out"
    assert_ok(args, data[:300], result)
    text = result.stdout + result.stderr
    assert result.exit_code == code and words in text, (name, result.exit_code, text[-600:])
    assert not any(a in text for a in absent), (name, text[-600:])


@pytest.mark.parametrize("kind", ["drop", "corrupt"])
def test_regression_noisy_line_stream(kind):
    """A stream through lines losing (or damaging) 2 % of their bytes both ways completes
    exactly (tests/test_stream_link.py measures it on more seeds)."""
    from tests.test_stream_link import AIRFOIL, NOISY_CARD, _noisy

    STATS["inputs_stream"] += 1
    r = _noisy(kind, 0.02, SEED)
    assert r.completed and r.exact(AIRFOIL), r.error
    assert r.report.final_position_steps == tuple(int(v) for v in AIRFOIL.end_steps)
    assert NOISY_CARD.speed is None  # a card executing periods as they arrive (no underrun)
