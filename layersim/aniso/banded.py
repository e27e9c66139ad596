"""Linear solves with the banded block matrices of coupled Fourier modes.

The adding and subtracting equations need ``Y = A^-1 B`` for ``A = I - K`` (or
``T^T T + eps^2 I``) where ``K`` couples Fourier mode ``k`` only to modes ``k +- 2s``,
``|s| <= ms`` (Zeltner & Jakob 2018 eq. (10)): ordered by mode, ``A`` is block banded. The
paper factors it once with UMFPACK and runs custom sparse-sparse substitutions (sec. 3.3).
Here (:func:`banded_solve` drives it):

1. **Components.** Mode parity is conserved, and for mirror-symmetric stacks (aligned layers)
   the cosine and sine slots decouple too; unknowns are ordered by (component, Fourier order),
   which keeps the matrix block banded with the bandwidth of its widest component.
2. **Active unknowns.** Rows of ``K`` that are empty (no scattering into that mode and
   ordinate, e.g. high orders at steep angles) give ``y = b`` directly and are eliminated.
3. **Block LU.** :class:`BlockBandedLU` factors the remaining matrix with dense blocks (one per
   Fourier order and component, its active ordinates), stored as dense block rows over the
   band, LAPACK partial pivoting inside the diagonal blocks and no pivoting across them.
   ``A = I - K`` with ``K`` a contraction of energy is block diagonally dominant in practice;
   the caller verifies the residual and falls back to sparse LU if it is not small.
4. **Pruned block substitution.** Right-hand sides are processed in groups (the columns of one
   source order); forward and backward substitution visit blocks outward from the source and
   stop after ``b`` consecutive blocks whose entries are below ``PRUNE`` times the group's
   largest right-hand side entry. Light entering in order ``k`` stays near order ``k``
   (coupling decays with ``|s|``), so each group touches a few dozen blocks: the sparse-RHS
   substitution of the paper, at BLAS-3 speed. Dropped entries are bounded by ``PRUNE``.
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sps

from ..stacking.adding import solve_columns, sparse_lu
from ..errors import InfeasibleError, OperatorError
from ..outofcore.assemble import from_parts
from ..outofcore.memory import empty_sparse
from ..outofcore.rowpieces import RowPieces
from ..outofcore.workspace import Workspace
from ..outofcore.memory import memory_limit
from ..threads import parallel_map, workers
from . import basis
from .pairs import PairPruner, slot_pairs

#: Relative magnitude below which blocks of the solution are treated as zero (and the
#: substitution stops after ``b`` such blocks in a row).
PRUNE = 1e-10

#: Relative residual above which a block-LU solve is redone with sparse LU, checked on
#: RESIDUAL_VECTORS random dense right-hand sides (:func:`_residual`).
RESIDUAL_CHECK = 1e-9
RESIDUAL_VECTORS = 8

#: Bytes of the dense solution of one group of right-hand sides in the substitutions, at
#: most (if it spread over all the coupled unknowns): the groups of the first blocks of a
#: strongly coupled stack hold over a thousand columns.
GROUP_BYTES = 32 << 20


class BlockBandedLU:
    """LU factorisation of a block-banded matrix given by its dense block rows.

    Parameters
    ----------
    rows : list of ndarray
        ``rows[i]`` has shape ``(r_i, c_i)``: block row ``i`` over the column blocks
        ``lo(i) .. hi(i) - 1`` with ``lo(i) = max(0, i - b)``, ``hi(i) = min(J, i + b + 1)``
        (overwritten by the factors: the multipliers left of the diagonal, the inverse of
        the diagonal block, ``U`` right of it).
    starts : int ndarray (J + 1,)
        Block boundaries of the unknowns.
    bandwidth : int
    """

    def __init__(self, rows: list, starts, bandwidth: int):
        self.starts = np.asarray(starts, np.int64)
        self.J = J = self.starts.size - 1
        self.b = b = int(bandwidth)
        self.R = rows
        for j in range(J):
            Rj = self.R[j]
            cj = self._cols(j, j, j + 1)
            with warnings.catch_warnings():     # an exactly singular block: the caller
                warnings.simplefilter("error", sla.LinAlgWarning)  # falls back to sparse LU
                try:
                    D = sla.lu_factor(Rj[:, cj], check_finite=False)
                except sla.LinAlgWarning as exc:
                    raise np.linalg.LinAlgError(f"block LU: {exc}") from None
            inverse = sla.lu_solve(D, np.eye(D[0].shape[0]), check_finite=False)
            if not np.all(np.isfinite(inverse)):
                raise np.linalg.LinAlgError("singular diagonal block in the block LU")
            hi = min(J, j + b + 1)
            if hi > j + 1:
                U = Rj[:, self._cols(j, j + 1, hi)]
                for i in range(j + 1, hi):
                    Ri = self.R[i]
                    ci = self._cols(i, j, j + 1)
                    Lij = sla.lu_solve(D, Ri[:, ci].T, trans=1, check_finite=False).T
                    Ri[:, ci] = Lij
                    Ri[:, self._cols(i, j + 1, hi)] -= Lij @ U
            # The explicit inverse of the diagonal block replaces it in its block row (no
            # later step reads it): the substitutions run in worker threads, and
            # scipy.linalg's LAPACK wrappers give corrupted results when called concurrently
            # (numpy's matmul does not). Kept beside the rows, the factors and the inverses
            # would take 2 x 8 sum(r_j^2) bytes more.
            Rj[:, cj] = inverse
            del D, inverse

    def _inverse(self, j: int) -> np.ndarray:
        """Inverse of the diagonal block ``j`` (a view into its block row)."""
        return self.R[j][:, self._cols(j, j, j + 1)]

    def _lo(self, i: int) -> int:
        return max(0, i - self.b)

    def _cols(self, i: int, a: int, z: int) -> slice:
        """Columns of block row ``i`` holding column blocks ``a .. z-1``."""
        base = self.starts[self._lo(i)]
        return slice(int(self.starts[a] - base), int(self.starts[z] - base))

    @staticmethod
    def band_shape(starts, bandwidth: int, i: int) -> tuple:
        J = len(starts) - 1
        lo, hi = max(0, i - bandwidth), min(J, i + bandwidth + 1)
        return int(starts[i + 1] - starts[i]), int(starts[hi] - starts[lo])

    @staticmethod
    def memory_estimate(starts, bandwidth: int) -> int:
        """Bytes of the dense block rows."""
        J = len(starts) - 1
        return 8 * sum(int(np.prod(BlockBandedLU.band_shape(starts, bandwidth, i)))
                       for i in range(J))

    def solve(self, rhs: dict, lo: int, hi: int, tol: float = PRUNE) -> dict:
        """Solve for one group of right-hand sides.

        Parameters
        ----------
        rhs : dict
            ``{block j: dense (r_j, ncols)}`` for ``lo <= j < hi`` (missing blocks are zero);
            emptied, each block released as the forward substitution uses it (and each block
            of the forward solution as the backward one does), so that the right-hand side,
            the forward and the backward solution are not held at once.
        tol : float
            Blocks of the solution below ``tol`` times the largest right-hand side entry are
            dropped; the substitution stops after ``b`` such blocks beyond the support.

        Returns
        -------
        dict
            ``{block j: dense (r_j, ncols)}`` of the (pruned) solution.
        """
        J, b = self.J, self.b
        scale = max((float(np.abs(v).max()) for v in rhs.values() if v.size), default=0.0)
        if scale == 0.0:
            return {}
        ncols = next(iter(rhs.values())).shape[1]
        cut = tol * scale
        size = lambda j: int(self.starts[j + 1] - self.starts[j])

        def stacked(store, a, z):
            """Vertical stack of store[a..z-1] (zeros where missing), or None."""
            if not any(k in store for k in range(a, z)):
                return None
            return np.vstack([store[k] if k in store else np.zeros((size(k), ncols))
                              for k in range(a, z)])

        Z: dict = {}
        quiet = 0
        for j in range(lo, J):
            t = rhs.pop(j, None)
            a = max(lo, j - b)
            prev = stacked(Z, a, j) if j > a else None
            if prev is not None:
                u = self.R[j][:, self._cols(j, a, j)] @ prev
                t = -u if t is None else t - u
            if t is not None and np.abs(t).max() > cut:
                Z[j] = t
                quiet = 0
            else:
                quiet += 1
                if j >= hi and quiet >= b:
                    break
        if not Z:
            return {}
        Y: dict = {}
        quiet = 0
        for j in range(max(Z), -1, -1):
            t = Z.pop(j, None)
            z = min(J, j + b + 1)
            nxt = stacked(Y, j + 1, z) if z > j + 1 else None
            if nxt is not None:
                u = self.R[j][:, self._cols(j, j + 1, z)] @ nxt
                t = -u if t is None else t - u
            if t is not None:
                y = self._inverse(j) @ t
                if np.abs(y).max() > cut:
                    Y[j] = y
                    quiet = 0
                    continue
            quiet += 1
            if j < lo and quiet >= b:
                break
        return Y


def banded_solve(A, B, h: int, md: int, what: str = "the adding equations",
                 identity_minus: bool = False, relerr: float | None = None,
                 release: bool = False, workspace: Workspace | None = None) -> sps.csr_matrix:
    """``Y = A^-1 B`` for a coupled-mode matrix ``A`` (slot basis) and sparse ``B``.

    Parameters
    ----------
    A : sparse (N, N) or RowPieces
        Banded by Fourier order (unknown ``slot * h + node``); with ``identity_minus`` the
        matrix ``K`` of ``A = I - K`` (never formed). Read piece by piece
        (:class:`~layersim.outofcore.rowpieces.RowPieces`, e.g. from a file, never assembled
        unless the sparse-LU fallback runs).
    B : sparse (N, C)
    h, md : int
        Ordinates per slot and Fourier orders.
    what : str
        Named in errors.
    relerr : float, optional
        Drop entries of the solution below ``relerr`` times the largest of their ordinate pair
        (the result of :func:`~layersim.aniso.pairs.prune_pairs`), applied while the groups
        of right-hand sides are solved (:class:`~layersim.aniso.pairs.PairPruner`), so that
        the unpruned solution is never held.
    release : bool
        The caller does not use ``A`` and ``B`` afterwards: their arrays are released (the
        matrices left empty, a RowPieces closed) as soon as the solve no longer needs them,
        ``B`` once it is reordered, ``A`` once the block factorisation has passed its
        residual check.
    workspace : Workspace, optional
        Where the grouped right-hand sides and the parts of the solution wait while the
        substitutions run (:class:`~layersim.outofcore.workspace.Workspace`; in memory by
        default).

    Raises
    ------
    InfeasibleError
        If the dense factors would exceed the memory limit.
    OperatorError
        If ``A`` has empty rows (singular).
    """
    workspace = workspace or Workspace()
    M = RowPieces.of(A if isinstance(A, RowPieces) else _without_zeros(A))
    shape = B.shape
    band = Band.of(M, h, md, identity_minus, what)
    if band.active.size == 0:
        return sps.csr_matrix(B)
    band.check_memory(what)
    Bo, Brest = _ordered_rhs(M, B, band, release)
    groups = _rhs_groups(Bo, band.starts, band.blk_pos, workspace.spool())
    del Bo
    keep = (lambda *part: part) if relerr is None else PairPruner(h, relerr)
    parts = _block_lu_solve(M, A, groups, band, keep, release, workspace)
    if parts is None:
        parts = _sparse_lu_solve(M, groups, band, keep, shape[1])
    groups.close()
    # the eliminated unknowns, then one CSR matrix in the unknowns' numbering
    parts.append(keep(band.rest[Brest.row], Brest.col, Brest.data))
    del Brest
    return from_parts(parts, shape, select=None if relerr is None else keep.final_filter)


def _without_zeros(A) -> sps.csr_matrix:
    """``A`` as CSR without explicit zeros (a CSR ``A`` is cleaned in place)."""
    A = sps.csr_matrix(A)
    A.eliminate_zeros()
    return A


@dataclass
class Band:
    """The block-banded structure of ``A`` (``I - K`` with ``identity_minus``, else ``K``).

    Unknowns whose row of ``A`` is the identity (``y = b``) are eliminated (``rest``); the
    others (``active``) are ordered by (component, Fourier order): components (parity, and
    cosine vs sine for mirror-symmetric stacks) never couple, so the matrix is block banded in
    this order with the bandwidth of its widest component, and one factorisation serves them
    all. Blocks are (component, Fourier order), functions of the slot: the structure follows
    from the slot pairs holding entries (no per-entry temporaries of the tens of millions of
    entries of ``K``).
    """

    active: np.ndarray      # unknowns solved for
    rest: np.ndarray        # eliminated unknowns
    ordered: np.ndarray     # unknown at each position of the block order
    starts: np.ndarray      # block boundaries (positions), (J + 1,)
    blk_pos: np.ndarray     # block of each position
    pos: np.ndarray         # position of each unknown, -1 if eliminated
    bandwidth: int
    sign: float             # -1 for A = I - K
    identity_minus: bool

    @classmethod
    def of(cls, M, h: int, md: int, identity_minus: bool, what: str) -> "Band":
        N = M.shape[0]
        counts = M.row_counts()
        if identity_minus:
            ident = counts == 0
        else:
            if np.any(counts == 0):
                raise OperatorError(f"{what}: the system matrix has empty rows (singular)")
            ident = (counts == 1) & (M.diagonal() == 1.0)
        active, rest = np.flatnonzero(~ident), np.flatnonzero(ident)
        sign = -1.0 if identity_minus else 1.0
        if active.size == 0:                        # y = b
            return cls(active, rest, active, np.zeros(1, np.int64), active,
                       np.full(N, -1, np.int64), 0, sign, identity_minus)
        slot_key = _slot_keys(M, h, md)
        key_all = slot_key[active // h]
        order = np.lexsort((active, key_all))
        key = key_all[order]
        starts = np.concatenate([[0], np.flatnonzero(np.diff(key)) + 1, [order.size]])
        blk_pos = np.repeat(np.arange(starts.size - 1), np.diff(starts))
        pos = np.full(N, -1, np.int64)
        pos[active[order]] = np.arange(order.size)
        # entries between active unknowns (rows of K are empty exactly where the unknown is
        # eliminated, so only the columns need the mask)
        rs, cs = slot_pairs(M, h, columns=pos >= 0)
        blk_of_key = {k: j for j, k in enumerate(key[starts[:-1]])}
        blk_of_slot = np.array([blk_of_key.get(k, -1) for k in slot_key])
        bw = int(np.abs(blk_of_slot[rs] - blk_of_slot[cs]).max(initial=0))
        return cls(active, rest, active[order], starts, blk_pos, pos, bw, sign, identity_minus)

    @property
    def blocks(self) -> int:
        return self.starts.size - 1

    def check_memory(self, what: str) -> None:
        """Refuse a factorisation whose dense block rows exceed the memory limit."""
        need = BlockBandedLU.memory_estimate(self.starts, self.bandwidth)
        limit = memory_limit()
        if need > limit:
            raise InfeasibleError(
                f"{what}: the coupled-mode factorisation needs about {need / 2**30:.2f} GiB "
                f"(limit {limit / 2**30:.2f} GiB, LAYERSIM_MAX_MEMORY): {self.active.size} "
                f"coupled unknowns, {self.blocks} blocks, a coupling band of {self.bandwidth} "
                "orders; lower md or ms in [discretization], or n, or make the anisotropy "
                "milder")


def _ordered_rhs(M, B, band: Band, release: bool):
    """``B`` split into the rows of the active unknowns in block order (CSC), with the
    eliminated unknowns ``y_rest = b_rest`` moved to the right-hand side through the columns
    of ``K`` at those unknowns (no row-permuted copy of ``K``), and the rows of the eliminated
    unknowns (COO). With ``release`` the arrays of ``B`` are released once it is split."""
    Bc = sps.csr_matrix(B)
    Brest, Bo = Bc[band.rest], Bc[band.ordered]
    if release:
        empty_sparse(B, Bc)
    del Bc
    if band.rest.size:
        Bo = Bo - band.sign * (M.columns(band.rest) @ Brest)[band.ordered]
    return Bo.tocsc(), Brest.tocoo()


def _block_lu_solve(M, A, groups, band: Band, keep, release: bool, workspace: Workspace):
    """The parts of the solution by the block LU and the pruned substitutions, or None if the
    factorisation fails or its residual check (:func:`_residual`) refuses it. ``groups`` are
    drained by the substitutions."""
    try:
        lu = BlockBandedLU(_block_rows(M, band), band.starts, band.bandwidth)
        if _residual(lu, M, band.starts, band.ordered, band.identity_minus) > RESIDUAL_CHECK:
            return None
    except np.linalg.LinAlgError:
        return None
    if release:
        _release_matrix(A, M)
    return _solve_groups(lu, groups.drain(), band.starts, band.ordered, keep,
                         out=workspace.spool())


def _sparse_lu_solve(M, groups, band: Band, keep, n_cols: int) -> list:
    """Fallback: SuperLU (UMFPACK when installed) on the active unknowns, nonzero columns
    only; the solution as one part."""
    ordered = band.ordered
    Ao = M.to_csr()[ordered][:, ordered]
    Ao = (sps.identity(ordered.size) - Ao) if band.identity_minus else Ao
    Bo = from_parts(groups, (ordered.size, n_cols), "csc",
                    select=lambda *g: _group_triplets(band.starts, *g))
    solve = sparse_lu(sps.csc_matrix(Ao))
    Y = sps.csr_matrix(solve_columns(solve, sps.csc_matrix(Bo))).tocoo()
    return [keep(ordered[Y.row], Y.col, Y.data)]


def _residual(lu, M, starts, ordered, identity_minus) -> float:
    """Largest residual of the block-LU solution of :data:`RESIDUAL_VECTORS` random dense
    right-hand sides (fixed seed, unpruned substitution), relative to their largest entry.

    The block LU does not pivot across blocks; where that lets the factors grow, the
    solution of any right-hand side that reaches the blocks concerned carries the error, and a
    dense right-hand side reaches every block. (A sample of the actual columns, which touch a
    few dozen blocks each, would need many passes over ``K``; this takes one pass and one
    substitution over the band.)
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
        empty_sparse(A)
    M.close()


