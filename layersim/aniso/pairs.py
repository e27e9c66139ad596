"""Ordinate pairs of coupled-mode matrices: which slot pairs hold entries, and pruning per
ordinate pair.

Rows and columns of a coupled-mode matrix are ``slot * h + node`` (:mod:`layersim.aniso.basis`).
The coupled projection truncates the coefficients of each ordinate pair ``(row % h, col % h)``
relative to the largest of that pair over all slots
(:data:`layersim.aniso.plan.COUPLED_RELERR`); the intermediate products of the adding
equations are truncated the same way (:func:`prune_pairs`, :class:`PairPruner`,
:func:`pruned_product`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from ..outofcore.assemble import select_entries
from ..outofcore.products import product
from ..outofcore.rowpieces import RowPieces
from ..outofcore.rows import row_chunks


def slot_pairs(mat, h: int, columns=None):
    """Distinct ``(row slot, column slot)`` pairs holding entries of the CSR matrix ``mat``
    (slots of ``h`` rows / columns), optionally only entries in the columns where the boolean
    mask ``columns`` is true.

    ``mat`` may also be a :class:`~layersim.outofcore.rowpieces.RowPieces` (read piece by piece).

    Returns
    -------
    rows, cols : int ndarray
    """
    pieces = mat if isinstance(mat, RowPieces) else [(0, sps.csr_matrix(mat))]
    mark = np.zeros((-(-mat.shape[0] // h), -(-mat.shape[1] // h)), bool)
    for start, piece in pieces:
        for lo, hi, rows in row_chunks(piece):
            cols = piece.indices[lo:hi]
            if columns is not None:
                sel = columns[cols]
                rows, cols = rows[sel], cols[sel]
            mark[(rows + start) // h, cols // h] = True
    return np.nonzero(mark)


def prune_pairs(mat, h: int, relerr: float) -> sps.csr_matrix:
    """Drop the entries of ``mat`` below ``relerr`` times the largest entry of their ordinate
    pair ``(row % h, col % h)`` over all slots (CSR copy): the truncation of each pair's
    coefficients that the coupled projection applies
    (:data:`layersim.aniso.plan.COUPLED_RELERR`), for the intermediate products of the
    adding equations. See :meth:`AnisoOperator.pruned` for operators (reciprocity kept)."""
    mat = sps.csr_matrix(mat)
    big = np.zeros(h * h)
    key = lambda lo, hi, rows: (rows % h) * h + mat.indices[lo:hi] % h
    for lo, hi, rows in row_chunks(mat):
        np.maximum.at(big, key(lo, hi, rows), np.abs(mat.data[lo:hi]))
    keep = np.empty(mat.nnz, bool)
    for lo, hi, rows in row_chunks(mat):
        keep[lo:hi] = np.abs(mat.data[lo:hi]) >= relerr * big[key(lo, hi, rows)]
    return select_entries(mat, keep)


class PairPruner:
    """A filter for a stream of entries ``(rows, cols, values)`` that ends with the result of
    :func:`prune_pairs` of all of them, without holding them all unpruned.

    Calling it keeps the entries of a part not below ``relerr`` times the largest magnitude
    of their ordinate pair ``(row % h, col % h)`` seen so far (this part included): every
    entry it drops is dropped by :func:`prune_pairs` of the whole. :meth:`final_filter` then filters
    the kept parts against the largest magnitudes of the whole stream, which are exactly those
    of :func:`prune_pairs` (the largest entries are never dropped).
    """

    def __init__(self, h: int, relerr: float):
        self.h, self.relerr = int(h), float(relerr)
        self.big = np.zeros(self.h * self.h)

    def _filter(self, rows, cols, vals, update: bool):
        key = (rows % self.h).astype(np.int64) * self.h + cols % self.h
        mag = np.abs(vals)
        if update:
            np.maximum.at(self.big, key, mag)
        sel = mag >= self.relerr * self.big[key]
        return rows[sel], cols[sel], vals[sel]

    def __call__(self, rows, cols, vals):
        return self._filter(rows, cols, vals, True)

    def final_filter(self, rows, cols, vals):
        """One part (filtered by earlier calls) pruned against the whole stream's maxima."""
        return self._filter(rows, cols, vals, False)


def pruned_product(a, b, h: int, relerr: float | None, pieces: bool = False,
                   directory: str | None = None):
    """``prune_pairs(a @ b, h, relerr)`` (``a @ b`` itself with ``relerr`` None, entries in
    SciPy's order) without holding the unpruned product: formed in chunks of rows, each
    filtered by a :class:`PairPruner` as it comes (:func:`layersim.outofcore.products.product`,
    which documents ``a``, ``pieces`` and ``directory``)."""
    keep = None if relerr is None else PairPruner(h, relerr)
    return product(a, b, keep, pieces=pieces, directory=directory)
