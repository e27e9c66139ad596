"""Sparse products formed in chunks of rows, filtered as they come.

The products of the coupled adding equations have several times the entries they keep once
pruned; formed at once, the unpruned product and a COO -> CSR conversion of it would be the
largest arrays of a solve. :func:`product` forms ``a @ b`` in chunks of rows of ``a`` of at most
:data:`PRODUCT_CHUNK_FLOPS` multiply-adds (which bounds each chunk's unpruned entries whatever
the operators' size), runs the chunks on :mod:`layersim.threads` (SciPy's sparse product
releases the GIL), passes each through a filter as it comes and keeps the kept entries as CSR
pieces, in memory or in a file.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from ..threads import parallel_map, workers
from .assemble import stack_rows, trim_heap
from .memory import release
from .rowpieces import RowPieces
from .rows import row_chunks

#: Bound on the multiply-adds of one chunk of :func:`product`: it bounds the chunk's
#: unpruned entries, and with the heap trimmed as the chunks are placed (:func:`trim_heap`)
#: the product's transient memory, at no cost in time against a few large chunks.
PRODUCT_CHUNK_FLOPS = 1 << 25


def product_row_chunks(a: sps.csr_matrix, b: sps.csr_matrix,
                       flops: int = PRODUCT_CHUNK_FLOPS) -> list:
    """Starts of the row chunks of ``a`` whose products with ``b`` take at most ``flops``
    multiply-adds each (one row at least), which bounds the entries of each chunk's unpruned
    product (ends with ``a.shape[0]``)."""
    per_entry = np.diff(b.indptr).astype(np.int64)
    bound = np.zeros(a.shape[0] + 1, np.int64)     # multiply-adds of rows 0 .. r-1
    for lo, hi, rows in row_chunks(a):
        if hi > lo:
            np.add.at(bound, rows + 1, per_entry[a.indices[lo:hi]])
    np.cumsum(bound, out=bound)
    starts, at = [0], 0
    while at < a.shape[0]:
        nxt = int(np.searchsorted(bound, bound[at] + flops, side="right")) - 1
        at = max(at + 1, min(nxt, a.shape[0]))
        starts.append(at)
    return starts


def csr_product(a: sps.csr_matrix, lo: int, hi: int, b: sps.csr_matrix) -> tuple:
    """CSR arrays ``(indptr, indices, data)`` of ``a[lo:hi] @ b`` (SciPy's product, entries
    in its order); the rows of ``a`` are read in place (no copy of the slice)."""
    a0, a1 = int(a.indptr[lo]), int(a.indptr[hi])
    rows = sps.csr_matrix((a.data[a0:a1], a.indices[a0:a1], a.indptr[lo:hi + 1] - a0),
                          shape=(hi - lo, a.shape[1]))
    c = sps.csr_matrix(rows @ b)
    return c.indptr, c.indices, c.data


def int32_indices(mat: sps.csr_matrix) -> sps.csr_matrix:
    """``mat`` with 32-bit index arrays where its entries and columns allow (as is)."""
    if mat.indptr.dtype == np.int32 and mat.indices.dtype == np.int32:
        return mat
    if max(mat.nnz, mat.shape[1]) >= np.iinfo(np.int32).max:
        return mat
    return sps.csr_matrix((mat.data, mat.indices.astype(np.int32),
                           mat.indptr.astype(np.int32)), shape=mat.shape)


def product(a, b, keep=None, pieces: bool = False, directory: str | None = None):
    """``a @ b`` (entries in SciPy's order), filtered by ``keep`` without holding the
    unfiltered product: it is formed in chunks of rows of ``a`` of at most
    :data:`PRODUCT_CHUNK_FLOPS` multiply-adds (:func:`product_row_chunks`), each filtered as it
    comes. The chunks are kept as CSR pieces and copied into the result one by one, each
    released as it is copied: the result's pages become resident as the pieces are freed, so
    that the assembly needs about one copy of the result (12 bytes per entry) instead of the
    three of a COO -> CSR conversion (44 bytes per entry).

    Parameters
    ----------
    a : sparse (M, K) or RowPieces
        Read piece by piece if given as :class:`~layersim.outofcore.rowpieces.RowPieces`
        (e.g. in a file): then only ``b`` is resident whole.
    b : sparse (K, N)
    keep : filter, optional
        ``keep(rows, cols, values)`` -> the triplet of the entries to keep, called on each chunk
        as it is formed (it may learn from the stream, e.g. pair maxima), and
        ``keep.final_filter(rows, cols, values)`` on each kept chunk once all are formed (e.g.
        :class:`~layersim.aniso.pairs.PairPruner`). None keeps every entry.
    pieces : bool
        Return a :class:`~layersim.outofcore.rowpieces.RowPieces` instead, its pieces written
        to a file in ``directory`` as they are formed (kept in memory without one) and never
        assembled: only the operands and the pieces in flight are resident (for ``K`` of the
        adding equations, which the banded solve reads piece by piece).
    directory : str, optional

    Returns
    -------
    scipy.sparse.csr_matrix (M, N) or RowPieces
    """
    b = int32_indices(sps.csr_matrix(b))        # converted once, not per chunk
    shape = (a.shape[0], b.shape[1])
    store = RowPieces(shape, directory) if pieces else None
    kept = []
    formed = trimmed = 0
    threads = workers()
    for offset, rows in (a if isinstance(a, RowPieces) else [(0, sps.csr_matrix(a))]):
        bounds = product_row_chunks(rows, b)
        chunks = list(zip(bounds[:-1], bounds[1:]))
        for at in range(0, len(chunks), threads):      # one chunk per thread in flight
            batch = chunks[at:at + threads]
            parts = parallel_map(lambda c, rows=rows: csr_product(rows, c[0], c[1], b),
                                 batch)
            for (start, _), part in zip(batch, parts):
                formed += part[1].size
                piece = _filter_piece(keep, offset + start, *part, True)
                if store is None:
                    kept.append(piece)
                else:
                    store.append(*piece)
            del parts, part, piece
            # the chunks' temporaries come from the heap, whose freed pages otherwise pile up
            trimmed = trim_heap(formed, trimmed)
        del rows
    final = (lambda *piece: piece) if keep is None else \
        (lambda *piece: _filter_piece(keep, *piece, False))
    if store is not None:
        out = store.filtered(final)
    else:
        for k in range(len(kept)):
            kept[k] = final(*kept[k])
        out = stack_rows(kept, shape)
    release()                       # the chunks' products and pieces came from the heap
    return out


def _filter_piece(keep, start: int, indptr, indices, data, update: bool):
    """One CSR piece of rows ``start ..`` filtered by ``keep`` (``update``: its ``__call__``,
    else its ``final_filter``; None keeps every entry), as ``(start, indptr, indices, data)``
    with 32-bit indices."""
    if keep is None:
        return start, np.asarray(indptr, np.int64), indices.astype(np.int32, copy=False), data
    rows = np.repeat(np.arange(start, start + indptr.size - 1, dtype=np.int32), np.diff(indptr))
    r, c, v = (keep if update else keep.final_filter)(rows, indices, data)
    counts = np.bincount(r - start, minlength=indptr.size - 1)
    ptr = np.zeros(indptr.size, np.int64)
    np.cumsum(counts, out=ptr[1:])
    return start, ptr, c.astype(np.int32, copy=False), v