def _block_rows(M, band: Band):
    """Dense block rows over the band of ``A`` (``I - M`` or ``M``) in the block order of
    ``band``, filled piece by piece of ``M`` (:class:`RowPieces`)."""
    pos, starts, blk_pos, bw = band.pos, band.starts, band.blk_pos, band.bandwidth
    sign, identity_minus = band.sign, band.identity_minus
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

    Returns ``out`` (a list by default, or a :class:`~layersim.outofcore.spool.Spool`) holding,
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
    unknowns' numbering ``ordered[position]``) for :func:`~layersim.outofcore.assemble.from_parts`.
    Groups are solved one per worker thread (:func:`layersim.threads.workers`) at a time
    and each round's parts go through ``keep`` (a :class:`~layersim.aniso.pairs.PairPruner`)
    as they come, so that the unpruned solution (several times the pruned one) is never held,
    and into ``out`` (a list, or a :class:`~layersim.outofcore.spool.Spool` that keeps them in
    a file beside the factors).
    """
    parts = [] if out is None else out
    unknown = ordered.astype(np.int32)

    def group(task):
        gcols, (lo, hi), indptr, indices, data = task
        lo, hi = int(lo), int(hi)
        # one dense array per block (the solve releases each as it is used; a dense array of
        # all of them, viewed by the blocks, would stay whole until the end)
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

    groups, threads = iter(groups), workers()
    while True:
        todo = list(itertools.islice(groups, threads))
        if not todo:
            return parts
        for part in parallel_map(group, todo):
            parts.append(part if keep is None else keep(*part))
        del todo
