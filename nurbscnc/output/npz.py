"""NPZ files written column by column as their windows come, each column deflated once.

An NPZ is a zip of ``<name>.npy`` members (``np.savez_compressed``); numpy.load and every
zip reader read it. The reference points come window by window, row-wise, while a zip
member must be complete before the next one begins. So each column is *deflated as its rows
come* (zlib, which works without Python's interpreter lock: the writer thread deflates
while the making thread samples the next window, :mod:`nurbscnc.output.background`), its
deflated bytes kept in memory while the output fits in one window and spooled to an unnamed
temporary file otherwise, and the members are laid out at the end: local header, data;
then the central directory.

A member's data is its .npy header, deflated on its own and ended by a sync flush (a
byte-aligned, non-final deflate block), followed by the column's own deflate stream: one
valid deflate stream (pigz joins its blocks the same way). The column's stream starts with
the probe that decides whether it is deflated at all: a column whose first
:data:`NPZ_PROBE_ROWS` rows deflate to more than :data:`NPZ_STORE_RATIO` of their size is
stored (x and y of long CAM programs: deflating them costs half the time and saves 5 % of
the file). The probe's deflate is the start of the member's, not a second pass over it.

The bytes do not depend on how the rows are split into windows (zlib's stream does not
depend on how its input is fed), and the choices are the ones the whole columns give.
"""

from __future__ import annotations

import io
import struct
import zipfile
import zlib

import numpy as np

#: Deflate level of the NPZ members (zlib's 1–9). Level 1, not ``np.savez_compressed``'s
#: default 6: on the 200,000-line spiral's reference points (40.6 MB raw) it writes 19.1 MB
#: instead of 18.8 MB (+1.6 %) in 55 % of the time (3.5 s against 6.3 s on a loaded
#: machine; deflate was the largest single cost of ``run -o x.npz``); any zip reader and
#: ``numpy.load`` read every level.
NPZ_DEFLATE_LEVEL = 1
#: A column whose first :data:`NPZ_PROBE_ROWS` rows deflate (zlib format: the stream and 6
#: bytes) to more than this share of their size is stored, not deflated: on the
#: 200,000-line spiral x and y deflate to 92 % (0.26 s each) and feed to 78 %, t, z, piece
#: and line to 10–24 %; storing x and y costs 0.9 MB (5 %) of 19.1 MB and saves half the
#: deflate time. The probe is the column's own first rows, so the choice (and the file)
#: does not depend on the windows. (8,192 rows would probe an eighth as long, but read the
#: spiral's x and y as deflatable.)
NPZ_STORE_RATIO = 0.85
NPZ_PROBE_ROWS = 1 << 16
#: Bytes per read when a spooled column is copied into its member.
SPOOL_BLOCK = 1 << 24
#: The zlib format's header and Adler-32 trailer around a deflate stream [bytes].
_ZLIB_WRAPPING = 6
#: Zip records (APPNOTE.TXT 4.3): central directory entry, end of central directory, and
#: the zip64 end record and its locator.
_CENTRAL = struct.Struct("<4s4B4HL2L5H2L")
_END = struct.Struct("<4s4H2LH")
_END64 = struct.Struct("<4sQ2H2L4Q")
_END64_LOCATOR = struct.Struct("<4sLQL")
_ZIP64_LIMIT = (1 << 31) - 1


