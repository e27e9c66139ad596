"""Microfacet BRDF with a tabulated or analytic NDF, in float64 numpy (Wang et al. 2008, sec. 3).

The forward model of single-view NDF fitting: it makes synthetic measurements and derives the
shadowing term S(k) from an NDF given on a :class:`~layersim.ndf.halfgrid.HalfGrid`.

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
from scipy.special import erf

from .halfgrid import HalfGrid


def half_vector(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """h = (i + o) / |i + o|, shape ``(..., 3)``."""
    h = np.asarray(wi, float) + np.asarray(wo, float)
    return h / np.linalg.norm(h, axis=-1, keepdims=True)


def reflect(o: np.ndarray, h: np.ndarray) -> np.ndarray:
    """reflect(o, h) = 2 (h . o) h - o (Wang et al. 2008, below eq. 10), shape ``(..., 3)``."""
    o, h = np.asarray(o, float), np.asarray(h, float)
    return 2.0 * np.sum(h * o, axis=-1, keepdims=True) * h - o


def _slope_form(h, alpha_u, alpha_v):
    h = np.asarray(h, float)
    return h[..., 0] ** 2 / alpha_u ** 2 + h[..., 1] ** 2 / alpha_v ** 2, h[..., 2]


def ggx_ndf(h: np.ndarray, alpha_u: float, alpha_v: float) -> np.ndarray:
    """Anisotropic GGX (Trowbridge-Reitz) NDF D(h) in 1/sr, shape ``h.shape[:-1]``; 0 for h.z <= 0.

    D(h) = 1 / (pi a_u a_v (h_x^2/a_u^2 + h_y^2/a_v^2 + h_z^2)^2).
    """
    s, z = _slope_form(h, alpha_u, alpha_v)
    d = 1.0 / (np.pi * alpha_u * alpha_v * (s + z * z) ** 2)
    return np.where(z > 0, d, 0.0)


def beckmann_ndf(h: np.ndarray, alpha_u: float, alpha_v: float) -> np.ndarray:
    """Anisotropic Beckmann NDF D(h) in 1/sr, shape ``h.shape[:-1]``; 0 for h.z <= 0.

    D(h) = exp(-(h_x^2/a_u^2 + h_y^2/a_v^2) / h_z^2) / (pi a_u a_v h_z^4).
    """
    s, z = _slope_form(h, alpha_u, alpha_v)
    zs = np.where(z > 0, z, 1.0)
    d = np.exp(-s / zs ** 2) / (np.pi * alpha_u * alpha_v * zs ** 4)
    return np.where(z > 0, d, 0.0)


def _projected_alpha_tan(k, alpha_u, alpha_v):
    """alpha(phi_k) tan(theta_k): the roughness projected on the plane of k times its tangent."""
    k = np.asarray(k, float)
    t2 = alpha_u ** 2 * k[..., 0] ** 2 + alpha_v ** 2 * k[..., 1] ** 2
    return np.sqrt(t2) / np.maximum(k[..., 2], 1e-300)


def smith_g1(k: np.ndarray, alpha_u: float, alpha_v: float, distribution: str) -> np.ndarray:
    """Closed-form Smith shadowing 1 / (1 + Lambda(k)) of the GGX or Beckmann NDF.

    It is the same function as eq. (5) of Wang et al. 2008 evaluated on that NDF (Ashikmin's
    derivation and Smith's agree for any NDF: both divide the projected area cos(theta_k) by the
    area of the microfacets facing k), so it checks :func:`shadowing_table`.

    Parameters
    ----------
    k : array (..., 3), unit vectors with k.z > 0
    distribution : "ggx" or "beckmann"
    """
    at = _projected_alpha_tan(k, alpha_u, alpha_v)
    if distribution == "ggx":
        lam = 0.5 * (np.sqrt(1.0 + at * at) - 1.0)
    elif distribution == "beckmann":
        a = 1.0 / np.maximum(at, 1e-300)
        lam = 0.5 * (erf(a) - 1.0) + np.exp(-a * a) / (2.0 * a * np.sqrt(np.pi))
    else:
        raise ValueError(f"distribution must be 'ggx' or 'beckmann', not {distribution!r}")
    return 1.0 / (1.0 + lam)


def fresnel_unpolarized(c: np.ndarray, eta: float) -> np.ndarray:
    """Unpolarised dielectric Fresnel reflectance, Wang et al. 2008 eq. (3) (Cook & Torrance 1981).

    Parameters
    ----------
    c : array, |i . h| (cosine of the angle of incidence on the microfacet)
    eta : float > 1, relative index of refraction
    """
    c = np.abs(np.asarray(c, float))
    g = np.sqrt(eta * eta + c * c - 1.0)
    a = (g - c) ** 2 / (2.0 * (g + c) ** 2)
    b = (c * (g + c) - 1.0) ** 2 / (c * (g - c) + 1.0) ** 2
    return a * (1.0 + b)


def specular_brdf(wi, wo, ndf, shadow, eta: float | None = None) -> np.ndarray:
    """Microfacet BRDF f = D(h) S(i) S(o) F / (4 cos_i cos_o) in 1/sr, Wang et al. 2008 eq. (2, 4).

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
    wi, wo = np.asarray(wi, float), np.asarray(wo, float)
    h = half_vector(wi, wo)
    ci, co = wi[..., 2], wo[..., 2]
    f = np.ones(h.shape[:-1]) if eta is None else fresnel_unpolarized(np.sum(wi * h, -1), eta)
    ok = (ci > 0) & (co > 0)
    val = ndf(h) * shadow(wi) * shadow(wo) * f / (4.0 * np.where(ok, ci * co, 1.0))
    return np.where(ok, val, 0.0)


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
