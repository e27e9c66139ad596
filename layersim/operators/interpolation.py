"""Interpolation of operator coefficients between ordinates, shared by evaluation, energies,
sampling, plots and file export.

* :func:`spline_weights`: cubic Hermite (Catmull-Rom type) weights, what ``eval`` and the
  sampler use in both elevations;
* :func:`hat_weights`: linear weights (non-negative, summing to 1), what ``albedo`` and
  ``bin_energies`` use in the incident elevation, so that they stay convex combinations of the
  energies at the ordinates;
* :func:`block_taps`, :func:`side_energies`: the per-block bookkeeping of both;
* :func:`bin_quadrature`, :func:`closed_bin`: integration of the interpolant over bins.
"""

from __future__ import annotations

import numpy as np

from .operator import BLOCKS


def spline_weights(nodes: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cubic Hermite spline weights on non-uniform ``nodes`` (increasing) at points ``x``.

    Derivatives are central differences (one-sided at the ends), so the interpolant of values
    ``f`` is ``sum_k w[:, k] f[idx[:, k]]`` with 4 taps. Beyond the ends the interpolant is
    constant (the outermost value). Returns ``idx`` (Q, 4) int64 and ``w`` (Q, 4).
    """
    nodes = np.asarray(nodes, float)
    x = np.asarray(x, float).ravel()
    n = nodes.size
    idx = np.zeros((x.size, 4), np.int64)
    w = np.zeros((x.size, 4))
    lo = x <= nodes[0]
    hi = x >= nodes[-1]
    idx[lo, 0], w[lo, 0] = 0, 1.0
    idx[hi, 0], w[hi, 0] = n - 1, 1.0
    mid = ~(lo | hi)
    if n < 2 or not mid.any():
        return idx, w
    xm = x[mid]
    k = np.clip(np.searchsorted(nodes, xm, side="right") - 1, 0, n - 2)
    x0, x1 = nodes[k], nodes[k + 1]
    width = x1 - x0
    t = (xm - x0) / width
    t2, t3 = t * t, t * t * t
    h00, h10 = 2 * t3 - 3 * t2 + 1, t3 - 2 * t2 + t
    h01, h11 = -2 * t3 + 3 * t2, t3 - t2
    # taps: k-1, k, k+1, k+2
    wm = np.zeros((xm.size, 4))
    wm[:, 1] += h00
    wm[:, 2] += h01
    has_left = k > 0
    km1 = np.maximum(k - 1, 0)
    a = np.where(has_left, h10 * width / (x1 - nodes[km1]), h10)
    wm[:, 2] += a
    wm[:, 0] -= np.where(has_left, a, 0.0)
    wm[:, 1] -= np.where(has_left, 0.0, a)
    has_right = k + 2 < n
    kp2 = np.minimum(k + 2, n - 1)
    b = np.where(has_right, h11 * width / (nodes[kp2] - x0), h11)
    wm[:, 3] += np.where(has_right, b, 0.0)
    wm[:, 2] += np.where(has_right, 0.0, b)
    wm[:, 1] -= b
    idx[mid] = np.stack([km1, k, k + 1, kp2], axis=1)
    w[mid] = wm
    return idx, w


def block_taps(op, table, mu_in: np.ndarray, mu_out: np.ndarray):
    """For each block present, the queries it serves and their 16 interpolation taps.

    ``mu_in`` and ``mu_out`` are the signed cosines of the propagation directions (Q,); yields
    ``(sel, pair, weight)``: indices into the queries, and (len(sel), 16) pair indices
    (``table.base(block) + o * h + i``) and weights of the bicubic spline in both elevations.
    Shared by the isotropic and the anisotropic ``eval``.
    """
    h = op.h
    names = np.where(mu_in > 0, np.where(mu_out < 0, "Rt", "Ttb"),
                     np.where(mu_out > 0, "Rb", "Tbt"))
    valid = (mu_in != 0) & (mu_out != 0)
    for name in BLOCKS:
        sel = np.flatnonzero(valid & (names == name))
        if sel.size == 0 or op.blocks[name] is None:
            continue
        io, wo_ = spline_weights(op.grid.mu, np.abs(mu_out[sel]))
        ii, wi_ = spline_weights(op.grid.mu, np.abs(mu_in[sel]))
        pair = table.base(name) + (io[:, :, None] * h + ii[:, None, :]).reshape(sel.size, 16)
        weight = (wo_[:, :, None] * wi_[:, None, :]).reshape(sel.size, 16)
        yield sel, pair, weight


def hat_weights(nodes: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation weights (2 taps, non-negative, summing to 1; constant beyond the
    ends) in the same (Q, 4) layout as :func:`spline_weights`."""
    nodes = np.asarray(nodes, float)
    x = np.clip(np.asarray(x, float).ravel(), nodes[0], nodes[-1])
    k = np.clip(np.searchsorted(nodes, x, side="right") - 1, 0, nodes.size - 2)
    t = (x - nodes[k]) / (nodes[k + 1] - nodes[k])
    idx = np.zeros((x.size, 4), np.int64)
    w = np.zeros((x.size, 4))
    idx[:, 0], idx[:, 1] = k, k + 1
    w[:, 0], w[:, 1] = 1.0 - t, t
    return idx, w


def side_energies(mu: np.ndarray, nodes: np.ndarray, energy) -> tuple[np.ndarray, np.ndarray]:
    """Energy fractions ``(R, T)`` of beams arriving at signed elevation cosines ``mu`` (Q,),
    interpolated linearly (:func:`hat_weights`) between the ordinates ``nodes`` (h,).

    ``energy(name, q)`` gives, for the queries ``q`` (indices into ``mu``), the fraction of a
    beam from each node that leaves through block ``name``: shape (h,) (the same for every
    query, isotropic stacks) or (len(q), h) (azimuth-dependent, anisotropic stacks), or None
    for a block left out. Beams from above use Rt / Ttb, from below Rb / Tbt.
    """
    idx, w = hat_weights(nodes, np.abs(mu))
    R = np.zeros(mu.size)
    T = np.zeros(mu.size)
    top = mu > 0
    for sel, rname, tname in ((top, "Rt", "Ttb"), (~top, "Rb", "Tbt")):
        q = np.flatnonzero(sel)
        if q.size == 0:
            continue
        for out, name in ((R, rname), (T, tname)):
            e = energy(name, q)
            if e is not None:
                e = np.broadcast_to(e, (q.size, nodes.size))
                out[q] = np.sum(w[q] * np.take_along_axis(e, idx[q], axis=1), axis=1)
    return R, T


def bin_quadrature(nodes: np.ndarray, edges: np.ndarray, order: int = 3):
    """Gauss-Legendre points integrating piecewise cubics (pieces between nodes) exactly over
    each bin: returns points, weights and the bin index of each point."""
    x, w = np.polynomial.legendre.leggauss(order)
    pts, wts, bins = [], [], []
    for b in range(edges.size - 1):
        lo, hi = edges[b], edges[b + 1]
        cuts = np.concatenate([[lo], nodes[(nodes > lo) & (nodes < hi)], [hi]])
        a, c = cuts[:-1], cuts[1:]
        half = 0.5 * (c - a)
        pts.append((0.5 * (a + c))[:, None] + half[:, None] * x[None, :])
        wts.append(half[:, None] * w[None, :])
        bins.append(np.full(a.size * order, b))
    return (np.concatenate([p.ravel() for p in pts]), np.concatenate([q.ravel() for q in wts]),
            np.concatenate(bins))


def closed_bin(edges: np.ndarray, x: float) -> int | None:
    """Index of the bin ``[edges[k], edges[k + 1])`` holding ``x``, the last bin closed (so that
    normal incidence, mu = 1, lands in the top elevation bin); None outside the edges."""
    if x == edges[-1]:
        return edges.size - 2
    k = int(np.searchsorted(edges, x, side="right")) - 1
    return k if 0 <= k < edges.size - 1 else None
