"""The adding equations for isotropic operators, and adding-doubling.

For a top layer 1 and a bottom layer 2 (Jakob's layerlab tutorial eq. (3); Grant & Hunt 1969)::

    Rt  = Rt1 + Tbt1 (I - Rt2 Rb1)^-1 Rt2 Ttb1
    Rb  = Rb2 + Ttb2 (I - Rb1 Rt2)^-1 Rb1 Tbt2
    Ttb = Ttb2 (I - Rb1 Rt2)^-1 Ttb1
    Tbt = Tbt1 (I - Rt2 Rb1)^-1 Tbt2

With ``A = I - Rb1 Rt2`` and the push-through identities ``(I - Rt2 Rb1)^-1 Rt2 = Rt2 A^-1`` and
``(I - Rt2 Rb1)^-1 = I + Rt2 A^-1 Rb1`` (Zeltner & Jakob 2018 eq. (12)), all four outputs need
solves with ``A`` only, which is factorised once per Fourier order::

    [Y1 | Y2] = A^-1 [Ttb1 | Rb1 Tbt2]
    Ttb = Ttb2 Y1          Rt  = Rt1 + Tbt1 Rt2 Y1
    Rb  = Rb2 + Ttb2 Y2    Tbt = Tbt1 Tbt2 + Tbt1 Rt2 Y2

Below an opaque bottom layer only ``Rt`` is computed. Each order uses dense LAPACK or sparse
SuperLU (UMFPACK via scikit-umfpack when installed) depending on the density and size of its
blocks (:data:`SPARSE_DENSITY`, :data:`SPARSE_MIN_H`); consecutive dense orders are solved as
one stacked batch (numpy's batched LAPACK and matmul).

Threads: orders are independent and can be spread over a thread pool (``threads=``), but on the
block sizes of typical plans (h <= 256) the per-order work is too small for Python threads to pay
off, and OpenBLAS's own threads slow small dense products down several-fold. Adding therefore
runs orders sequentially by default (``layersim.config.settings().order_threads``) with BLAS
limited to one thread (via threadpoolctl) for blocks below :data:`BLAS_SINGLE_BELOW` ordinates.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

from contextlib import nullcontext

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from threadpoolctl import threadpool_limits

from ..config import settings
from ..operators.deltas import add_deltas
from ..errors import OperatorError
from ..operators.operator import IsoOperator, OrderStack, prune_order

try:  # optional, faster sparse LU
    import scikits.umfpack as _umfpack  # noqa: F401
    _HAVE_UMFPACK = True
except ImportError:  # pragma: no cover - depends on the environment
    _HAVE_UMFPACK = False

#: Orders whose blocks hold fewer than this fraction of nonzeros use sparse LU ...
SPARSE_DENSITY = 0.05
#: ... if their blocks have at least this many ordinates per hemisphere: below it, SciPy's
#: per-call overhead outweighs what sparsity saves (docs/performance.md).
SPARSE_MIN_H = 128
#: The density threshold grows as ``(h / SPARSE_MIN_H)^2`` up to this factor: dense LAPACK's
#: cost grows as h^3 while the sparse path's per-call overhead does not (crossover near 5 % at
#: h = 128 and 12-15 % at h = 195, docs/performance.md).
SPARSE_DENSITY_GROWTH = 3.0
#: Entries of one (orders x h x h) array of a batch of consecutive dense orders (2 MiB;
#: :func:`_add_orders_dense`).
ORDER_BATCH_ELEMENTS = 1 << 18
#: Blocks with fewer ordinates per hemisphere than this run with single-threaded BLAS.
BLAS_SINGLE_BELOW = 512


def check_pair(top, bottom) -> None:
    """Refuse to stack ``top`` on ``bottom`` unless they share a grid, ``top`` is transmissive
    and the index of the medium between them agrees (either representation)."""
    if top.grid != bottom.grid:
        raise OperatorError(f"cannot add operators on different grids ({top.grid.rule} n="
                            f"{top.grid.n} over {bottom.grid.rule} n={bottom.grid.n}); "
                            "build both from the same discretisation plan")
    if top.opaque:
        raise OperatorError("the top operator is opaque: nothing reaches a layer below it")
    if abs(top.eta_bottom - bottom.eta_top) > 1e-9 * max(1.0, top.eta_bottom):
        raise OperatorError(f"index mismatch: the top operator ends in a medium of index "
                            f"{top.eta_bottom:g} but the bottom one starts in {bottom.eta_top:g}")


def add(top: IsoOperator, bottom: IsoOperator, threads: int | None = None) -> IsoOperator:
    """Operator of ``top`` stacked on ``bottom`` (both on the same grid).

    Parameters
    ----------
    top, bottom : IsoOperator
        ``top`` must be transmissive; ``bottom`` may be opaque (then only ``Rt`` is formed).
    threads : int, optional
        Worker threads for the Fourier orders (default
        ``layersim.config.settings().order_threads``, ``LAYERSIM_ORDER_THREADS``; see the
        module docstring).

    Returns
    -------
    IsoOperator
        With ``max(top.m, bottom.m)`` orders, ``eta_top`` of ``top`` and ``eta_bottom`` of
        ``bottom``.
    """
    check_pair(top, bottom)
    m = max(top.m, bottom.m)
    opaque = bottom.opaque

    names = ("Rt",) if opaque else ("Rt", "Rb", "Ttb", "Tbt")
    # runs of orders that go the same way (dense LAPACK in stacked batches, or sparse LU
    # order by order), each a task
    tasks = order_tasks(top, bottom, m, opaque)

    def work(task):
        orders, dense = task
        if dense:
            return _add_orders_dense(top, bottom, orders, opaque)
        return _add_orders_sparse(top, bottom, orders, opaque, names)

    threads = threads or settings().order_threads
    limit = threadpool_limits(1, user_api="blas") if top.h < BLAS_SINGLE_BELOW else nullcontext()
    with limit:
        if threads > 1 and len(tasks) > 4:
            with ThreadPoolExecutor(threads) as pool:
                results = list(pool.map(work, tasks))
        else:
            results = [work(t) for t in tasks]
    blocks = {name: OrderStack.concatenate([r[name] for r in results]) for name in names}
    delta = add_deltas(top.delta, bottom.delta, opaque)      # diagonal algebra (deltas.py)
    return IsoOperator(top.grid, blocks, top.eta_top, None if opaque else bottom.eta_bottom,
                       delta)


def order_tasks(top: IsoOperator, bottom: IsoOperator, m: int, opaque: bool) -> list:
    """The orders of :func:`add` as tasks ``(range of orders, dense)``: orders whose blocks hold
    at least :func:`sparse_density` nonzeros (all orders below :data:`SPARSE_MIN_H` ordinates)
    go dense, in runs of at most :data:`ORDER_BATCH_ELEMENTS` entries per (orders, h, h)
    array; the others sparse, one range per run (the density counts the operand blocks of the
    order, from the stored entries per order, without building per-order matrices)."""
    h = top.h
    if h < SPARSE_MIN_H:
        dense = np.ones(m, bool)
    else:
        counts = [top.order_nnz(k, m) for k in ("Rb", "Ttb", "Tbt")] + [bottom.order_nnz("Rt", m)]
        if not opaque:
            counts += [bottom.order_nnz(k, m) for k in ("Rb", "Ttb", "Tbt")]
        dense = np.sum(counts, axis=0) / (len(counts) * h * h) >= sparse_density(h)
    per = max(1, ORDER_BATCH_ELEMENTS // (h * h))
    tasks, start = [], 0
    for l in range(1, m + 1):
        if l == m or dense[l] != dense[start] or (dense[start] and l - start == per):
            tasks.append((range(start, l), bool(dense[start])))
            start = l
    return tasks


def sparse_density(h: int) -> float:
    """Fraction of nonzeros below which an order of ``h`` ordinates per hemisphere is added
    with sparse LU (:data:`SPARSE_DENSITY`, :data:`SPARSE_DENSITY_GROWTH`)."""
    growth = (h / max(SPARSE_MIN_H, 1)) ** 2
    return SPARSE_DENSITY * min(SPARSE_DENSITY_GROWTH, max(1.0, growth))


def _add_orders_sparse(top: IsoOperator, bottom: IsoOperator, orders: range, opaque: bool,
                       names: tuple) -> dict:
    """:func:`_add_order_sparse` for each order of ``orders``; ``{block: OrderStack}``."""
    out = {name: [] for name in names}
    for l in orders:
        b1 = {k: top.block(k, l) for k in ("Rt", "Rb", "Ttb", "Tbt")}
        b2 = {k: bottom.block(k, l) for k in names}
        coupled = b1["Rb"].nnz > 0 and b2["Rt"].nnz > 0
        for name, mat in _add_order_sparse(b1, b2, opaque, coupled).items():
            out[name].append(OrderStack.from_csr(mat, top.h))
    return {name: OrderStack.concatenate(stacks) for name, stacks in out.items()}


def _dense_orders(op: IsoOperator, name: str, orders: range) -> np.ndarray:
    """Block ``name`` of ``op`` for ``orders`` as a dense (len(orders), h, h) array."""
    blk = op.blocks[name]
    if isinstance(blk, OrderStack):
        return blk.dense(orders)
    return np.stack([op.block(name, l).toarray() for l in orders])


def _add_orders_dense(top: IsoOperator, bottom: IsoOperator, orders: range,
                      opaque: bool) -> dict:
    """The adding equations for a batch of orders at once, with dense LAPACK: the solves and
    products stacked, the blocks read and the results pruned and stored as stacked CSR
    (:class:`OrderStack`) without per-order SciPy matrices, whose construction would cost more
    than the arithmetic. Returns ``{block: OrderStack of the orders}``."""
    Rt1, Rb1, Ttb1, Tbt1 = (_dense_orders(top, k, orders) for k in ("Rt", "Rb", "Ttb", "Tbt"))
    Rt2 = _dense_orders(bottom, "Rt", orders)
    h = Rt1.shape[1]
    if opaque:
        rhs = Ttb1
    else:
        Rb2, Ttb2, Tbt2 = (_dense_orders(bottom, k, orders) for k in ("Rb", "Ttb", "Tbt"))
        rhs = np.concatenate([Ttb1, Rb1 @ Tbt2], axis=2)
    # uncoupled orders (Rb1 or Rt2 zero) have A = I, whose LU solve returns rhs exactly.
    # numpy.linalg, not scipy.linalg: batches may run on threads (threads=), and scipy's
    # LAPACK wrappers returned corrupted results when called concurrently (layersim.threads)
    Y = np.linalg.solve(np.eye(h) - Rb1 @ Rt2, rhs)
    Y1 = Y[:, :, :h]
    out = {"Rt": Rt1 + Tbt1 @ (Rt2 @ Y1)}
    if not opaque:
        Y2 = Y[:, :, h:]
        out["Ttb"] = Ttb2 @ Y1
        out["Rb"] = Rb2 + Ttb2 @ Y2
        out["Tbt"] = Tbt1 @ Tbt2 + Tbt1 @ (Rt2 @ Y2)
    return {k: OrderStack.from_dense(np.ascontiguousarray(v)) for k, v in out.items()}


def sparse_lu(A: sps.csc_matrix):
    """A solve function of the sparse LU factorisation of ``A`` (UMFPACK where installed,
    else SuperLU with COLAMD ordering)."""
    if _HAVE_UMFPACK:  # pragma: no cover - optional dependency
        return spla.factorized(A)
    lu = spla.splu(A, permc_spec="COLAMD")
    return lu.solve


def _add_order_sparse(b1, b2, opaque, coupled):
    Rt1, Rb1, Ttb1, Tbt1 = b1["Rt"], b1["Rb"], b1["Ttb"], b1["Tbt"]
    Rt2 = b2["Rt"]
    h = Rt1.shape[0]
    if opaque:
        rhs = Ttb1
    else:
        Rb2, Ttb2, Tbt2 = b2["Rb"], b2["Ttb"], b2["Tbt"]
        rhs = sps.hstack([Ttb1, Rb1 @ Tbt2], format="csc")
    if coupled:
        A = (sps.identity(h, format="csc") - (Rb1 @ Rt2)).tocsc()
        solve = sparse_lu(A)
        Y = sps.csr_matrix(solve_columns(solve, rhs.tocsc()))
    else:
        Y = sps.csr_matrix(rhs)
    Y1 = Y[:, :h]
    out = {"Rt": Rt1 + Tbt1 @ (Rt2 @ Y1)}
    if not opaque:
        Y2 = Y[:, h:]
        out["Ttb"] = Ttb2 @ Y1
        out["Rb"] = Rb2 + Ttb2 @ Y2
        out["Tbt"] = Tbt1 @ Tbt2 + Tbt1 @ (Rt2 @ Y2)
    return {k: prune_order(sps.csr_matrix(v)) for k, v in out.items()}


def solve_columns(solve, rhs: sps.csc_matrix) -> np.ndarray:
    """Solve for the nonzero columns of a sparse right-hand side only (empty columns stay
    zero): the sparse-RHS shortcut of Zeltner & Jakob 2018 sec. 3.3."""
    out = np.zeros(rhs.shape)
    cols = np.flatnonzero(np.diff(rhs.indptr))
    if cols.size:
        out[:, cols] = solve(rhs[:, cols].toarray())
    return out


def double(layer: IsoOperator, times: int, threads: int | None = None) -> IsoOperator:
    """Add ``layer`` to itself ``times`` times (thickness multiplied by ``2**times``)."""
    for _ in range(times):
        layer = add(layer, layer, threads)
    return layer
