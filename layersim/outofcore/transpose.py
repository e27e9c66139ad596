"""Transposes of sparse matrices that may be held in a file."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from .assemble import csr_arrays
from .rowpieces import RowPieces


def transposed(mat) -> sps.csr_matrix:
    """``mat^T`` in CSR. A matrix in a file (:class:`~layersim.outofcore.rowpieces.RowPieces`) is
    transposed by a counting sort over its pieces, read twice (column counts, then each
    piece's entries scattered to their rows of the transpose), so that only the transpose
    and one piece are resident; the one conversion of scipy (C++) otherwise."""
    if isinstance(mat, RowPieces) and mat.wrapped is not None:
        mat = mat.wrapped
    if not isinstance(mat, RowPieces):
        return sps.csc_matrix(mat).T.tocsr()     # the CSC -> CSR conversion makes the copy
    n_rows, n_cols = mat.shape
    counts = np.zeros(n_cols, np.int64)
    for _, piece in mat:
        counts += np.bincount(piece.indices, minlength=n_cols)
    indptr, indices, data = csr_arrays(n_cols, n_rows, int(counts.sum()))
    np.cumsum(counts, out=indptr[1:])
    free = indptr[:-1].astype(np.int64)          # next free place in each row of mat^T
    for start, piece in mat:
        by_col = piece.tocsc()                   # rows ascending within each column
        del piece
        n = np.diff(by_col.indptr)
        col = np.repeat(np.arange(n_cols, dtype=np.int32), n)
        at = free[col] + (np.arange(by_col.nnz) - by_col.indptr[col])
        indices[at] = by_col.indices + start
        data[at] = by_col.data
        free += n
        del by_col, col, at
    return sps.csr_matrix((data, indices, indptr), shape=(n_cols, n_rows))