def npy_header(dtype: np.dtype, count: int) -> bytes:
    """The .npy header of a 1-D C-order array of ``count`` items of ``dtype``: what
    ``np.save`` writes before the data (format version 1.0: the header is short)."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buf,
        {"descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False, "shape": (count,)},
    )
    return buf.getvalue()


def _deflater():
    return zlib.compressobj(NPZ_DEFLATE_LEVEL, zlib.DEFLATED, -15)


class _Column:
    """One member being made: its .npy header, its data stream (deflated from the probe on,
    or stored), CRC-32 and sizes."""

    def __init__(self, name: str, dtype: np.dtype, count: int, probe: bytes):
        self.name = f"{name}.npy"
        header = npy_header(dtype, count)
        self.crc = zlib.crc32(probe, zlib.crc32(header))
        self.size = len(header) + len(probe)
        self._zip = _deflater()
        start = self._zip.compress(probe)
        probed = len(start) + len(self._zip.copy().flush()) + _ZLIB_WRAPPING
        self.deflated = not probe or probed <= NPZ_STORE_RATIO * len(probe)
        if self.deflated:
            head = _deflater()
            self.head = head.compress(header) + head.flush(zlib.Z_SYNC_FLUSH)
            self.first = start
        else:
            self._zip = None
            self.head, self.first = header, probe

    def add(self, data: bytes) -> bytes:
        """The member's bytes for the next rows ``data`` (raw) of the column."""
        self.crc = zlib.crc32(data, self.crc)
        self.size += len(data)
        return self._zip.compress(data) if self.deflated else data

    def end(self) -> bytes:
        """The member's last bytes (the end of its deflate stream)."""
        return self._zip.flush() if self.deflated else b""

    def info(self, compressed: int, offset: int) -> zipfile.ZipInfo:
        """The member's zip entry: ``compressed`` bytes of data at ``offset``."""
        info = zipfile.ZipInfo(self.name)  # 1980-01-01, as ZipFile.open(name, "w") dates it
        info.compress_type = zipfile.ZIP_DEFLATED if self.deflated else zipfile.ZIP_STORED
        info.external_attr = 0o600 << 16  # rw------- as ZipFile.open(name, "w") makes it
        info.file_size, info.compress_size, info.CRC = self.size, compressed, self.crc
        info.header_offset = offset
        return info


class _Parts:
    """Each column's member bytes after its head: in memory while the output is one window
    (a whole-array output never spools), appended to a spool file from the second window on
    (memory: one window)."""

    def __init__(self, columns: int, spool_dir: str | None):
        self._dir = spool_dir
        self._spool = None
        self._parts: list[list] = [[] for _ in range(columns)]

    def put(self, j: int, data: bytes, spill: bool = False) -> None:
        """Column ``j``'s next bytes; ``spill``: from a later window (start spooling)."""
        if spill and self._spool is None:
            import tempfile

            self._spool = tempfile.TemporaryFile(dir=self._dir)
            for parts in self._parts:  # the first window's bytes go too
                parts[:] = [self._spooled(p) for p in parts]
        if data:
            self._parts[j].append(data if self._spool is None else self._spooled(data))

    def _spooled(self, data: bytes) -> tuple[int, int]:
        offset = self._spool.seek(0, 2)
        self._spool.write(data)
        return (offset, len(data))

    def size(self, j: int) -> int:
        return sum(p[1] if isinstance(p, tuple) else len(p) for p in self._parts[j])

    def copy(self, j: int, out) -> None:
        """Column ``j``'s bytes, in order, to ``out``."""
        for p in self._parts[j]:
            if not isinstance(p, tuple):
                out.write(p)
                continue
            offset, left = p
            self._spool.seek(offset)
            while left > 0:
                block = self._spool.read(min(SPOOL_BLOCK, left))
                if not block:
                    raise OSError("the spooled columns came back short")
                out.write(block)
                left -= len(block)

    def close(self) -> None:
        if self._spool is not None:
            self._spool.close()


