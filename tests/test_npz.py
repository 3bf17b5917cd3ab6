"""The NPZ writer (:mod:`nurbscnc.output.npz`) against zipfile and numpy, which read and
check every file here:

- stored members make the very bytes zipfile writes (the container: local headers with
  zip64 fields, central directory, end record);
- deflated members inflate (zipfile's testzip: every member inflated, its CRC-32 compared)
  to the .npy numpy.load reads; the header's own deflate segment joins the data's;
- the store-or-deflate choice is the zlib-format rule on the first NPZ_PROBE_ROWS rows,
  checked against ``zlib.compress`` on columns on both sides of the threshold;
- the bytes do not depend on the windows; a pipe (no ``tell``) gets the same bytes;
- sizes and offsets past 2 GiB take zip64 fields in the central directory and the zip64
  end record (the limit lowered to reach them with small files).
"""

from __future__ import annotations

import io
import zipfile
import zlib

import numpy as np
import pytest

import nurbscnc.output.npz as npz


def _write(cols: dict, window: int, spool_dir) -> bytes:
    n = len(next(iter(cols.values())))
    buf = io.BytesIO()
    wins = [tuple(c[i : i + window] for c in cols.values()) for i in range(0, max(n, 1), window)]
    npz.write_npz(buf, str(spool_dir), list(cols), wins, n)
    return buf.getvalue()


def _zipfile_npz(cols: dict, deflate: dict) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, mode="w", compresslevel=npz.NPZ_DEFLATE_LEVEL) as zipf:
        for name, col in cols.items():
            zipf.compression = zipfile.ZIP_DEFLATED if deflate[name] else zipfile.ZIP_STORED
            with zipf.open(f"{name}.npy", "w", force_zip64=True) as fid:
                np.lib.format.write_array(fid, col, allow_pickle=False)
    return buf.getvalue()


def test_stored_members_are_zipfiles_bytes(tmp_path):
    """Columns that do not deflate (random doubles) are stored: the file is byte for byte
    the one zipfile writes with ZipFile.open(name, "w", force_zip64=True) and np.save's
    format, at one window and at many."""
    rng = np.random.default_rng(5)
    cols = {"a": rng.normal(size=70_001), "b": rng.normal(size=70_001)}
    want = _zipfile_npz(cols, {"a": False, "b": False})
    assert _write(cols, 70_001, tmp_path) == want
    assert _write(cols, 999, tmp_path) == want


