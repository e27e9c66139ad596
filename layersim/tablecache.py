"""Tables computed once and kept on disk under ``settings().cache_dir`` (``LAYERSIM_CACHE_DIR``):
where a table's file lies, reading it back and writing it atomically.

The cache only saves time: a missing or unreadable file reads as absent (the caller computes the
table again and replaces it), and a directory that cannot be written leaves the table in memory.
Callers check that what they read is the table they asked for (a key or the shape).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from .config import settings


def path(*parts: str) -> Path | None:
    """The file ``parts`` under the cache directory; None when the cache is off."""
    root = settings().cache_dir
    return None if root is None else Path(root).joinpath(*parts)


def read(file: Path | None) -> dict | None:
    """The arrays of the ``.npz`` file ``file`` by name, or None when there is none or it
    cannot be read."""
    if file is None or not file.exists():
        return None
    try:
        with np.load(file) as data:
            return {name: data[name] for name in data.files}
    except (OSError, ValueError, KeyError):
        return None


def write(file: Path | None, **arrays) -> None:
    """Store ``arrays`` in the ``.npz`` file ``file``, atomically (a temporary file renamed
    into place); nothing when the cache is off or cannot be written."""
    if file is None:
        return
    try:
        file.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=file.parent, suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, file)
    except OSError:
        pass
