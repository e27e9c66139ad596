"""The adding equations for coupled-mode operators (seed 000 eq. (11)-(12)).

For a top layer 1 and a bottom layer 2, with ``A' = I - Rt2 Rb1`` and the push-through
identities ``(I - Rb1 Rt2)^-1 = I + Rb1 A'^-1 Rt2`` and ``(I - Rb1 Rt2)^-1 Rb1 = Rb1 A'^-1``
(seed 000 eq. (12)), all four outputs need solves with ``A'`` only (one factorisation)::

    [Z1 | Z2] = A'^-1 [Rt2 Ttb1 | Tbt2]
    Rt  = Rt1 + Tbt1 Z1            Tbt = Tbt1 Z2
    Ttb = Ttb2 Ttb1 + Ttb2 Rb1 Z1  Rb  = Rb2 + Ttb2 Rb1 Z2

(below an opaque bottom only ``Rt``). This is the mirror image of the arrangement of
:mod:`layersim.adding` (``A = I - Rb1 Rt2``): the solution is multiplied by the top layer's
transmission only, never by the bottom's reflection, which is the largest operator of a
coated anisotropic base (and ``Tbt1`` is block diagonal when the coating is isotropic): on
Table 2 of seed 000 the products of the other arrangement took 40 of 58 s.
``A`` is banded by Fourier order and solved with :func:`banded_solve` (block LU, pruned block
substitution, sparse right-hand sides); results are pruned at
:data:`layersim.operator.DROP_TOLERANCE` relative to each block's largest entry, and, with the
``relerr`` of :func:`layersim.solve` (:data:`layersim.aniso.plan.COUPLED_RELERR`), per ordinate
pair as the projected layers are, intermediates included.

An isotropic operand is converted to the slot basis first (block diagonal): adding an
anisotropic layer to an isotropic one works, and the result is anisotropic.
"""

from __future__ import annotations

import functools
import itertools

import numpy as np
import scipy.sparse as sps

from .. import memory
from ..errors import InfeasibleError, OperatorError
from ..adding import _check_pair  # same grid / opacity / index checks for both representations
from ..operator import DROP_TOLERANCE
from . import basis
from .banded import PRUNE, BlockBandedLU
from .park import Parked, Spool, park, park_directory, unpark
from .rowpieces import RowPieces
from .operator import (AnisoOperator, PairPruner, as_aniso, from_parts, prune,
                       pruned_product, reciprocal_prune, slot_pairs, sum_pieces)

#: Relative residual above which a block-LU solve is redone with sparse LU, checked on
#: RESIDUAL_VECTORS random dense right-hand sides (:func:`_residual`).
RESIDUAL_CHECK = 1e-9
RESIDUAL_VECTORS = 8

#: Bytes of the dense solution of one group of right-hand sides in the substitutions, at
#: most (if it spread over all the coupled unknowns): on Table 2 row 6 of seed 000 the
#: groups of the first blocks held up to 1231 columns, 290 MiB each, two in flight.
GROUP_BYTES = 32 << 20


def _memory_limit() -> int:
    from ..plan import memory_limit
    return memory_limit()


