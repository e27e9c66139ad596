"""The bytes of a table file, with a read failure reported as a format error that names the
file (so that the command line prints it on one line)."""

from __future__ import annotations

from pathlib import Path

from ..errors import FileFormatError

__all__ = ["read_bytes"]


def read_bytes(path, size: int = -1) -> bytes:
    """The bytes of the file at ``path``: all of them, or at most the first ``size``.

    Raises
    ------
    FileFormatError
        The file cannot be read (missing, a folder, no permission); the message names it and
        the system's reason.
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            return fh.read(size)
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read ({exc.strerror or exc})") from None
