"""Linear combinations of solved operators on one discretisation.

The Fourier coefficients of a stack's operator are linear in its BSDF, so ``sum_i w_i A_i`` of
operators solved on the same ordinates and orders is the operator of the BSDF ``sum_i w_i
f_i``: an ordinary operator that every evaluation (eval, albedo, bins, sampling, files) takes
as it is. The brushed route combines the solves of its raised coat this way (Richardson
extrapolation in the added slope variance, :func:`layersim.layers.brushed.
extrapolation_weights`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from ..errors import OperatorError
from .operator import BLOCKS, Operator

__all__ = ["linear_combination"]


def linear_combination(ops: list, weights) -> Operator:
    """``sum_i weights[i] * ops[i]``, block by block, Fourier order by order, and the delta
    parts alike.

    Parameters
    ----------
    ops : list of Operator, length m >= 1
        Operators of one representation on one discretisation: the same grid, number of
        orders, indices above and below and present blocks (as solved with one plan).
    weights : sequence of float, length m
        Dimensionless weights (any sign).

    Returns
    -------
    Operator
        Of the representation of ``ops[0]``; a coupled one keeps the largest ``ms`` of
        ``ops``.

    Raises
    ------
    OperatorError
        If the operators differ in grid, orders, indices or present blocks, or the lengths
        of ``ops`` and ``weights`` differ.
    """
    weights = [float(w) for w in weights]
    _check_alike(ops, weights)
    first = ops[0]
    blocks = {name: _combined_block([op.blocks[name] for op in ops], weights)
              for name in BLOCKS}
    keys = {k for op in ops for k in op.delta}
    delta = {k: sum(w * op.delta.get(k, np.zeros(first.h)) for op, w in zip(ops, weights))
             for k in keys}
    if first.representation == "isotropic":
        return type(first)(first.grid, blocks, first.eta_top, first.eta_bottom, delta)
    return type(first)(first.grid, first.m, blocks, first.eta_top, first.eta_bottom, delta,
                       ms=max(op.ms for op in ops))


def _combined_block(mats: list, weights: list):
    """The weighted sum of one block of every operator: None where left out, a list of
    per-order matrices for isotropic operators, one matrix for coupled ones."""
    if mats[0] is None:
        return None
    if sps.issparse(mats[0]):
        return _weighted(mats, weights)
    return [_weighted([m[l] for m in mats], weights) for l in range(len(mats[0]))]


def _weighted(mats: list, weights: list):
    """``sum_i w_i M_i`` of sparse matrices of one shape."""
    total = weights[0] * mats[0]
    for w, m in zip(weights[1:], mats[1:]):
        total = total + w * m
    return total.tocsr()


def _check_alike(ops: list, weights: list) -> None:
    """Refuse operators that are not solved on one discretisation (see
    :func:`linear_combination`)."""
    if not ops or len(ops) != len(weights):
        raise OperatorError(f"a linear combination needs one weight per operator, got "
                            f"{len(ops)} operators and {len(weights)} weights")
    first = ops[0]
    for op in ops[1:]:
        same = (op.representation == first.representation and op.grid == first.grid
                and op.m == first.m and op.eta_top == first.eta_top
                and op.eta_bottom == first.eta_bottom
                and all((op.blocks[k] is None) == (first.blocks[k] is None) for k in BLOCKS))
        if not same:
            raise OperatorError("operators combined linearly must be solved on one "
                                "discretisation (representation, grid, orders, indices and "
                                "present blocks): solve them with one plan")
