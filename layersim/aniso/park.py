"""Operator blocks parked on disk between their uses (out-of-core adding).

Below an opaque base the coupled adding equations (:mod:`layersim.aniso.adding`) use the top
layer's ``Rt1`` and ``Tbt1`` only after the solve, and the products and the factorisation
before it are the largest transients of a solve: on Table 2 row 6 of seed 000 the two blocks
are 270 MiB held idle through a phase that peaks at 1.2 GiB. A :class:`Parked` block is
written to a file when it goes idle and read back (the file removed) when it is needed:
0.7 s to write and 0.07 s to read back for those two blocks on the CI machine (ext4), the
file mostly still in the page cache, which the system reclaims under memory pressure where a
resident block cannot be.

What is parked in a solve (:func:`layersim.solve` of an anisotropic stack): the blocks of an
operator that an adding step will consume, as the projection builds them
(:func:`~layersim.ingredients.aniso_microfacet.aniso_interface_operator` with ``park_dir``;
read back by the adding step when it needs them, the top's ``Rt`` and ``Tbt`` after the
solve), and, before that, the projected parts of each block and a triangle of pairs while its
reciprocal image is formed; in the adding step the bottom's ``Rt`` (read piece by piece by
both products), the right-hand side ``Rt2 Ttb1``, ``K`` and ``Tbt1 Z1``, each written piece by
piece as it is formed (:class:`~layersim.aniso.rowpieces.RowPieces` on a :class:`Spool`), the
right-hand sides grouped for the substitutions and the parts of the solution (a
:class:`Spool`), and the result while its reciprocal image is formed.

Every file is a :class:`Spool`, removed from the directory as it is created (it lives while
held open): a killed solve leaves no file behind.

Parking needs a directory on a disk: a RAM-backed file system (tmpfs, ramfs) would move the
block to memory that is not even counted as the process's, so :func:`park_directory` answers
``None`` there and the blocks stay resident. ``LAYERSIM_PARK_DIR`` names the directory
(default: :func:`tempfile.gettempdir`); ``LAYERSIM_PARK_DIR=off`` turns parking off.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np
import scipy.sparse as sps

from ..memory import empty_sparse, sparse_bytes

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
    where = os.environ.get("LAYERSIM_PARK_DIR", "").strip()
    if where.lower() == "off":
        return None
    where = where or tempfile.gettempdir()
    if not os.path.isdir(where) or _filesystem(where) in _RAM_FILESYSTEMS:
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

    The file is a :class:`Spool` of one item (the CSR arrays), as the pieces of
    :class:`~layersim.aniso.rowpieces.RowPieces` are.
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


def _unlink(path: str | None) -> None:
    """Remove a file of ours if there is one (already gone is fine)."""
    if path is not None:
        try:
            os.remove(path)
        except OSError:
            pass


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


class Spool:
    """Tuples of arrays appended one by one and read back in order, in a temporary file in
    ``directory`` or, without one, in memory: the parts of a result formed piece by piece
    (the pieces of ``K`` of the adding equations,
    :class:`~layersim.aniso.rowpieces.RowPieces`; the solution's parts in the banded solve)
    wait on disk instead of beside the work that forms them.

    The file is removed from the directory as soon as it is created and lives only while the
    spool holds it open (until :meth:`close`, or until the object goes): a solve that is
    killed (out of memory, a signal) leaves no file behind, where the named files did (260
    MiB each for ``K`` of Table 2 row 6 of seed 000). Where an open file cannot be removed
    (Windows), it keeps its name until :meth:`close`.

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
