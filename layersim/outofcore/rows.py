"""Spans and chunks of the rows of CSR matrices, sized by their entries.

Passes over the matrices of coupled stacks (tens of millions of entries) form per-entry
temporaries (row indices, keys, magnitudes); walking the rows in spans of a bounded number of
entries bounds those temporaries whatever the matrix.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

#: Entries per piece when a CSR matrix is read piece by piece
#: (:meth:`~layersim.outofcore.rowpieces.RowPieces.of`): bounds the per-entry temporaries of a
#: pass (~16 MiB per array).
PIECE_ENTRIES = 1 << 21


def row_spans(indptr, lo: int, hi: int, entries: int | None = None):
    """``(start, stop)`` spans covering rows ``lo .. hi - 1`` of a CSR matrix with row
    pointers ``indptr``, about ``entries`` entries each (:data:`PIECE_ENTRIES` by default;
    one row at least)."""
    entries = PIECE_ENTRIES if entries is None else entries
    start = lo
    while start < hi:
        stop = int(np.searchsorted(indptr, indptr[start] + entries, side="right")) - 1
        stop = min(hi, max(stop, start + 1))
        yield start, stop
        start = stop


#: Entries per chunk of :func:`row_chunks` (its per-entry temporaries: ~16 MiB per array).
CHUNK_ENTRIES = 1 << 21


def row_chunks(mat: sps.csr_matrix, entries: int = CHUNK_ENTRIES):
    """``(lo, hi, rows)`` for chunks of rows of a CSR matrix holding about ``entries`` entries
    (one row at least): its entries ``lo:hi`` and their rows. Per-entry index arrays of the
    operators of coupled stacks (tens of millions of entries) take more memory than the
    matrices themselves when formed at once; chunks of a fixed number of rows do not bound
    them either, rows of ``K`` holding hundreds of entries."""
    for start, stop in row_spans(mat.indptr, 0, mat.shape[0], entries):
        ptr = mat.indptr[start:stop + 1]
        yield int(ptr[0]), int(ptr[-1]), np.repeat(np.arange(start, stop), np.diff(ptr))
