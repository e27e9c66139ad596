"""A sparse matrix held as consecutive pieces of rows, on disk between its uses.

The coupled adding equations (:mod:`layersim.aniso.adding`) solve with ``A = I - K``,
``K = Rt2 Rb1``, and the banded solve (:func:`layersim.aniso.banded.banded_solve`) reads ``K``
only row by row: its structure, its dense block rows over the band, the columns of the
eliminated unknowns and the residual check. Formed as one CSR matrix, ``K`` would be held
beside both its factors and then beside the dense block rows made from it.
:func:`~layersim.outofcore.products.product` instead writes each piece of rows to a
:class:`RowPieces` file as it is formed (the operands and one piece per thread resident), and
the solve reads the pieces back one at a time (from the page cache).

A :class:`RowPieces` without a directory keeps its pieces in memory (parking off, or a
RAM-backed temporary directory: :func:`layersim.outofcore.parking.park_directory`), and
:meth:`RowPieces.of` wraps a CSR matrix without copying it, so that callers read every
matrix the same way.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from .assemble import stack_rows
from .rows import row_spans
from .spool import Spool

_INDPTR, _INDICES, _DATA = np.dtype(np.int64), np.dtype(np.int32), np.dtype(np.float64)


class RowPieces:
    """A CSR matrix of shape ``shape`` as consecutive pieces of rows, appended in order
    (rows not covered by any piece are empty).

    Parameters
    ----------
    shape : (int, int)
    directory : str, optional
        Keep the pieces in a temporary file there (a :class:`~layersim.outofcore.spool.Spool`,
        removed by :meth:`close` or when the object goes); None keeps them in memory.
    """

    def __init__(self, shape: tuple, directory: str | None = None):
        self.shape = (int(shape[0]), int(shape[1]))
        self.nnz = 0
        self._starts: list = []        # first row of each piece
        self._spool = Spool(directory)
        self._csr = None               # wrapped matrix (of())

    @classmethod
    def of(cls, mat) -> "RowPieces":
        """Read a CSR matrix piece by piece (no copy; pieces of about
        :data:`~layersim.outofcore.rows.PIECE_ENTRIES` entries)."""
        if isinstance(mat, RowPieces):
            return mat
        out = cls(mat.shape)
        out._csr = sps.csr_matrix(mat)
        out.nnz = int(out._csr.nnz)
        return out

    @classmethod
    def written(cls, mat, directory: str | None) -> "RowPieces":
        """A CSR matrix copied piece by piece to a file in ``directory`` (:meth:`of` without
        one): once the caller drops its references, the matrix is out of memory while its
        pieces are read (e.g. to build its transpose beside them)."""
        if directory is None or isinstance(mat, RowPieces):
            return cls.of(mat)
        mat = sps.csr_matrix(mat)
        out = cls(mat.shape, directory)
        for start, stop in row_spans(mat.indptr, 0, mat.shape[0]):
            part = mat[start:stop]
            out.append(start, part.indptr, part.indices, part.data)
        return out

    @property
    def wrapped(self):
        """The CSR matrix that :meth:`of` wraps, or None."""
        return self._csr

    @property
    def on_disk(self) -> bool:
        return self._spool.on_disk

    def append(self, start: int, indptr, indices, data) -> None:
        """Add rows ``start .. start + len(indptr) - 2`` (``indptr`` from 0; after the rows
        of earlier pieces)."""
        if self._csr is not None:
            raise RuntimeError("RowPieces.of() wraps a matrix; it cannot be appended to")
        self._spool.append((np.asarray(indptr, _INDPTR), np.asarray(indices, _INDICES),
                            np.asarray(data, _DATA)))
        self._starts.append(int(start))
        self.nnz += int(indptr[-1])

    def _piece(self, arrays):
        ptr, idx, val = arrays
        return sps.csr_matrix((val, idx, ptr), shape=(ptr.size - 1, self.shape[1]))

    def __iter__(self):
        """``(start, piece)``: each piece a CSR matrix of its rows (all columns)."""
        if self._csr is not None:
            mat = self._csr
            for start, stop in row_spans(mat.indptr, 0, mat.shape[0]):
                yield start, mat[start:stop]
            return
        for start, arrays in zip(self._starts, self._spool):
            yield start, self._piece(arrays)

    # ---- what the banded solve reads -------------------------------------------------

    def row_counts(self) -> np.ndarray:
        """Entries per row, (N,)."""
        counts = np.zeros(self.shape[0], np.int64)
        for start, piece in self:
            counts[start:start + piece.shape[0]] = np.diff(piece.indptr)
        return counts

    def matmul(self, X):
        """``self @ X``, piece by piece: CSR for a sparse ``X``, an ndarray for a dense one."""
        if isinstance(X, np.ndarray):
            if self._csr is not None:
                return self._csr @ X
            out = np.zeros((self.shape[0], X.shape[1]), np.result_type(X, _DATA))
            for start, piece in self:
                out[start:start + piece.shape[0]] = piece @ X
            return out
        X = sps.csr_matrix(X)
        if self._csr is not None:
            return sps.csr_matrix(self._csr @ X)
        pieces = []
        for start, piece in self:
            pieces.append(sps.csr_matrix(piece @ X))
            del piece
        return _vstack_at(pieces, self._starts, (self.shape[0], X.shape[1]))

    def columns(self, cols) -> sps.csr_matrix:
        """``self[:, cols]`` (CSR)."""
        if self._csr is not None:
            return self._csr[:, cols]
        pieces = [piece[:, cols] for _, piece in self]
        return _vstack_at(pieces, self._starts, (self.shape[0], len(cols)))

    def to_csr(self, release: bool = False) -> sps.csr_matrix:
        """The whole matrix, its pieces read and copied one at a time (with ``release``,
        each dropped once copied and this object closed: no second copy of the matrix)."""
        if self._csr is not None:
            out = self._csr
        else:
            nnz = self.nnz
            items = zip(self._starts, self._spool.drain() if release else self._spool)
            out = stack_rows(((start, *arrays) for start, arrays in items), self.shape, nnz)
        if release:
            self.close()
        return out

    def diagonal(self) -> np.ndarray:
        """The main diagonal, (min(shape),)."""
        out = np.zeros(min(self.shape))
        for start, piece in self:
            d = piece.diagonal(k=start)
            out[start:start + d.size] = d
        return out

    def filtered(self, fn) -> "RowPieces":
        """A new RowPieces (same place: memory or a new file) of the pieces mapped by
        ``fn(start, indptr, indices, data) -> (start, indptr, indices, data)`` (e.g. a
        pruning); this one is emptied as they are read."""
        if self._csr is not None:
            raise RuntimeError("RowPieces.of() wraps a matrix; filter the matrix instead")
        out = RowPieces(self.shape, self._spool.directory)
        for start, arrays in zip(self._starts, self._spool.drain()):
            out.append(*fn(start, *arrays))
        self.close()
        return out

    def close(self) -> None:
        """Drop the pieces (and remove the file)."""
        self._spool.close()
        self._starts = []
        self._csr = None
        self.nnz = 0


def _vstack_at(pieces: list, starts: list, shape: tuple) -> sps.csr_matrix:
    """CSR matrix of ``shape`` whose rows ``starts[k] ..`` are ``pieces[k]`` (in order; other
    rows empty; ``pieces`` emptied)."""
    rows = [(s, p.indptr, p.indices, p.data) for s, p in zip(starts, pieces)]
    pieces.clear()
    return stack_rows(rows, shape)
