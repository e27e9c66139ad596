"""The continuous marginal/conditional warp of a bilinear 2D density, as the RGL tensor format's
readers evaluate it (Mitsuba 3 ``Marginal2D<Float, Dim, Continuous = true>``, pbrt-v4
``PiecewiseLinear2D``), in numpy.

A table of shape ``params... + (h, w)`` holds a non-negative function on the unit square, given
at the nodes ``(x, y) = (j / (w - 1), i / (h - 1))`` and bilinear between them, one slice per
combination of parameter nodes. ``sample`` maps uniform variates to points distributed as the
function (continuous: first the marginal in ``y``, then the conditional in ``x``; no
discontinuities); ``invert`` is its inverse; ``eval`` the
interpolant. Between parameter nodes every table (the normalised data and both CDFs) is
interpolated linearly, with the weights clamped to the parameter range, so that a point
between slices is warped by the interpolated distribution. The RGL writer
(:mod:`layersim.bsdffile.rgl`) uses ``sample`` to place its grid and ``invert`` to check the
written file as a renderer reads it.

References: Dupuy & Jakob 2018, "An adaptive parameterization for efficient material
acquisition and rendering", ACM TOG 37(6) (the warp and its use); Mitsuba 3
``include/mitsuba/core/distr_2d.h`` (``Marginal2D``); pbrt-v4 ``src/pbrt/util/sampling.h``
(``PiecewiseLinear2D``).
"""

from __future__ import annotations

import numpy as np

#: The float32 epsilon that the readers clip sample variates to (``dr::Epsilon<float>``).
EPS32 = 2.0 ** -24