def banded_solve(A, B, h: int, md: int, what: str = "the adding equations",
                 identity_minus: bool = False, relerr: float | None = None,
                 release: bool = False, directory: str | None = None) -> sps.csr_matrix:
    """``Y = A^-1 B`` for a coupled-mode matrix ``A`` (slot basis) and sparse ``B``.

    Parameters
    ----------
    A : sparse (N, N) or RowPieces
        Banded by Fourier order (unknown ``slot * h + node``); with ``identity_minus`` the
        matrix ``K`` of ``A = I - K`` (never formed). Read piece by piece
        (:class:`~layersim.aniso.rowpieces.RowPieces`, e.g. from a file, never assembled
        unless the sparse-LU fallback runs).
    B : sparse (N, C)
    h, md : int
        Ordinates per slot and Fourier orders.
    what : str
        Named in errors.
    relerr : float, optional
        Drop entries of the solution below ``relerr`` times the largest of their ordinate pair
        (the result of :func:`~layersim.aniso.operator.prune_pairs`), applied while the groups
        of right-hand sides are solved (:class:`~layersim.aniso.operator.PairPruner`), so that
        the unpruned solution is never held.
    release : bool
        The caller does not use ``A`` and ``B`` afterwards: their arrays are released (the
        matrices left empty, a RowPieces closed) as soon as the solve no longer needs them,
        ``B`` once it is reordered, ``A`` once the block factorisation has passed its
        residual check. On Table 2 row 6 of seed 000 they are 370 MiB of the substitution's
        peak.
    directory : str, optional
        Keep the parts of the solution in a file there while the substitutions run
        (:class:`~layersim.aniso.park.Spool`; :func:`~layersim.aniso.park.park_directory`).

    Raises
    ------
    InfeasibleError
        If the dense factors would exceed the memory limit.
    """
    if isinstance(A, RowPieces):
        M = A
    else:
        A_csr = sps.csr_matrix(A)
        A_csr.eliminate_zeros()
        M = RowPieces.of(A_csr)
        del A_csr
    B_in, B = B, sps.csr_matrix(B)
    N = M.shape[0]
    sign = -1.0 if identity_minus else 1.0
    counts = M.row_counts()
    if identity_minus:
        ident = counts == 0
    else:
        if np.any(counts == 0):
            raise OperatorError(f"{what}: the system matrix has empty rows (singular)")
        ident = (counts == 1) & (M.diagonal() == 1.0)
    active = np.flatnonzero(~ident)
    if active.size == 0:
        return B
    rest = np.flatnonzero(ident)
    # Order the active unknowns by (component, Fourier order): components (parity, and cosine
    # vs sine for mirror-symmetric stacks) never couple, so the matrix is block banded in this
    # order with the bandwidth of its widest component, and one factorisation serves them all.
    # Blocks are (component, Fourier order), functions of the slot: the structure follows from
    # the slot pairs holding entries (no per-entry temporaries of the tens of millions of
    # entries of K).
    slot_key = _slot_keys(M, h, md)
    key_all = slot_key[active // h]
    order = np.lexsort((active, key_all))
    key = key_all[order]
    starts = np.concatenate([[0], np.flatnonzero(np.diff(key)) + 1, [order.size]])
    J = starts.size - 1
    blk_pos = np.repeat(np.arange(J), np.diff(starts))          # block of each position
    pos = np.full(N, -1, np.int64)
    pos[active[order]] = np.arange(order.size)                   # position of each unknown
    # bandwidth: entries between active unknowns (rows of K are empty exactly where the unknown
    # is eliminated, so only the columns need the mask)
    rs, cs = slot_pairs(M, h, columns=pos >= 0)
    blk_of_key = {k: j for j, k in enumerate(key[starts[:-1]])}
    blk_of_slot = np.array([blk_of_key.get(k, -1) for k in slot_key])
    bw = int(np.abs(blk_of_slot[rs] - blk_of_slot[cs]).max(initial=0))
    need = BlockBandedLU.memory_estimate(starts, bw)
    limit = _memory_limit()
    if need > limit:
        raise InfeasibleError(
            f"{what}: the coupled-mode factorisation needs about {need / 2**30:.2f} GiB "
            f"(limit {limit / 2**30:.2f} GiB, LAYERSIM_MAX_MEMORY): {active.size} coupled "
            f"unknowns, {J} blocks, a coupling band of {bw} orders; lower md or ms in "
            "[discretization], or n, or make the anisotropy milder")
    ordered = active[order]                                      # unknown at each position
    Brest, shape = B[rest], B.shape             # the eliminated unknowns: y = b
    Bo = B[ordered]
    if release:                                 # before the copies below
        memory.empty_sparse(B_in, B)
    del B, B_in
    if rest.size:
        # y_rest = b_rest: move those columns to the right-hand side (through the columns
        # of K at those unknowns: a row-permuted copy of K took 670 MiB on Table 2 row 6 of
        # seed 000)
        Bo = Bo - sign * (M.columns(rest) @ Brest)[ordered]
    Bo = Bo.tocsc()
    Brest = Brest.tocoo()
    # the right-hand sides by group (in a file where there is one: on Table 2 row 6 of
    # seed 000 they took 118 MiB beside the factors)
    groups = _rhs_groups(Bo, starts, blk_pos, Spool(directory))
    del Bo
    rows = _block_rows(M, pos, starts, blk_pos, bw, sign, identity_minus)
    parts = None
    keep = (lambda *part: part) if relerr is None else PairPruner(h, relerr)
    try:
        lu = BlockBandedLU(rows, starts, bw)
        del rows
        # verify (the block LU does not pivot across blocks)
        if _residual(lu, M, starts, ordered, identity_minus) <= RESIDUAL_CHECK:
            if release:
                _release_matrix(A, M)
            parts = _solve_groups(lu, groups.drain(), starts, ordered, keep,
                                  out=Spool(directory))
        del lu
    except np.linalg.LinAlgError:
        parts = None
    if parts is None:
        Ao = M.to_csr()[ordered][:, ordered]
        Ao = (sps.identity(order.size) - Ao) if identity_minus else Ao
        Bo = from_parts(groups, (order.size, shape[1]), "csc",
                        select=lambda *g: _group_triplets(starts, *g))
        Y = _sparse_lu_solve(Ao, Bo).tocoo()
        parts = [keep(ordered[Y.row], Y.col, Y.data)]
        del Y, Bo
    groups.close()
    # the eliminated unknowns, then one CSR matrix in the unknowns' numbering
    parts.append(keep(rest[Brest.row], Brest.col, Brest.data))
    del Brest
    return from_parts(parts, shape, select=None if relerr is None else keep.final_filter)


def _residual(lu, M, starts, ordered, identity_minus) -> float:
    """Largest residual of the block-LU solution of :data:`RESIDUAL_VECTORS` random dense
    right-hand sides (fixed seed, unpruned substitution), relative to their largest entry.

    The block LU does not pivot across blocks; where that lets the factors grow, the
    solution of any right-hand side that reaches the blocks concerned carries the error, and a
    dense right-hand side reaches every block. (A sample of 256 of the actual columns, which
    touch a few dozen blocks each, took 6 s of the 20 s solve on Table 2 row 6 of seed 000,
    in 8 passes over ``K``; this takes one pass and one substitution over the band.)
    """
    n, J = int(starts[-1]), starts.size - 1
    V = np.random.default_rng(0).standard_normal((n, RESIDUAL_VECTORS))
    Y = lu.solve({j: V[starts[j]:starts[j + 1]].copy() for j in range(J)}, 0, J, tol=0.0)
    full = np.zeros((M.shape[0], RESIDUAL_VECTORS))        # zero at eliminated unknowns
    for j, y in Y.items():
        full[ordered[starts[j]:starts[j + 1]]] = y
    del Y
    y = full[ordered]
    My = M.matmul(full)[ordered]
    del full
    worst = float(np.abs(V - (y - My if identity_minus else My)).max())
    return worst / float(np.abs(V).max()) if np.isfinite(worst) else np.inf


def _release_matrix(A, M) -> None:
    """Release the system matrix of :func:`banded_solve` (``A`` as passed, ``M`` its pieces)."""
    if isinstance(A, RowPieces):
        A.close()
    else:
        memory.empty_sparse(A)
    M.close()


def _block_rows(M, pos, starts, blk_pos, bw, sign, identity_minus):
    """Dense block rows over the band of ``A`` (``I - M`` or ``M``) in the block order
    (``pos`` is the position of each unknown, -1 if eliminated; ``blk_pos`` the block of each
    position), filled piece by piece of ``M`` (:class:`RowPieces`)."""
    J = starts.size - 1
    rows = [np.zeros(BlockBandedLU.band_shape(starts, bw, i)) for i in range(J)]
    col0 = starts[np.maximum(0, np.arange(J) - bw)]        # first column of each block row
    for start, piece in M:
        sub = piece.tocoo()
        del piece
        p, c = pos[sub.row + start], pos[sub.col]
        ok = (p >= 0) & (c >= 0)
        p, c, v = p[ok], c[ok], sign * sub.data[ok]
        del sub, ok
        blk = blk_pos[p]
        order = np.argsort(blk, kind="stable")
        p, c, v, blk = p[order], c[order], v[order], blk[order]
        cuts = np.flatnonzero(np.diff(blk)) + 1
        for a, z in zip(np.concatenate([[0], cuts]), np.concatenate([cuts, [blk.size]])):
            if z > a:
                i = int(blk[a])
                rows[i][p[a:z] - starts[i], c[a:z] - col0[i]] = v[a:z]
    if identity_minus:
        for i in range(J):
            d = np.arange(starts[i + 1] - starts[i])
            rows[i][d, starts[i] - col0[i] + d] += 1.0
    return rows


def _slot_keys(M, h, md):
    """Block key of every slot, ``component * (md + 1) + Fourier order``: components are
    decoupled groups of unknowns, Fourier-order parity, and cosine vs sine slots when no entry
    couples them (mirror-symmetric stacks). Finer decoupling (e.g. isotropic operators, where
    every order is its own component) needs no label: it shows as a zero bandwidth."""
    sin_of = basis.slot_is_sin(md)
    mode = basis.slot_mode(md)
    rs, cs = slot_pairs(M, h)
    mixed = bool(np.any(sin_of[rs] != sin_of[cs]))
    label = (mode % 2) + (0 if mixed else 2 * sin_of.astype(np.int64))
    return label * (md + 1) + mode


def _rhs_groups(Bc, starts, blk_pos, out=None):
    """The right-hand sides ``Bc`` (CSC, rows in block order) in groups for
    :func:`_solve_groups`: columns grouped by the first block they touch, groups with more
    columns than fit :data:`GROUP_BYTES` of dense solution split (the solution of one source
    order spreads over the orders it couples to, up to every active unknown).

    Returns ``out`` (a list by default, or a :class:`~layersim.aniso.park.Spool`) holding,
    per group, ``(columns, [lo, hi], indptr, indices, data)``: its columns of ``Bc`` (int32),
    the blocks ``lo .. hi - 1`` they touch and the CSR arrays of ``Bc[rows of those blocks,
    columns]``."""
    out = [] if out is None else out
    cols = np.flatnonzero(np.diff(Bc.indptr))
    if cols.size == 0:
        return out
    rb = blk_pos[Bc.indices]
    first = np.minimum.reduceat(rb, Bc.indptr[cols])
    last = np.maximum.reduceat(rb, Bc.indptr[cols])
    width = max(1, GROUP_BYTES // (8 * int(starts[-1])))
    for g in np.unique(first):
        sel = np.flatnonzero(first == g)
        for at in range(0, sel.size, width):
            part = sel[at:at + width]
            gcols = cols[part].astype(np.int32)
            lo, hi = int(g), int(last[part].max()) + 1
            sub = Bc[:, gcols][starts[lo]:starts[hi]].tocsr()
            out.append((gcols, np.array([lo, hi]), sub.indptr, sub.indices, sub.data))
    return out


def _group_triplets(starts, gcols, bounds, indptr, indices, data):
    """``(positions, columns, values)`` of one group of :func:`_rhs_groups`."""
    rows = starts[bounds[0]] + np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
    return rows, gcols[indices], data


def _solve_groups(lu, groups, starts, ordered, keep=None, out=None):
    """Pruned block substitution of the groups of right-hand sides of :func:`_rhs_groups`
    (any iterable of them, read in order, e.g. ``Spool.drain()``).

    Returns the solution as parts ``(rows, cols, values)`` (32-bit indices, rows in the
    unknowns' numbering ``ordered[position]``) for :func:`~layersim.aniso.operator.from_parts`.
    Groups are solved :data:`layersim.threads.THREADS` at a time and each round's parts go
    through ``keep`` (a :class:`~layersim.aniso.operator.PairPruner`) as they come, so that
    the unpruned solution (several times the pruned one) is never held, and into ``out``
    (a list, or a :class:`~layersim.aniso.park.Spool` that keeps them in a file: on Table 2
    row 6 of seed 000 they were 330 MiB beside the factors).
    """
    from ..threads import THREADS
    parts = [] if out is None else out
    unknown = ordered.astype(np.int32)

    def group(task):
        gcols, (lo, hi), indptr, indices, data = task
        lo, hi = int(lo), int(hi)
        # one dense array per block (the solve releases each as it is used: a dense array
        # of all of them, viewed by the blocks, stayed whole until the end)
        sub = sps.csr_matrix((data, indices, indptr), shape=(indptr.size - 1, gcols.size))
        rhs = {j: sub[starts[j] - starts[lo]:starts[j + 1] - starts[lo]].toarray()
               for j in range(lo, hi)
               if sub.indptr[starts[j + 1] - starts[lo]] > sub.indptr[starts[j] - starts[lo]]}
        scale = np.abs(sub.data).max()
        del sub
        rows, cs, vals = [], [], []
        Y = lu.solve(rhs, lo, hi)
        del rhs
        for j in sorted(Y):
            y = Y.pop(j)
            r, c = np.nonzero(np.abs(y) > PRUNE * scale)
            rows.append(unknown[r + starts[j]])
            cs.append(gcols[c])
            vals.append(y[r, c])
        if not rows:
            return np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros(0)
        return np.concatenate(rows), np.concatenate(cs), np.concatenate(vals)

    groups = iter(groups)
    while True:
        todo = list(itertools.islice(groups, THREADS))
        if not todo:
            return parts
        for part in _map(group, todo):
            parts.append(part if keep is None else keep(*part))
        del todo


def _map(fn, items):
    """:func:`layersim.threads.parallel_map`: the substitutions of the groups are independent
    (numpy matmul only; see that module about scipy.linalg)."""
    from ..threads import parallel_map
    return parallel_map(fn, items)


def _sparse_lu_solve(Ac, Bc):
    """Fallback: SuperLU (UMFPACK when installed) on the component, nonzero columns only."""
    from ..adding import _solve_columns, _sparse_lu
    solve = _sparse_lu(sps.csc_matrix(Ac))
    return sps.csr_matrix(_solve_columns(solve, sps.csc_matrix(Bc)))


def _sum(terms: list, directory, assemble: bool = True):
    """``prune(a + b)`` of ``terms = [a, b]``, handed over (the list is emptied): summed in
    pieces (:func:`~layersim.aniso.operator.sum_pieces`, in a file in ``directory``), the
    terms released before the sum is assembled (on Table 2 row 6 of seed 000,
    ``Rt1 + Tbt1 Z1`` held 3 x 170 MiB at once). Without ``assemble`` the pruned sum is
    returned as :class:`~layersim.aniso.rowpieces.RowPieces` (for
    :func:`~layersim.aniso.operator.reciprocal_prune`, which reads it piece by piece: the
    assembled sum was the largest array of the adding step's end, 390 MiB above the
    baseline on row 6)."""
    a, b = terms
    terms.clear()
    pieces = sum_pieces(a, b, directory=directory)
    del a, b
    if not assemble:
        return prune(pieces, DROP_TOLERANCE)
    return prune(pieces.to_csr(release=True), DROP_TOLERANCE)


def _multiply(a, b, h: int, relerr: float | None, floor: float | None = None,
              pieces: bool = False, directory: str | None = None):
    """``a @ b`` by :func:`~layersim.aniso.operator.pruned_product`: pruned per ordinate
    pair at ``relerr`` as it is formed, or, with ``relerr`` None, whole (without the entries
    below ``floor`` times its largest, if given); with ``pieces`` as
    :class:`~layersim.aniso.rowpieces.RowPieces` in a file in ``directory``."""
    if relerr is not None or floor is None:
        return pruned_product(a, b, h, relerr, pieces=pieces, directory=directory)
    out = prune(pruned_product(a, b, h, None), floor)
    return RowPieces.written(out, directory) if pieces else out


def _bytes(block) -> int:
    """Bytes of a block, resident or parked."""
    return block.bytes if isinstance(block, Parked) else memory.sparse_bytes(block)


def add(top, bottom, relerr: float | None = None,
        relerr_intermediate: float | None = None, consume: str | None = None) -> AnisoOperator:
    """Operator of ``top`` stacked on ``bottom`` (coupled modes).

    Parameters
    ----------
    top, bottom : AnisoOperator or IsoOperator
        Same grid; isotropic operands are converted; the result has
        ``md = max(top.md, bottom.md)``.
    relerr : float, optional
        Also drop coefficients of the result below ``relerr`` times the largest of their
        ordinate pair, making it exactly reciprocal (:meth:`AnisoOperator.pruned`); the
        products with the solution are pruned per pair at ``relerr / 10`` as they are
        computed (:func:`~layersim.aniso.operator.pruned_product`), so that they are never
        held unpruned.
    relerr_intermediate : float, optional
        The same for the products ``K``, ``Rt2 Ttb1`` and the solution ``Z``
        (:func:`~layersim.aniso.operator.prune_pairs`): ``Z`` keeps entries down to
        :data:`~layersim.aniso.banded.PRUNE` of each group of right-hand sides, and the
        products with it cost in proportion to its entries (3/4 of them are below 1e-6 of
        their pair on Table 2 row 6).

        By default only entries below :data:`~layersim.operator.DROP_TOLERANCE` of their
        block's largest are dropped; :func:`layersim.solve` passes
        :data:`layersim.aniso.plan.STACK_RELERR` and ``STACK_RELERR_INTERMEDIATE``.
    consume : {None, "top", "bottom", "both"}
        Operands that the caller will not use again and whose blocks it holds no other
        reference to: they are emptied (:meth:`AnisoOperator.consume`) and each of their
        blocks is released as soon as the equations no longer need it (below an opaque base,
        all but ``Rt1`` and ``Tbt1`` before the solve; on Table 2 row 6 of seed 000 that is
        460 of the operands' 710 MiB), and the blocks idle until after the solve are parked
        on disk meanwhile (:mod:`layersim.aniso.park`; there ``Rt1`` and ``Tbt1``, 270 MiB).
        Blocks that arrive parked (projected with ``park_dir``) are read back when needed.
        With ``consume`` naming the bottom, its ``Rt`` is read piece by piece from a file by
        both products. Whatever ``consume``, the right-hand side ``Rt2 Ttb1``, ``K``, the
        right-hand sides grouped for the substitutions, the solution's parts and
        ``Tbt1 Z1`` are written to files as they are formed and read back piece by piece,
        where :func:`~layersim.aniso.park.park_directory` allows.
        :func:`layersim.solve` passes it for operators that no later channel reuses.

    Returns
    -------
    AnisoOperator
    """
    for side, op in (("top", top), ("bottom", bottom)):
        if getattr(op, "consumed", False):
            raise OperatorError(f"the {side} operator was consumed by an earlier adding step "
                                "(consume=...) and no longer holds its blocks")
    md = max(top.m, bottom.m)
    top_a, bottom_a = as_aniso(top, md), as_aniso(bottom, md)
    _check_pair(top_a, bottom_a)
    N = top_a.size
    h = top_a.h
    grid, eta_top, eta_bottom = top_a.grid, top_a.eta_top, bottom_a.eta_bottom
    opaque = bottom_a.opaque
    delta = {}
    if not opaque:
        for name in ("Ttb", "Tbt"):
            if name in top_a.delta and name in bottom_a.delta:
                delta[name] = top_a.delta[name] * bottom_a.delta[name]
    one, two = dict(top_a.blocks), dict(bottom_a.blocks)   # this call's references
    if consume not in (None, "top", "bottom", "both"):
        raise ValueError(f"consume must be None, 'top', 'bottom' or 'both', not {consume!r}")
    for side, ops in (("top", (top, top_a)), ("bottom", (bottom, bottom_a))):
        if consume in (side, "both"):
            for op in ops:
                if isinstance(op, AnisoOperator):
                    op.consume()
    del top, bottom, top_a, bottom_a
    # blocks idle until after the solve go to disk meanwhile (layersim.aniso.park), if this
    # call owns them: the top's Rt and Tbt and the bottom's Ttb and Rb now, the top's Ttb and
    # Rb (transmissive bottom) once their products are formed; the directory is chosen for
    # all of them
    own_top, own_bottom = consume in ("top", "both"), consume in ("bottom", "both")
    idle = [(one, "Rt"), (one, "Tbt")] if own_top else []
    if own_bottom and not opaque:
        idle += [(two, "Ttb"), (two, "Rb")]
    later = [(one, "Ttb"), (one, "Rb")] if own_top and not opaque else []
    # (and Rt2, the pieces of the right-hand side Rt2 Ttb1, of K = Rt2 Rb1 and of Tbt1 Z1,
    # estimated by the bytes of their factors and of Rt1)
    need = sum(_bytes(d[name]) for d, name in idle + later) \
        + 3 * _bytes(two["Rt"]) + _bytes(one["Ttb"]) + _bytes(one["Rb"]) + _bytes(one["Rt"])
    directory = park_directory(need)
    for d, name in idle:
        d[name] = park(d[name], directory)
    product = functools.partial(_multiply, h=h, relerr=relerr_intermediate, floor=1e-16)
    output = functools.partial(_multiply, h=h, relerr=None if relerr is None else 0.1 * relerr)
    # below an opaque base only Rt = Rt1 + Tbt1 Z1 is formed after the solve: Ttb1, then
    # Rt2 and Rb1 are released as soon as their products are formed; Rt2, the left factor
    # of both, is read piece by piece from a file where this call owns it; the right-hand
    # side and K go to files piece by piece as they are formed (the banded solve reads K
    # piece by piece: layersim.aniso.rowpieces); blocks parked by the projection
    # (aniso_interface_operator(park_dir=...)) are read back when needed
    Rt2 = unpark(two.pop("Rt"))
    if own_bottom:
        Rt2 = RowPieces.written(Rt2, directory)
    Ttb1 = unpark(one.pop("Ttb"))
    first = product(Rt2, Ttb1, pieces=True, directory=directory)
    if not opaque:
        one["Ttb"] = Ttb1
    del Ttb1
    Rb1 = unpark(one.pop("Rb"))
    K = product(Rt2, Rb1, pieces=True, directory=directory)
    if not opaque:
        one["Rb"] = Rb1
    del Rt2, Rb1
    for d, name in later:
        d[name] = park(d[name], directory)
    if opaque:
        rhs = first.to_csr(release=True)
    else:
        rhs = sps.hstack([first.to_csr(release=True), unpark(two.pop("Tbt"))], format="csr")
    del first
    memory.release()
    Z = banded_solve(K, rhs, h, md, identity_minus=True, relerr=relerr_intermediate,
                     release=True, directory=directory)
    del K, rhs              # emptied by the solve as soon as it no longer needed them
    memory.release()
    Z1 = Z if opaque else Z[:, :N]
    Tbt1 = unpark(one.pop("Tbt"))
    # Tbt1 Z1 to a file as it is formed, Rt1 read back after it (150 MiB on row 6)
    terms = [output(Tbt1, Z1, pieces=True, directory=directory), None]
    if opaque:
        del Z, Z1, Tbt1
    terms[1] = unpark(one.pop("Rt"))
    whole = relerr is None          # else the sums go to reciprocal_prune as row pieces
    blocks = {"Rt": _sum(terms, directory, whole)}
    if not opaque:
        Z2 = Z[:, N:]
        del Z
        Rb1, Ttb1 = unpark(one.pop("Rb")), unpark(one.pop("Ttb"))
        Ttb2 = unpark(two.pop("Ttb"))
        W = _multiply(Ttb2, Rb1, h, None)
        del Rb1
        blocks["Tbt"] = prune(output(Tbt1, Z2), DROP_TOLERANCE)
        blocks["Ttb"] = _sum([_multiply(Ttb2, Ttb1, h, None), output(W, Z1)], directory,
                             whole)
        del Ttb1, Ttb2, Z1
        blocks["Rb"] = _sum([unpark(two.pop("Rb")), output(W, Z2)], directory, whole)
        del W, Z2, Tbt1
    memory.release()
    if relerr is not None:
        reciprocal_prune(blocks, grid, md, eta_top, eta_bottom, delta, relerr, directory)
        memory.release()
    return AnisoOperator(grid, md, blocks, eta_top, None if opaque else eta_bottom, delta)
