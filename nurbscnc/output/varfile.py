"""Writing LinuxCNC's parameter file (``rs274ngc.var``) back, atomically.

The text is :func:`nurbscnc.program.varfile.format_var_text`'s; it goes to a temporary file
beside the old one, which then replaces it (:func:`nurbscnc.output.files.atomic_output`):
a write that fails leaves the old file whole, and nothing else is touched (LinuxCNC keeps a
``.bak`` copy too; nurbscnc's rename makes the new file appear whole or not at all).
"""

from __future__ import annotations

from nurbscnc.errors import OutputError
from nurbscnc.output.files import atomic_output


def write_var_file(path: str, text: str) -> None:
    """Replace the parameter file ``path`` with ``text`` (OutputError naming the file when
    it cannot be written; the old file is then as it was)."""
    try:
        with atomic_output(path) as fh:
            fh.write(text)
            fh.flush()
    except OSError as exc:
        raise OutputError(
            f"cannot write the parameter file {path}: {exc.strerror or exc}"
        ) from None
