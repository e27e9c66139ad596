"""Radial shapes of sums of microfacet slopes: the lobe of a specular path.

A path's exit wave vector deviates from the specular one by ``Delta p = sum_e c_e R_e
diag(alpha_e) x_e`` (:mod:`.lobes`), ``x_e`` independent slopes of unit roughness with the
slope density ``P22`` (Heitz 2014, eq. 9): GGX ``1 / (pi (1 + r^2)^2)``, whose characteristic
function is ``s K1(s)`` (a bivariate Student t with 2 degrees of freedom), and Beckmann
``exp(-r^2) / pi``, whose characteristic function is ``exp(-s^2 / 4)``. In coordinates
whitened by the summed scale matrix ``M = sum_e M_e`` the density of the sum is radial,
``g(r) / sqrt(det M)``, with

    g(r) = 1/(2 pi) int_0^inf prod_e phi_e(beta_e k) J0(k r) k dk,   beta_e^2 = tr M_e / tr M

(the inverse Hankel transform of the product of the events' characteristic functions). This is
exact for isotropic events and for Beckmann ones (Gaussians: covariances add, Belcour 2018,
sec. 5, made exact in shape); for GGX events of different anisotropies it keeps the summed
scale matrix and the radial shape of the scales, an approximation.

Shapes are tabulated in ``t = r^2 / (1 + r^2)`` in [0, 1], where the density of ``t`` is
``h(t) = pi g(r) (1 + r^2)^2`` (1 for one GGX event, and 1 at ``t = 1`` for any sum of GGX
events, whose tails add: each ``~ beta_e^2 / (pi r^4)``); ``h`` is piecewise linear between the
nodes, normalised to unit integral, and sampled by inverting its piecewise quadratic CDF.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.special import j0, k1

__all__ = ["T_NODES", "radial_shape", "shape_density", "sample_t", "g_of_r"]

#: Nodes in ``t``: uniform to 0.995 (``r`` = 14), then ``t = 1`` (``r`` infinite), where ``h`` is
#: the tails' limit ``sum of beta_e^2 over GGX events``.
T_NODES = np.concatenate([np.linspace(0.0, 0.995, 200), [1.0]])

#: Gauss-Legendre nodes (60 panels) of the Hankel integral on ``k`` in [0, 60]: the product of
#: characteristic functions is below ``exp(-60)`` there (``sum beta_e >= 1`` for GGX events,
#: ``exp(-k^2 / 4)`` for Beckmann ones), and 6000 nodes resolve ``J0(k r)`` to ``r = 14``
#: (135 periods) to 1e-12.
_K_MAX, _K_NODES = 60.0, 6000


@functools.lru_cache(maxsize=1)
def _hankel_kernel():
    # composite Gauss-Legendre: 60 panels of 100 nodes (one rule of 6000 nodes costs seconds
    # to build)
    x, w = np.polynomial.legendre.leggauss(_K_NODES // 60)
    width = _K_MAX / 60
    k = ((np.arange(60)[:, None] + 0.5 * (x[None, :] + 1.0)) * width).ravel()
    w = np.tile(0.5 * width * w, 60)
    t = T_NODES[:-1]
    r = np.sqrt(t / (1.0 - t))
    return k, j0(np.outer(r, k)) * (w * k)[None, :] / (2.0 * np.pi), r


def _characteristic(k: np.ndarray, beta: np.ndarray, ggx: np.ndarray) -> np.ndarray:
    out = np.ones_like(k)
    for b, is_ggx in zip(beta, ggx):
        s = b * k
        if is_ggx:
            with np.errstate(invalid="ignore", over="ignore"):
                v = np.where(s > 0, s * k1(np.maximum(s, 1e-300)), 1.0)
            out = out * np.nan_to_num(v, nan=0.0)
        else:
            out = out * np.exp(-0.25 * s * s)
    return out


def radial_shape(beta, ggx) -> np.ndarray:
    """``h`` at :data:`T_NODES` for events of relative scales ``beta`` (sum of squares 1)
    and distributions ``ggx`` (True: GGX, False: Beckmann); unit integral."""
    beta = np.asarray(beta, float)
    ggx = np.asarray(ggx, bool)
    beta = beta / np.sqrt(np.sum(beta ** 2))
    if not ggx.any():
        t = T_NODES[:-1]
        r2 = t / (1.0 - t)
        h = np.append(np.exp(-r2) * (1.0 + r2) ** 2, 0.0)
    elif ggx.sum() == 1 and beta[ggx][0] > 1.0 - 1e-12:
        h = np.ones_like(T_NODES)
    else:
        k, kernel, r = _hankel_kernel()
        g = kernel @ _characteristic(k, beta, ggx)
        h = np.append(np.pi * g * (1.0 + r ** 2) ** 2, np.sum(beta[ggx] ** 2))
    h = np.maximum(h, 0.0)
    return h / np.trapezoid(h, T_NODES)


def _cell(t: np.ndarray):
    """The node interval of each ``t`` and the fraction across it."""
    t = np.clip(np.asarray(t, float), 0.0, 1.0)
    i = np.clip(np.searchsorted(T_NODES, t, side="right") - 1, 0, T_NODES.size - 2)
    return i, (t - T_NODES[i]) / (T_NODES[i + 1] - T_NODES[i])


def shape_density(h: np.ndarray, t: np.ndarray, rows=None) -> np.ndarray:
    """``h(t)``, the density of ``t`` (piecewise linear): ``h`` one table (T,), or tables
    (P, T) of which row ``rows[q]`` serves ``t[q]``."""
    h = np.asarray(h, float)
    i, a = _cell(t)
    if h.ndim == 1:
        return (1.0 - a) * h[i] + a * h[i + 1]
    return (1.0 - a) * h[rows, i] + a * h[rows, i + 1]


def cumulative(h: np.ndarray) -> np.ndarray:
    """The CDF of ``h`` (..., T) at the nodes (trapezoids: exact for piecewise linear)."""
    d = np.diff(T_NODES)
    c = np.cumsum(0.5 * (h[..., 1:] + h[..., :-1]) * d, axis=-1)
    return np.concatenate([np.zeros(h.shape[:-1] + (1,)), c], axis=-1)


def g_of_r(h: np.ndarray, r2: np.ndarray, rows=None) -> np.ndarray:
    """The radial density ``g`` (per unit area of whitened coordinates) at ``r^2``
    (tables and rows as :func:`shape_density`)."""
    t = r2 / (1.0 + r2)
    return shape_density(h, t, rows) * (1.0 - t) ** 2 / np.pi


def sample_t(h: np.ndarray, C: np.ndarray, rows: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``t`` drawn with density ``h[rows[q]]`` (tables (P, T), their CDFs ``C``
    (:func:`cumulative`)) from uniforms ``u`` (Q,): the inverse of the piecewise quadratic
    CDF."""
    d = np.diff(T_NODES)
    u = np.asarray(u, float) * C[rows, -1]
    i = np.empty(u.shape, int)
    for r in np.unique(rows):
        sel = rows == r
        i[sel] = np.searchsorted(C[r], u[sel], side="right") - 1
    i = np.clip(i, 0, d.size - 1)
    h0, h1, di = h[rows, i], h[rows, i + 1], d[i]
    a = 0.5 * (h1 - h0) / di
    v = np.maximum(u - C[rows, i], 0.0)
    s = 2.0 * v / (h0 + np.sqrt(np.maximum(h0 * h0 + 4.0 * a * v, 0.0)) + 1e-300)
    return np.clip(T_NODES[i] + np.minimum(s, di), 0.0, 1.0 - 1e-15)
