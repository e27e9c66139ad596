"""The adding equations for coupled-mode operators (seed 000 eq. (11)-(12)).

For a top layer 1 and a bottom layer 2, with ``A = I - Rb1 Rt2`` and the push-through identity
of eq. (12), all four outputs need solves with ``A`` only (one factorisation)::

    [Y1 | Y2] = A^-1 [Ttb1 | Rb1 Tbt2]
    Ttb = Ttb2 Y1          Rt  = Rt1 + Tbt1 Rt2 Y1
    Rb  = Rb2 + Ttb2 Y2    Tbt = Tbt1 Tbt2 + Tbt1 Rt2 Y2

(the same arrangement as :mod:`layersim.adding`; below an opaque bottom only ``Rt``).
``A`` is banded by Fourier order and solved with :func:`banded_solve` (block LU, pruned block
substitution, sparse right-hand sides); results are pruned at
:data:`layersim.operator.DROP_TOLERANCE` relative to each block's largest entry.

An isotropic operand is converted to the slot basis first (block diagonal): adding an
anisotropic layer to an isotropic one works, and the result is anisotropic.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps
import scipy.sparse.csgraph as csgraph

from ..errors import InfeasibleError, OperatorError
from ..operator import DROP_TOLERANCE
from . import basis
from .banded import PRUNE, BlockBandedLU
from .operator import AnisoOperator, as_aniso, prune

#: Relative residual above which a block-LU solve is redone with sparse LU.
RESIDUAL_CHECK = 1e-9


def _memory_limit() -> int:
    from ..plan import memory_limit
    return memory_limit()


def banded_solve(A, B, h: int, md: int, what: str = "the adding equations") -> sps.csr_matrix:
    """``Y = A^-1 B`` for a coupled-mode matrix ``A`` (slot basis) and sparse ``B``.

    Parameters
    ----------
    A : sparse (N, N)
        Banded by Fourier order (unknown ``slot * h + node``).
    B : sparse (N, C)
    h, md : int
        Ordinates per slot and Fourier orders.
    what : str
        Named in errors.

    Raises
    ------
    InfeasibleError
        If the dense factors of a component would exceed the memory limit.
    """
    A = sps.csr_matrix(A)
    B = sps.csr_matrix(B)
    N = A.shape[0]
    # identity rows (y = b) are eliminated; their columns move to the right-hand side
    A.eliminate_zeros()
    counts = np.diff(A.indptr)
    if np.any(counts == 0):
        raise OperatorError(f"{what}: the system matrix has empty rows (singular)")
    ident = (counts == 1) & (A.diagonal() == 1.0)
    active = np.flatnonzero(~ident)
    if active.size == 0:
        return B
    rest = np.flatnonzero(ident)
    A_ra = A[active]
    Brhs = (B[active] - A_ra[:, rest] @ B[rest]).tocsc()
    Aaa = A_ra[:, active].tocsr()
    # Order the active unknowns by (component, Fourier order): components (parity, and cosine
    # vs sine for mirror-symmetric stacks) never couple, so the matrix is block banded in this
    # order with the bandwidth of its widest component, and one factorisation serves them all.
    label = _component_labels(Aaa, active, h, md)
    mode = basis.slot_mode(md)[active // h]
    order = np.lexsort((active, mode, label))
    key = label[order] * (md + 1) + mode[order]
    cuts = np.flatnonzero(np.diff(key)) + 1
    starts = np.concatenate([[0], cuts, [order.size]])
    blk_of = np.empty(order.size, np.int64)
    blk_of[:] = np.searchsorted(starts, np.arange(order.size), side="right") - 1
    Ao = Aaa[order][:, order].tocsr()
    Bo = Brhs[order]
    coo = Ao.tocoo()
    bw = int(np.abs(blk_of[coo.row] - blk_of[coo.col]).max(initial=0))
    need = BlockBandedLU.memory_estimate(starts, bw)
    limit = _memory_limit()
    if need > limit:
        raise InfeasibleError(
            f"{what}: the coupled-mode factorisation needs about {need / 2**30:.2f} GiB "
            f"(limit {limit / 2**30:.2f} GiB, LAYERSIM_MAX_MEMORY): {active.size} coupled "
            f"unknowns, {starts.size - 1} blocks, a coupling band of {bw} orders; lower md or "
            "ms in [discretization], or n, or make the anisotropy milder")
    Yo = _solve_blocks(Ao, Bo, starts, blk_of, bw)
    if Yo is None:
        Yo = _sparse_lu_solve(Ao, Bo)
    Yo = Yo.tocoo()
    Brest = B[rest].tocoo()
    rows = np.concatenate([active[order[Yo.row]], rest[Brest.row]])
    cols = np.concatenate([Yo.col, Brest.col])
    vals = np.concatenate([Yo.data, Brest.data])
    Y = sps.csr_matrix((vals, (rows, cols)), shape=B.shape)
    Y.sum_duplicates()
    return Y


def _component_labels(Aaa, active, h, md):
    """Connected component of the slot graph for every active unknown."""
    slots = basis.n_slots(md)
    slot = active // h
    coo = Aaa.tocoo()
    g = sps.coo_matrix((np.ones(coo.nnz), (slot[coo.row], slot[coo.col])),
                       shape=(slots, slots)).tocsr()
    _, labels = csgraph.connected_components(g + g.T, directed=False)
    return labels[slot]


def _solve_blocks(Ac, Bc, starts, blk_of, bw):
    """Block-LU solve; None if the factorisation or its residual check fails."""
    try:
        lu = BlockBandedLU(Ac, starts, bw)
    except (np.linalg.LinAlgError, ValueError):
        return None
    Bc = sps.csc_matrix(Bc)
    cols = np.flatnonzero(np.diff(Bc.indptr))
    if cols.size == 0:
        return sps.csr_matrix(Bc.shape)
    # group columns by the first block they touch (columns of one source order together)
    rb = blk_of[Bc.indices]
    first = np.minimum.reduceat(rb, Bc.indptr[cols])
    last = np.maximum.reduceat(rb, Bc.indptr[cols])
    rows_out, cols_out, vals_out = [], [], []
    for g in np.unique(first):
        gcols = cols[first == g]
        lo, hi = int(g), int(last[first == g].max()) + 1
        dense = Bc[:, gcols].toarray()
        rhs = {j: dense[starts[j]:starts[j + 1]] for j in range(lo, hi)}
        scale = np.abs(dense).max()
        sol = lu.solve(rhs, lo, hi)
        for j, y in sol.items():
            r, c = np.nonzero(np.abs(y) > PRUNE * scale)
            rows_out.append(r + starts[j])
            cols_out.append(gcols[c])
            vals_out.append(y[r, c])
    if rows_out:
        Y = sps.csr_matrix((np.concatenate(vals_out), (np.concatenate(rows_out),
                                                       np.concatenate(cols_out))),
                           shape=Bc.shape)
    else:
        Y = sps.csr_matrix(Bc.shape)
    resid = Bc - Ac @ Y
    ref = abs(Bc).max()
    if resid.nnz and abs(resid).max() > RESIDUAL_CHECK * max(ref, 1e-300):
        return None
    return Y


def _sparse_lu_solve(Ac, Bc):
    """Fallback: SuperLU (UMFPACK when installed) on the component, nonzero columns only."""
    from ..adding import _solve_columns, _sparse_lu
    solve = _sparse_lu(sps.csc_matrix(Ac))
    return sps.csr_matrix(_solve_columns(solve, sps.csc_matrix(Bc)))


def _check_pair(top: AnisoOperator, bottom: AnisoOperator) -> None:
    if top.grid != bottom.grid:
        raise OperatorError(f"cannot add operators on different grids ({top.grid.rule} n="
                            f"{top.grid.n} over {bottom.grid.rule} n={bottom.grid.n}); "
                            "build both from the same discretisation plan")
    if top.opaque:
        raise OperatorError("the top operator is opaque: nothing reaches a layer below it")
    if abs(top.eta_bottom - bottom.eta_top) > 1e-9 * max(1.0, top.eta_bottom):
        raise OperatorError(f"index mismatch: the top operator ends in a medium of index "
                            f"{top.eta_bottom:g} but the bottom one starts in {bottom.eta_top:g}")


def add(top, bottom) -> AnisoOperator:
    """Operator of ``top`` stacked on ``bottom`` (coupled modes).

    Parameters
    ----------
    top, bottom : AnisoOperator or IsoOperator
        Same grid; isotropic operands are converted; the result has
        ``md = max(top.md, bottom.md)``.

    Returns
    -------
    AnisoOperator
    """
    md = max(top.m, bottom.m)
    top, bottom = as_aniso(top, md), as_aniso(bottom, md)
    _check_pair(top, bottom)
    N = top.size
    h = top.h
    opaque = bottom.opaque
    Rt1, Rb1, Ttb1, Tbt1 = (top.block(k) for k in ("Rt", "Rb", "Ttb", "Tbt"))
    Rt2 = bottom.block("Rt")
    K = prune(Rb1 @ Rt2, 1e-16)
    A = sps.identity(N, format="csr") - K
    if opaque:
        rhs = Ttb1
    else:
        Rb2, Ttb2, Tbt2 = (bottom.block(k) for k in ("Rb", "Ttb", "Tbt"))
        rhs = sps.hstack([Ttb1, Rb1 @ Tbt2], format="csr")
    Y = banded_solve(A, rhs, h, md)
    Y1 = Y[:, :N]
    out = {"Rt": Rt1 + Tbt1 @ (Rt2 @ Y1)}
    if not opaque:
        Y2 = Y[:, N:]
        out["Ttb"] = Ttb2 @ Y1
        out["Rb"] = Rb2 + Ttb2 @ Y2
        out["Tbt"] = Tbt1 @ Tbt2 + Tbt1 @ (Rt2 @ Y2)
    blocks = {k: prune(v, DROP_TOLERANCE) for k, v in out.items()}
    delta = {}
    if not opaque:
        for name in ("Ttb", "Tbt"):
            if name in top.delta and name in bottom.delta:
                delta[name] = top.delta[name] * bottom.delta[name]
    return AnisoOperator(top.grid, md, blocks, top.eta_top,
                         None if opaque else bottom.eta_bottom, delta)
