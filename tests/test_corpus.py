"""Conformance corpus: every ``*.ngc`` under the corpus folder passes ``nurbscnc check``.

The corpus (real LinuxCNC programs nobody on this project wrote) lives outside the repository:
it is the folder named by the environment variable ``NURBSCNC_CORPUS``, by default
``../shared/corpus`` next to the repository root. Without it the tests skip and say where they
looked.

Each file must give ``ok: true``, no errors, and the segment counts by kind and the path
lengths recorded in the golden file ``tests/golden/corpus_segments.json``::

    {"linuxcnc/general/3dtest.ngc": {"arc": 3, "line": 22, "rapid": 24,
                                     "length_mm": ..., "rapid_length_mm": ...}, ...}

(relative POSIX path -> counts of each segment kind present, the feed-move length and the
rapid length in mm). The golden file must list exactly the files present, so a new corpus
file, or a change of what the interpreter makes of one, is recorded on purpose. To regenerate
it after checking that the change is intended::

    .venv/bin/python tests/test_corpus.py --regenerate

(``NURBSCNC_CORPUS=/path/to/corpus`` selects another corpus folder). Review the diff before
committing it.
"""

from __future__ import annotations

import json
import os
import sys
from collections import Counter
from pathlib import Path

import pytest
from click.testing import CliRunner

from nurbscnc.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_CORPUS = ROOT / ".." / "shared" / "corpus"
GOLDEN = Path(__file__).resolve().parent / "golden" / "corpus_segments.json"
KINDS = ("line", "rapid", "arc", "nurbs", "dwell", "pause")
LENGTH_KEYS = ("length_mm", "rapid_length_mm")
#: Lengths are sums of Gauss–Legendre arc lengths: stable to rounding, far below this.
LENGTH_REL_TOL = 1e-6


def corpus_dir() -> Path:
    """The corpus folder (``$NURBSCNC_CORPUS`` or ``../shared/corpus``), resolved."""
    return Path(os.environ.get("NURBSCNC_CORPUS") or DEFAULT_CORPUS).resolve()


def corpus_files(corpus: Path) -> list[str]:
    """Every ``*.ngc`` below ``corpus`` (recursively), as sorted relative POSIX paths."""
    return sorted(p.relative_to(corpus).as_posix() for p in corpus.rglob("*.ngc"))


def require_corpus() -> Path:
    corpus = corpus_dir()
    if not corpus.is_dir():
        pytest.skip(
            f"conformance corpus not found at {corpus}; set NURBSCNC_CORPUS to the folder "
            "holding the *.ngc programs (default: ../shared/corpus next to the repository)"
        )
    return corpus


def check_json(path: Path) -> tuple[int, dict, str]:
    """Run ``nurbscnc check --json PATH`` in-process: (exit code, parsed JSON, stderr)."""
    result = CliRunner().invoke(main, ["check", "--json", str(path)])
    try:
        data = json.loads(result.stdout)
    except json.JSONDecodeError:
        data = {}
    return result.exit_code, data, result.stderr


def golden_entry(data: dict) -> dict:
    """The golden record of one ``check --json`` answer: counts by kind and the lengths."""
    entry = dict(sorted(Counter(s["kind"] for s in data["segments"]).items()))
    for key in LENGTH_KEYS:
        entry[key] = data[key]
    return entry


def load_golden() -> dict:
    with open(GOLDEN, encoding="utf-8") as fh:
        return json.load(fh)


# The parameter list is computed at collection; with no corpus there is one placeholder case,
# which skips with the explanation.
_CORPUS = corpus_dir()
_FILES = corpus_files(_CORPUS) if _CORPUS.is_dir() else ["<no corpus>"]


def test_golden_lists_exactly_the_corpus_files():
    corpus = require_corpus()
    present = set(corpus_files(corpus))
    assert present, f"no *.ngc files under {corpus}"
    recorded = set(load_golden())
    missing = sorted(present - recorded)
    stale = sorted(recorded - present)
    assert not missing and not stale, (
        f"corpus and golden file differ: not recorded {missing}, recorded but absent {stale}; "
        "if intended, run: python tests/test_corpus.py --regenerate"
    )


@pytest.mark.parametrize("rel", _FILES)
def test_corpus_file_checks_ok(rel):
    corpus = require_corpus()
    code, data, stderr = check_json(corpus / rel)
    assert code == 0, f"{rel}: exit {code}: {stderr}"
    assert "Traceback" not in stderr
    assert data["ok"] is True
    assert data["errors"] == []
    segments = data["segments"]
    assert segments, f"{rel}: no segments"
    for seg in segments:
        assert seg["kind"] in KINDS
        assert isinstance(seg["line"], int) and seg["line"] >= 1
        assert seg["length_mm"] >= 0.0
    # The summary's own counts agree with its segment list.
    assert data["counts"] == dict(Counter(s["kind"] for s in segments))
    # Feed length = sum over feed moves, rapid length = sum over rapids (same numbers, so
    # only summation-order rounding separates them).
    feed = sum(s["length_mm"] for s in segments if s["kind"] not in ("rapid", "dwell", "pause"))
    rapid = sum(s["length_mm"] for s in segments if s["kind"] == "rapid")
    assert data["length_mm"] == pytest.approx(feed, rel=1e-12, abs=1e-12)
    assert data["rapid_length_mm"] == pytest.approx(rapid, rel=1e-12, abs=1e-12)

    golden = load_golden()
    assert rel in golden, f"{rel} is not in {GOLDEN.name}; run tests/test_corpus.py --regenerate"
    got = golden_entry(data)
    want = golden[rel]
    assert {k: v for k, v in got.items() if k in KINDS} == {
        k: v for k, v in want.items() if k in KINDS
    }
    for key in LENGTH_KEYS:
        assert got[key] == pytest.approx(want[key], rel=LENGTH_REL_TOL, abs=1e-12), key


def regenerate() -> int:
    """Rewrite the golden file from the current interpreter; refuse if any file fails."""
    corpus = corpus_dir()
    if not corpus.is_dir():
        print(f"no corpus at {corpus}; set NURBSCNC_CORPUS", file=sys.stderr)
        return 2
    golden = {}
    failed = []
    for rel in corpus_files(corpus):
        code, data, stderr = check_json(corpus / rel)
        if code != 0 or not data.get("ok"):
            failed.append(f"{rel}: exit {code}: {stderr.strip()}")
            continue
        golden[rel] = golden_entry(data)
    if failed:
        print("not regenerated, these files fail check:\n" + "\n".join(failed), file=sys.stderr)
        return 1
    GOLDEN.parent.mkdir(parents=True, exist_ok=True)
    tmp = GOLDEN.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(golden, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    tmp.replace(GOLDEN)
    print(f"wrote {GOLDEN} ({len(golden)} files from {corpus})")
    return 0


if __name__ == "__main__":
    if sys.argv[1:] != ["--regenerate"]:
        print(__doc__)
        print("usage: python tests/test_corpus.py --regenerate", file=sys.stderr)
        sys.exit(2)
    sys.exit(regenerate())
