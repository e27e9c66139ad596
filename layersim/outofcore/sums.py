"""Sums of sparse matrices in pieces of rows, and pruning of small entries."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from .rowpieces import RowPieces
from .rows import CHUNK_ENTRIES, row_spans

def sum_pieces(a, b, alpha: float = 1.0, beta: float = 1.0,
               directory: str | None = None) -> RowPieces:
    """``alpha a + beta b`` as :class:`~layersim.outofcore.rowpieces.RowPieces`, summed in chunks
    of rows of about :data:`CHUNK_ENTRIES` entries (read piece by piece of ``a`` if it is
    given as RowPieces), kept in a file in ``directory`` (in memory without one): the caller
    releases ``a`` and ``b`` before assembling the sum (``to_csr(release=True)``), which then
    takes the result's memory only, where a sum formed at once holds both operands beside
    it."""
    b = sps.csr_matrix(b)
    if a.shape != b.shape:
        raise ValueError(f"sum_pieces: shapes {a.shape} and {b.shape} differ")
    out = RowPieces(a.shape, directory)
    for start, stop, rows in summed_rows(a, b):
        part = beta * b[start:stop]
        part = sps.csr_matrix(part if rows is None else alpha * rows + part)
        out.append(start, part.indptr, part.indices, part.data)
        del part, rows
    return out


def summed_rows(a, b):
    """``(start, stop, rows of a or None)`` over all rows for :func:`sum_pieces`: spans of
    about :data:`CHUNK_ENTRIES` entries of ``a + b``, within the pieces of ``a`` if it is
    given as RowPieces (and over the rows between them, ``a`` empty there)."""
    if isinstance(a, RowPieces) and a.wrapped is not None:
        a = a.wrapped
    n = a.shape[0]
    if not isinstance(a, RowPieces):
        a = sps.csr_matrix(a)
        both = a.indptr.astype(np.int64) + b.indptr
        for start, stop in row_spans(both, 0, n, CHUNK_ENTRIES):
            yield start, stop, a[start:stop]
        return
    done = 0
    for start, piece in a:
        for span in row_spans(b.indptr, done, start, CHUNK_ENTRIES):
            yield *span, None
        done = start + piece.shape[0]
        both = piece.indptr.astype(np.int64) + (b.indptr[start:done + 1] - b.indptr[start])
        for lo, hi in row_spans(both, 0, piece.shape[0], CHUNK_ENTRIES):
            yield start + lo, start + hi, piece[lo:hi]
        del piece
    for span in row_spans(b.indptr, done, n, CHUNK_ENTRIES):
        yield *span, None


def prune(mat, tolerance: float):
    """Drop entries below ``tolerance`` times the largest magnitude of ``mat``.

    A CSR matrix is pruned in place (pass a temporary) and returned; other formats are
    converted. :class:`~layersim.outofcore.rowpieces.RowPieces` are pruned piece by piece (one
    pass for the largest magnitude, one to filter) into new RowPieces, these emptied."""
    if isinstance(mat, RowPieces) and mat.wrapped is None:
        cut = tolerance * max((np.abs(p.data).max() for _, p in mat if p.nnz), default=0.0)

        def drop(start, indptr, indices, data):
            piece = drop_below(sps.csr_matrix((data, indices, indptr),
                                               shape=(indptr.size - 1, mat.shape[1])), cut)
            return start, piece.indptr, piece.indices, piece.data
        return mat.filtered(drop)
    mat = sps.csr_matrix(mat.wrapped if isinstance(mat, RowPieces) else mat)
    return drop_below(mat, tolerance * np.abs(mat.data).max()) if mat.nnz else mat


def drop_below(mat: sps.csr_matrix, cut: float) -> sps.csr_matrix:
    """``mat`` without its entries of magnitude below ``cut`` (in place)."""
    mat.data[np.abs(mat.data) < cut] = 0.0
    mat.eliminate_zeros()
    return mat