@pytest.mark.parametrize("n", [0, 1, 5_000, 65_536, 65_537, 200_000])
def test_deflated_members_read_back_and_match_zipfile(tmp_path, n):
    """A time column, a piece index, a constant and a noisy one, of 0 to 200,000 rows: the
    same members, choices, CRC-32s and sizes as zipfile's file, testzip clean, numpy.load
    equal, and the same bytes for windows of 7, 4,096 and all rows."""
    rng = np.random.default_rng(n)
    cols = {
        "t": np.arange(n) * 1e-3,
        "piece": np.repeat(np.arange(n // 50 + 1), 50)[:n],
        "z": np.zeros(n),
        "x": rng.normal(size=n),
    }
    got = _write(cols, max(n, 1), tmp_path)
    for w in (7, 4096):
        assert _write(cols, w, tmp_path) == got
    probe = {k: v[: npz.NPZ_PROBE_ROWS].tobytes() for k, v in cols.items()}
    deflate = {
        k: not p or len(zlib.compress(p, npz.NPZ_DEFLATE_LEVEL)) <= npz.NPZ_STORE_RATIO * len(p)
        for k, p in probe.items()
    }
    want = _zipfile_npz(cols, deflate)
    with zipfile.ZipFile(io.BytesIO(got)) as a, zipfile.ZipFile(io.BytesIO(want)) as b:
        assert a.testzip() is None
        for x, y in zip(a.infolist(), b.infolist(), strict=True):
            assert (x.filename, x.compress_type, x.CRC, x.file_size, x.header_offset == 0) == (
                y.filename,
                y.compress_type,
                y.CRC,
                y.file_size,
                y.header_offset == 0,
            )
    with np.load(io.BytesIO(got)) as back:
        for name, col in cols.items():
            assert back[name].dtype == col.dtype and np.array_equal(back[name], col)
    assert list(tmp_path.iterdir()) == []  # the spool is gone


def test_the_choice_is_zlibs_rule_on_both_sides_of_the_threshold(tmp_path):
    """Columns mixing random and repeated bytes in steps around NPZ_STORE_RATIO: each is
    deflated exactly where zlib.compress of its first NPZ_PROBE_ROWS rows is within the
    ratio (both outcomes met)."""
    rng = np.random.default_rng(11)
    n = 80_000
    cols = {}
    for i, share in enumerate(np.linspace(0.70, 0.95, 26)):
        col = rng.normal(size=n)
        flat = rng.random(n) > share  # rows replaced by a constant: they deflate away
        col[flat] = 1.0
        cols[f"c{i}"] = col
    got = _write(cols, 30_000, tmp_path)
    with zipfile.ZipFile(io.BytesIO(got)) as z:
        kinds = {i.filename[:-4]: i.compress_type for i in z.infolist()}
    outcomes = set()
    for name, col in cols.items():
        p = col[: npz.NPZ_PROBE_ROWS].tobytes()
        want = len(zlib.compress(p, npz.NPZ_DEFLATE_LEVEL)) <= npz.NPZ_STORE_RATIO * len(p)
        assert (kinds[name] == zipfile.ZIP_DEFLATED) == want, name
        outcomes.add(want)
    assert outcomes == {True, False}


class _Pipe(io.RawIOBase):
    """A write-only stream without tell or seek (a FIFO)."""

    def __init__(self):
        self.data = bytearray()

    def writable(self):
        return True

    def write(self, b):
        self.data += b
        return len(b)

    def seekable(self):
        return False

    def tell(self):
        raise OSError("not seekable")


def test_a_pipe_gets_the_same_bytes(tmp_path):
    cols = {"t": np.arange(100_000) * 1e-3, "k": np.arange(100_000) // 7}
    pipe = _Pipe()
    npz.write_npz(
        pipe,
        str(tmp_path),
        list(cols),
        [tuple(c[i : i + 30_000] for c in cols.values()) for i in range(0, 100_000, 30_000)],
        100_000,
    )
    assert bytes(pipe.data) == _write(cols, 100_000, tmp_path)


def test_zip64_fields_past_the_limit(tmp_path, monkeypatch):
    """With the 2 GiB limit lowered to 1,000 bytes, sizes, offsets and the central
    directory's place take zip64 fields and the zip64 end record: zipfile and numpy still
    read every member (its CRC checked)."""
    monkeypatch.setattr(npz, "_ZIP64_LIMIT", 1000)
    rng = np.random.default_rng(2)
    cols = {"x": rng.normal(size=3000), "t": np.arange(3000) * 1e-3, "z": np.zeros(3000)}
    got = _write(cols, 700, tmp_path)
    with zipfile.ZipFile(io.BytesIO(got)) as z:
        assert z.testzip() is None
        assert [i.header_offset > 1000 for i in z.infolist()] == [False, True, True]
    with np.load(io.BytesIO(got)) as back:
        for name, col in cols.items():
            assert np.array_equal(back[name], col)


def test_row_counts_that_do_not_add_up_are_refused(tmp_path):
    cols = (np.arange(10.0), np.arange(10.0))
    with pytest.raises(ValueError, match="announced"):
        npz.write_npz(io.BytesIO(), str(tmp_path), ["a", "b"], [cols], 9)
    with pytest.raises(ValueError, match="announced"):
        npz.write_npz(io.BytesIO(), str(tmp_path), ["a", "b"], [cols, cols], 15)
    with pytest.raises(ValueError, match="11 announced|announced"):
        npz.write_npz(io.BytesIO(), str(tmp_path), ["a", "b"], [cols], 11)