def write_npz(fh, spool_dir: str | None, names, windows, count: int) -> None:
    """Named 1-D columns, given window by window (tuples of columns, rows in order, ``count``
    rows in all), as an NPZ on the binary file ``fh`` (module doc). A window of more rows
    than announced, or fewer rows in all, is a ValueError (the caller's output is then
    discarded)."""
    windows = iter(windows)
    head, rows = [], 0  # the windows that hold the first NPZ_PROBE_ROWS rows
    for window in windows:
        head.append([np.asarray(c) for c in window])
        rows += len(head[-1][0])
        # All rows in hand: go on without waiting for the end of the windows (the maker
        # may still be summarising this one; a window too many is found at the end).
        if rows >= min(NPZ_PROBE_ROWS, count):
            break
    if not head:
        raise ValueError("no rows to write")
    if rows > count:
        raise ValueError(f"more rows than the {count} announced")
    dtypes = [c.dtype for c in head[0]]
    joined = [
        np.ascontiguousarray(np.concatenate([w[j] for w in head]), dtype=d)
        for j, d in enumerate(dtypes)
    ]
    columns = [
        _Column(name, d, count, col[:NPZ_PROBE_ROWS].tobytes())
        for name, d, col in zip(names, dtypes, joined)
    ]
    parts = _Parts(len(columns), spool_dir)
    try:
        for j, (column, col) in enumerate(zip(columns, joined)):
            parts.put(j, column.first)
            parts.put(j, column.add(col[NPZ_PROBE_ROWS:].tobytes()))
        del joined, head
        for window in windows:
            cols = [np.ascontiguousarray(np.asarray(c), dtype=d) for c, d in zip(window, dtypes)]
            rows += len(cols[0])
            if rows > count:
                raise ValueError(f"more rows than the {count} announced")
            for j, (column, col) in enumerate(zip(columns, cols)):
                parts.put(j, column.add(col.tobytes()), spill=True)
        if rows != count:
            raise ValueError(f"{rows} rows written, {count} announced")
        for j, column in enumerate(columns):
            parts.put(j, column.end())
        _lay_out(fh, columns, parts)
    finally:
        parts.close()


class _Counted:
    """Writes to ``fh`` counting the bytes (the zip's offsets: ``fh`` may be a pipe, where
    ``tell`` fails)."""

    def __init__(self, fh):
        self._fh, self.at = fh, 0

    def write(self, data) -> None:
        self._fh.write(data)
        self.at += len(data)

    def tell(self) -> int:
        return self.at


def _lay_out(fh, columns: list[_Column], parts: _Parts) -> None:
    """The members (local header, head, data) and the central directory, as zipfile writes
    an NPZ (zip64 extra fields on every local header, as ``np.savez`` forces them; the
    sizes and CRC known before the data, so no data descriptors, on a pipe too)."""
    fh = _Counted(fh)
    infos = []
    for j, column in enumerate(columns):
        info = column.info(len(column.head) + parts.size(j), fh.tell())
        fh.write(info.FileHeader(zip64=True))
        fh.write(column.head)
        parts.copy(j, fh)
        infos.append(info)
    start = fh.tell()
    for info in infos:  # the central directory, as zipfile's _write_end_record makes it
        big = info.file_size > _ZIP64_LIMIT or info.compress_size > _ZIP64_LIMIT
        extra = [info.file_size, info.compress_size] if big else []
        offset = info.header_offset
        if offset > _ZIP64_LIMIT:
            extra.append(offset)
            offset = 0xFFFFFFFF
        data = struct.pack(f"<HH{len(extra)}Q", 1, 8 * len(extra), *extra) if extra else b""
        least = 45 if extra else 0  # zip64 needs version 4.5
        y, mo, d, h, mi, sec = info.date_time
        name = info.filename.encode("ascii")
        fh.write(
            _CENTRAL.pack(
                b"PK\x01\x02",
                max(least, info.create_version),
                info.create_system,
                max(least, info.extract_version),
                info.reserved,
                info.flag_bits,
                info.compress_type,
                h << 11 | mi << 5 | sec // 2,
                (y - 1980) << 9 | mo << 5 | d,
                info.CRC,
                0xFFFFFFFF if big else info.compress_size,
                0xFFFFFFFF if big else info.file_size,
                len(name),
                len(data),
                0,
                0,
                info.internal_attr,
                info.external_attr,
                offset,
            )
        )
        fh.write(name)
        fh.write(data)
    end = fh.tell()
    count, size, offset = len(infos), end - start, start
    if offset > _ZIP64_LIMIT or size > _ZIP64_LIMIT:
        fh.write(_END64.pack(b"PK\x06\x06", 44, 45, 45, 0, 0, count, count, size, offset))
        fh.write(_END64_LOCATOR.pack(b"PK\x06\x07", 0, end, 1))
        size, offset = min(size, 0xFFFFFFFF), min(offset, 0xFFFFFFFF)
    fh.write(_END.pack(b"PK\x05\x06", 0, 0, count, count, size, offset, 0))