class Marginal2D:
    """A (possibly parameterised) bilinear density on the unit square and its warp.

    Parameters
    ----------
    data : array_like, shape ``params + (h, w)``
        Function values at the grid nodes (``h, w >= 2``), ``y`` (rows) slowest.
    param_values : sequence of 1D arrays
        Increasing node positions of each parameter axis (``len(params)`` of them).
    normalize : bool
        Scale every slice to integrate to 1 over the square (the readers' ``vndf`` and
        ``luminance``); False keeps the values (``ndf``, ``sigma``, ``spectra``).
    """

    def __init__(self, data, param_values=(), normalize: bool = True):
        data = np.asarray(data, np.float64)
        self.params = [np.asarray(p, np.float64) for p in param_values]
        self.h, self.w = data.shape[-2:]
        if self.h < 2 or self.w < 2:
            raise ValueError(f"a Marginal2D table needs at least 2 x 2 nodes, got {data.shape}")
        if data.shape[:-2] != tuple(len(p) for p in self.params):
            raise ValueError(f"table shape {data.shape} does not match the parameter sizes "
                             f"{[len(p) for p in self.params]}")
        flat = data.reshape(-1, self.h, self.w)
        # conditional CDF along x per row, then the marginal along y (trapezoids of the
        # bilinear interpolant, as the readers build them)
        cond = np.cumsum(0.5 / (self.w - 1) * (flat[:, :, :-1] + flat[:, :, 1:]), axis=2)
        rows = cond[:, :, -1]
        marg = np.cumsum(0.5 / (self.h - 1) * (rows[:, :-1] + rows[:, 1:]), axis=1)
        norm = 1.0 / marg[:, -1] if normalize else np.ones(len(flat))
        self.data = flat * norm[:, None, None]
        self.cond = cond * norm[:, None, None]
        self.marg = marg * norm[:, None]
        self.normalize = normalize

    # ---- parameters -------------------------------------------------------------------

    def corners(self, param) -> list:
        """The slices and weights that interpolate at ``param`` (one array per axis, each of
        shape (n,)): a list of ``(slice index (n,), weight (n,))``, ``2 ** len(params)`` of
        them (an axis of one node contributes weight 1)."""
        out = [(0, 1.0)]
        stride = 1
        for axis in reversed(range(len(self.params))):
            nodes = self.params[axis]
            x = np.asarray(param[axis], np.float64)
            if len(nodes) == 1:
                continue
            k = np.clip(np.searchsorted(nodes, x, side="left") - 1, 0, len(nodes) - 2)
            t = np.clip((x - nodes[k]) / (nodes[k + 1] - nodes[k]), 0.0, 1.0)
            out = [(s + stride * (k + d), w * (t if d else 1.0 - t))
                   for s, w in out for d in (0, 1)]
            stride *= len(nodes)
        return out

    @staticmethod
    def _mix(table, corners, index):
        """``table[slice, index...]`` interpolated over the parameter corners."""
        return sum(w * table[(s,) + index] for s, w in corners)

    def _cell(self, pos, corners):
        """The grid cell of each point ``pos`` (n, 2) (clipped to the square): its column and
        row ``i, j``, the fractions ``fx, fy`` within it and the corner values ``(v00, v10, v01,
        v11)`` of the data interpolated over the parameter corners."""
        pos = np.clip(np.asarray(pos, np.float64), 0.0, 1.0)
        x, y = pos[:, 0] * (self.w - 1), pos[:, 1] * (self.h - 1)
        i = np.minimum(x.astype(int), self.w - 2)
        j = np.minimum(y.astype(int), self.h - 2)
        mix = self._mix
        corner = (mix(self.data, corners, (j, i)), mix(self.data, corners, (j, i + 1)),
                  mix(self.data, corners, (j + 1, i)), mix(self.data, corners, (j + 1, i + 1)))
        return i, j, x - i, y - j, corner

    # ---- evaluation -------------------------------------------------------------------

    def eval(self, pos, param=()) -> np.ndarray:
        """The (normalised, if so built) bilinear interpolant at ``pos`` (n, 2) = (x, y)."""
        i, j, fx, fy, (v00, v10, v01, v11) = self._cell(pos, self.corners(param))
        return (1 - fy) * ((1 - fx) * v00 + fx * v10) + fy * ((1 - fx) * v01 + fx * v11)

    def sample(self, u, param=()):
        """Warp uniform variates ``u`` (n, 2) to points (n, 2) of the square; returns
        ``(points, density)``, the density being the normalised interpolant there."""
        u = np.clip(np.asarray(u, np.float64), EPS32, 1.0 - EPS32)
        c = self.corners(param)
        n = len(u)
        marg = sum(w[:, None] * self.marg[s] for s, w in _broadcast(c, n))
        uy = u[:, 1] * (1.0 if self.normalize else marg[:, -1])
        row = np.minimum(np.sum(marg < uy[:, None], axis=1), self.h - 2)
        uy = uy - np.where(row > 0, marg[np.arange(n), np.maximum(row - 1, 0)], 0.0)
        cond0 = sum(w[:, None] * self.cond[s, row] for s, w in _broadcast(c, n))
        cond1 = sum(w[:, None] * self.cond[s, row + 1] for s, w in _broadcast(c, n))
        r0, r1 = cond0[:, -1], cond1[:, -1]
        fy = _sample_segment(uy, self.h - 1, r0, r1)
        ux = u[:, 0] * (r0 + (r1 - r0) * fy)
        cdf = cond0 + (cond1 - cond0) * fy[:, None]
        col = np.minimum(np.sum(cdf < ux[:, None], axis=1), self.w - 2)
        ux = ux - np.where(col > 0, cdf[np.arange(n), np.maximum(col - 1, 0)], 0.0)
        v00, v10 = self._mix(self.data, c, (row, col)), self._mix(self.data, c, (row, col + 1))
        v01 = self._mix(self.data, c, (row + 1, col))
        v11 = self._mix(self.data, c, (row + 1, col + 1))
        c0, c1 = v00 + (v01 - v00) * fy, v10 + (v11 - v10) * fy
        fx = _sample_segment(ux, self.w - 1, c0, c1)
        pts = np.stack([(col + fx) / (self.w - 1), (row + fy) / (self.h - 1)], axis=-1)
        return pts, c0 + (c1 - c0) * fx

    def invert(self, pos, param=()):
        """Inverse of :meth:`sample`: the variates (n, 2) that map to ``pos`` (n, 2), and the
        density at ``pos``."""
        c = self.corners(param)
        n = len(pos)
        i, j, fx, fy, (v00, v10, v01, v11) = self._cell(pos, c)
        c0, c1 = v00 + (v01 - v00) * fy, v10 + (v11 - v10) * fy
        pdf = c0 + (c1 - c0) * fx
        ux = _invert_segment(fx, 1.0 / (self.w - 1), c0, c1)
        prev = np.maximum(i - 1, 0)
        before = (1 - fy) * self._mix(self.cond, c, (j, prev)) \
            + fy * self._mix(self.cond, c, (j + 1, prev))
        ux = ux + np.where(i > 0, before, 0.0)
        r0 = self._mix(self.cond, c, (j, np.full(n, self.w - 2)))
        r1 = self._mix(self.cond, c, (j + 1, np.full(n, self.w - 2)))
        ux = ux / (r0 + (r1 - r0) * fy)
        uy = _invert_segment(fy, 1.0 / (self.h - 1), r0, r1)
        uy = uy + np.where(j > 0, self._mix(self.marg, c, (np.maximum(j - 1, 0),)), 0.0)
        if not self.normalize:
            uy = uy / self._mix(self.marg, c, (np.full(n, self.h - 2),))
        return np.stack([ux, uy], axis=-1), pdf


def _broadcast(corners, n):
    """Corners with per-point slice indices and weights of shape (n,)."""
    return [(np.broadcast_to(s, (n,)), np.broadcast_to(np.asarray(w, np.float64), (n,)))
            for s, w in corners]


def _sample_segment(u, inv_width, v0, v1):
    """Position in [0, 1] within a segment whose density goes linearly from ``v0`` to ``v1``
    at which the integral reaches ``u`` (the readers' ``sample_segment``)."""
    non_const = np.abs(v0 - v1) > 1e-4 * (v0 + v1)
    divisor = np.where(non_const, v0 - v1, v0 + v1)
    s = u * 2.0 * inv_width
    s = np.where(non_const, v0 - np.sqrt(np.maximum(v0 * v0 + s * (v1 - v0), 0.0)), s)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(divisor != 0.0, s / np.where(divisor != 0.0, divisor, 1.0), s)


def _invert_segment(t, width, v0, v1):
    """Integral of the linear density over ``[0, t]`` of a segment (``invert_segment``)."""
    return t * (v0 + (v1 - v0) * 0.5 * t) * width
