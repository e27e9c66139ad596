"""Tuples of arrays written one by one to an unnamed temporary file and read back in order."""

from __future__ import annotations

import os
import tempfile

import numpy as np


def _unlink(path: str | None) -> None:
    """Remove a file of ours if there is one (already gone is fine)."""
    if path is not None:
        try:
            os.remove(path)
        except OSError:
            pass


class Spool:
    """Tuples of arrays appended one by one and read back in order, in a temporary file in
    ``directory`` or, without one, in memory: the parts of a result formed piece by piece
    (the pieces of ``K`` of the adding equations,
    :class:`~layersim.outofcore.rowpieces.RowPieces`; the solution's parts in the banded
    solve) wait on disk instead of beside the work that forms them.

    The file is removed from the directory as soon as it is created and lives only while the
    spool holds it open (until :meth:`close`, or until the object goes): a solve that is
    killed (out of memory, a signal) leaves no file behind. Where an open file cannot be
    removed (Windows), it keeps its name until :meth:`close`.

    Parameters
    ----------
    directory : str, optional
    """

    def __init__(self, directory: str | None = None):
        self._items: list = []          # arrays (in memory) or [(offset, ((dtype, size), ..))]
        self._file = self._name = self.directory = None
        if directory is not None:
            fd, name = tempfile.mkstemp(prefix="layersim-spool-", suffix=".bin", dir=directory)
            self._file = os.fdopen(fd, "w+b")
            self.directory = directory
            try:
                os.unlink(name)
            except OSError:
                self._name = name       # removed by close()

    @property
    def on_disk(self) -> bool:
        return self._file is not None

    def __len__(self) -> int:
        return len(self._items)

    def append(self, arrays: tuple) -> None:
        """Add one tuple of (1-D) arrays (as ``list.append``)."""
        if self._file is None:
            self._items.append(tuple(arrays))
            return
        offset = self._file.seek(0, os.SEEK_END)
        layout = []
        for a in arrays:
            a = np.ascontiguousarray(a)
            a.tofile(self._file)
            layout.append((a.dtype, a.size))
        self._items.append((offset, tuple(layout)))

    def _read(self, item) -> tuple:
        if self._file is None:
            return item
        offset, layout = item
        self._file.seek(offset)
        return tuple(np.fromfile(self._file, dtype, size) for dtype, size in layout)

    def __iter__(self):
        for item in self._items:
            yield self._read(item)

    def drain(self):
        """Iterate once more, releasing each tuple as it is read (and the file at the end)."""
        for k in range(len(self._items)):
            item, self._items[k] = self._items[k], None
            yield self._read(item)
            del item
        self.close()

    def close(self) -> None:
        self._items = []
        if self._file is not None:
            self._file.close()
            self._file = None
        _unlink(self._name)
        self._name = self.directory = None

    def __del__(self):
        self.close()
