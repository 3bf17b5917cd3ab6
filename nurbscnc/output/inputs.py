"""Reading an input file whole, bounded: a program, a tool table, a parameter file, a point
file or a trace.

Apart from the writers (:mod:`nurbscnc.output.files`) so that reading a program loads none
of their modules (zipfile, secrets: a tenth of the start-up of ``plan`` on a short program).
"""

from __future__ import annotations

import sys

from nurbscnc.errors import DataError, OutputError

#: The largest input read whole [bytes] (a program, a point CSV, a trace, a tool table):
#: about 15 million lines of CAM output, whose moves would need some 5 GB to plan. A stream
#: that never ends (/dev/urandom) is refused past it instead of filling the memory.
MAX_INPUT_BYTES = 512 << 20


def read_input_bytes(path: str, what: str, error=DataError) -> bytes:
    """The bytes of ``path`` (``-``: stdin), at most :data:`MAX_INPUT_BYTES`. OSError →
    OutputError (exit 3); a larger input → ``error`` (exit 2) naming it as ``what``."""
    try:
        if path == "-":
            data = sys.stdin.buffer.read(MAX_INPUT_BYTES + 1)
        else:
            with open(path, "rb") as fh:
                data = fh.read(MAX_INPUT_BYTES + 1)
    except OSError as exc:
        raise OutputError(f"cannot read {path}: {exc.strerror or exc}") from None
    if len(data) > MAX_INPUT_BYTES:
        raise error(
            f"{what} is larger than {MAX_INPUT_BYTES:,} bytes "
            f"({MAX_INPUT_BYTES / 2**20:g} MiB), the most nurbscnc reads"
        )
    return data
