"""Reciprocal images of coupled-mode blocks: the block that reciprocity pairs with a block.

In ``S = G D`` (``G`` the coefficients, ``D`` the slot scale of
:func:`layersim.aniso.operator.reciprocity_error`) reciprocity is a transpose; on the blocks
``B`` themselves it reads ``diag(c) B^T diag(1 / c)`` with ``c`` the column scale of
:func:`layersim.aniso.operator.slot_column_scale`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from ..outofcore.rowpieces import RowPieces
from ..outofcore.rows import row_chunks
from ..outofcore.sums import sum_pieces
from ..outofcore.transpose import transposed


def reciprocal_image(mat, h: int, col_scale: np.ndarray, factor: float = 1.0,
                     skip_diagonal: bool = False) -> sps.csr_matrix:
    """``factor * diag(c) mat^T diag(1 / c)``: the block that reciprocity pairs with ``mat``
    (``c = col_scale``, the slot scale over the flux weights, see
    :meth:`AnisoOperator.pruned`), formed from one transposed copy scaled in place.

    Parameters
    ----------
    mat : sparse (N, N) or RowPieces
        Read piece by piece if given as :class:`~layersim.outofcore.rowpieces.RowPieces` (see
        :func:`~layersim.outofcore.transpose.transposed`).
    h : int
        Ordinates per slot.
    col_scale : ndarray (N,)
    factor : float
    skip_diagonal : bool
        Leave out the entries of the ordinate pairs ``o == i`` (the image of one triangle of
        pairs, to be added to that triangle).
    """
    t = transposed(mat)
    for lo, hi, rows in row_chunks(t):
        cols = t.indices[lo:hi]
        part = t.data[lo:hi]
        part *= factor * col_scale[rows] / col_scale[cols]
        if skip_diagonal:
            part[rows % h == cols % h] = 0.0
    if skip_diagonal:
        t.eliminate_zeros()
    return t


def with_reciprocal_image(mat, h: int, col_scale: np.ndarray, alpha: float, beta: float,
                          skip_diagonal: bool = False,
                          directory: str | None = None) -> RowPieces:
    """``alpha mat + beta reciprocal_image(mat)`` (:func:`reciprocal_image`) in pieces of rows
    (:func:`~layersim.outofcore.sums.sum_pieces`), for the mean of a reflection block and its
    image and for a block
    projected on one triangle of ordinate pairs.

    With ``directory`` the matrix is first written there piece by piece and its image built
    from the file (:func:`~layersim.outofcore.transpose.transposed`), so that ``mat``, its
    image and their sum are never
    resident together: the caller hands ``mat`` over (no reference of its own left) and
    assembles the result once this returns (``to_csr(release=True)``).
    """
    mat = RowPieces.written(mat, directory)
    image = reciprocal_image(mat, h, col_scale, skip_diagonal=skip_diagonal)
    out = sum_pieces(mat, image, alpha, beta, directory)
    mat.close()
    return out
