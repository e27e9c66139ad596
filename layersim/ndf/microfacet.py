"""Microfacet BRDF with a tabulated or analytic NDF, in float64 (Wang et al. 2008, sec. 3).

The forward model of single-view NDF fitting: it makes synthetic measurements and derives the
shadowing term S(k) from an NDF given on a :class:`~layersim.ndf.halfgrid.HalfGrid`. The pointwise
physics (analytic D, Smith's S, the Fresnel term and the BRDF's product of eq. 2) is that of
:mod:`layersim.kernels.physics`, evaluated on arrays by :mod:`layersim.kernels.pointwise`; this
module holds the geometry (half vectors, mirror directions) and the quadratures of eq. (5) over a
table of D, for which the kernels have no pointwise counterpart.

Conventions (``docs/conventions.md``): unit vectors of shape ``(..., 3)`` in the local frame, z the
macro-surface normal, ``wi`` toward the light and ``wo`` toward the viewer, both pointing away from
the surface; NDF values in 1/sr, normalised so that the projected area integrates to 1,
``int (h . n) D(h) dw_h = 1``; BRDF values in 1/sr without the cosine factor.

References
----------
Wang, Zhao, Tong, Snyder, Guo, 2008, "Modeling anisotropic surface reflectance with example-based
microfacet synthesis", ACM TOG 27(3): eq. (2) the specular BRDF, eq. (3) the Fresnel term, eq. (4)
G = S(i) S(o), eq. (5) S derived from D (after Ashikmin et al. 2000).
"""

from __future__ import annotations

import numpy as np

from ..kernels import pointwise
from .halfgrid import HalfGrid


def half_vector(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """h = (i + o) / |i + o|, shape ``(..., 3)``."""
    h = np.asarray(wi, float) + np.asarray(wo, float)
    return h / np.linalg.norm(h, axis=-1, keepdims=True)


def reflect(o: np.ndarray, h: np.ndarray) -> np.ndarray:
    """reflect(o, h) = 2 (h . o) h - o (Wang et al. 2008, below eq. 10), shape ``(..., 3)``."""
    o, h = np.asarray(o, float), np.asarray(h, float)
    return 2.0 * np.sum(h * o, axis=-1, keepdims=True) * h - o


def specular_brdf(wi, wo, ndf, shadow, eta: float | None = None) -> np.ndarray:
    """Microfacet BRDF f = D(h) S(i) S(o) F / (4 cos_i cos_o) in 1/sr, Wang et al. 2008 eq. (2, 4).

    ``D`` and ``S`` are evaluated here (they may be tables); the product with the Fresnel and
    Jacobian factor is :func:`layersim.kernels.pointwise.microfacet_brdf`.

    Parameters
    ----------
    wi, wo : arrays (..., 3), unit vectors toward light and viewer
    ndf : callable h (..., 3) -> D (...) in 1/sr
    shadow : callable k (..., 3) -> S (...)
    eta : relative index for the Fresnel term of eq. (3); None: F = 1, as the fit assumes

    Returns
    -------
    f : array (...), 0 where either direction is below the horizon
    """
    wi, wo = np.broadcast_arrays(np.asarray(wi, float), np.asarray(wo, float))
    h = half_vector(wi, wo)
    f = pointwise.microfacet_brdf(wi, wo, ndf(h), shadow(wi), shadow(wo), eta)
    return f.reshape(h.shape[:-1])


def shadowing_table(grid: HalfGrid, d: np.ndarray, k: np.ndarray, chunk: int = 128) -> np.ndarray:
    """S(k) derived from a tabulated NDF, Wang et al. 2008 eq. (5) (Ashikmin et al. 2000).

    Eq. (5) divides the projected area cos(theta_k) by the projected area of the microfacets
    facing k, int <h . k>_+ D dw_h. For a height field int (h . k) D dw_h = k . n, so that area is
    (k . n) M + B(k), with M = int (h . n) D dw_h (1 when D is normalised) and
    B(k) = int <-h . k>_+ D dw_h the microfacets facing away from k. Hence the evaluated form

        S(k) = 1 / (1 + Lambda(k)),   Lambda(k) = B(k) / ((k . n) M),

    which equals eq. (5) for any complete NDF, does not depend on the scale of D (single-view
    fitting knows D only times the specular coefficient) and, for a partial NDF, needs D only
    where facets face away from k, instead of the tangential moments of D over the whole
    hemisphere that a partial NDF gets wrong.

    Parameters
    ----------
    grid : HalfGrid of the NDF
    d : array (n_theta, n_phi), D on the grid nodes (any scale; 0 where unknown)
    k : array (m, 3), unit directions with k.z > 0
    chunk : directions per block (memory: chunk * n_theta * n_phi doubles)

    Returns
    -------
    S : array (m,)
    """
    wd = (grid.weights * d).ravel()
    hs = grid.directions().reshape(-1, 3)
    mass = wd @ hs[:, 2]
    k = np.asarray(k, float).reshape(-1, 3)
    out = np.empty(len(k))
    for a in range(0, len(k), chunk):
        kb = k[a:a + chunk]
        away = np.maximum(-(kb @ hs.T), 0.0) @ wd
        out[a:a + chunk] = 1.0 / (1.0 + away / np.maximum(kb[:, 2] * mass, 1e-300))
    return out


def shadowing_rings(grid: HalfGrid, d: np.ndarray, theta_k: np.ndarray) -> np.ndarray:
    """S(k) of :func:`shadowing_table` for k on rings theta_k x grid.phi, by FFT along phi.

    The weight <-h . k>_+ depends on the azimuths of h and k only through their difference, so
    B(k) on a ring of k is a circular convolution of D's rows with a kernel, O(n log n) per ring.

    Parameters
    ----------
    grid : HalfGrid of the NDF
    d : array (n_theta, n_phi), D (any scale; 0 where unknown)
    theta_k : array (m,), polar angles of k in radians, below pi/2

    Returns
    -------
    S : array (m, n_phi), S at (theta_k[a], grid.phi[b])
    """
    th, dp = grid.theta, grid.phi
    tk = np.asarray(theta_k, float)[:, None, None]
    kern = np.maximum(-(np.sin(tk) * np.sin(th)[None, :, None] * np.cos(dp)[None, None, :]
                        + np.cos(tk) * np.cos(th)[None, :, None]), 0.0)
    wd = grid.weights * d
    spec = np.einsum("ktm,tm->km", np.fft.rfft(kern, axis=-1), np.fft.rfft(wd, axis=-1))
    away = np.fft.irfft(spec, n=grid.n_phi, axis=-1)
    mass = np.sum(wd * np.cos(th)[:, None])
    return 1.0 / (1.0 + np.maximum(away, 0.0) / np.maximum(np.cos(tk[:, :, 0]) * mass, 1e-300))
