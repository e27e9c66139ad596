"""Blocks parked on disk between their uses.

A :class:`Parked` block is written to a file when it goes idle and read back (the file
removed) when it is needed. The file mostly stays in the page cache, which the system reclaims
under memory pressure where a resident block cannot be: below an opaque base the coupled
adding equations (:mod:`layersim.aniso.adding`) use the top layer's ``Rt1`` and ``Tbt1`` only
after the solve, and the products and the factorisation before it are the largest transients
of a solve, so those two blocks wait on disk meanwhile. What a solve parks is listed in
:mod:`layersim.outofcore.workspace`.

Every file is a :class:`~layersim.outofcore.spool.Spool`, removed from the directory as it is
created (it lives while held open): a killed solve leaves no file behind.

Parking needs a directory on a disk: a RAM-backed file system (tmpfs, ramfs) would move the
block to memory that is not even counted as the process's, so :func:`park_directory` answers
``None`` there and the blocks stay resident. ``layersim.config.settings().park_dir``
(``LAYERSIM_PARK_DIR``) names the directory (default: :func:`tempfile.gettempdir`; None,
``LAYERSIM_PARK_DIR=off``, turns parking off).
"""

from __future__ import annotations

import os

import scipy.sparse as sps

from ..config import settings
from .memory import empty_sparse, sparse_bytes
from .spool import Spool

#: Blocks smaller than this stay resident (parking them saves little and costs a file).
PARK_MIN_BYTES = 16 << 20

#: File systems whose files live in memory.
_RAM_FILESYSTEMS = {"tmpfs", "ramfs", "devtmpfs"}


def _filesystem(path: str) -> str | None:
    """Type of the file system holding ``path`` (the longest mount point above it, from
    ``/proc/mounts``), or None where that is not readable (non-Linux)."""
    try:
        with open("/proc/mounts") as f:
            mounts = [line.split()[1:3] for line in f]
    except OSError:
        return None
    path = os.path.realpath(path)
    best, kind = "", None
    for point, fstype in mounts:
        point = point.replace("\\040", " ")
        inside = path == point or path.startswith(point.rstrip("/") + "/")
        if inside and len(point) > len(best):
            best, kind = point, fstype
    return kind


def park_directory(need: int = 0) -> str | None:
    """The directory to park ``need`` bytes in, or None (parking off, the directory missing,
    RAM-backed or without twice ``need`` bytes free)."""
    where = settings().park_dir
    if where is None or not os.path.isdir(where) or _filesystem(where) in _RAM_FILESYSTEMS:
        return None
    try:
        st = os.statvfs(where)
    except OSError:
        return None
    return where if st.f_bavail * st.f_frsize >= 2 * need else None


class Parked:
    """A CSR matrix written to a file, read back once by :meth:`load`.

    Parameters
    ----------
    mat : scipy.sparse.csr_matrix
        Its arrays are written and the caller's reference is the only one to drop: the
        matrix object itself is emptied (shape kept), so that its memory goes now.
    directory : str
    head : int
        Keep a copy of the first ``head`` rows resident (:attr:`head`; e.g. the slot-0 rows
        that the energy check of a projected operator reads,
        :meth:`~layersim.aniso.operator.AnisoOperator.albedo_slots`).

    The file is a :class:`~layersim.outofcore.spool.Spool` of one item (the CSR arrays), as
    the pieces of
    :class:`~layersim.outofcore.rowpieces.RowPieces` are.
    """

    def __init__(self, mat: sps.csr_matrix, directory: str, head: int = 0):
        self.shape = mat.shape
        self.nnz = int(mat.nnz)
        self.bytes = sparse_bytes(mat)
        self.head = mat[:head].copy() if head else None
        self._spool = Spool(directory)
        self._spool.append((mat.indptr, mat.indices, mat.data))
        empty_sparse(mat)

    def load(self) -> sps.csr_matrix:
        """The matrix, read back; the file is removed."""
        if not self._spool.on_disk:
            raise RuntimeError("this parked block was already loaded")
        indptr, indices, data = next(iter(self._spool))
        self._spool.close()
        return sps.csr_matrix((data, indices, indptr), shape=self.shape)


def park(mat, directory: str | None, head: int = 0):
    """``Parked(mat, directory, head)`` for a CSR matrix of at least :data:`PARK_MIN_BYTES`
    when ``directory`` is given, else ``mat`` itself."""
    if directory is None or not sps.issparse(mat) or mat.format != "csr":
        return mat
    if sparse_bytes(mat) < PARK_MIN_BYTES:
        return mat
    return Parked(mat, directory, head)


def unpark(item):
    """The matrix of a :class:`Parked` block (loaded), or ``item`` itself."""
    return item.load() if isinstance(item, Parked) else item


