"""Cosine-series tools for the semi-analytic projection of microfacet BSDFs.

All series here are *cosine* series ``f(phi) = sum_k c_k cos(k phi)`` on [0, pi] (even,
2 pi-periodic), batched over rows (one row per ordinate pair). No pointwise physics is written
here: the peak factors are functions of the slope-space form ``q(phi) = c - d cos(phi)`` whose
endpoints ``q0 = q(0)`` and ``qpi = q(pi)`` the kernels report, their values come from
``physics.ndf_peak`` (:func:`peak_values`), and what this module derives is their closed-form
cosine series below, which has no pointwise counterpart in the kernels.

Peak factors (see :mod:`layersim.kernels.physics`)
--------------------------------------------------
* Beckmann: ``exp(-q) = exp(-q0) exp(d (cos phi - 1))``. By Jacobi-Anger (A&S 9.6.34) its
  coefficients are ``(2 - delta_k0) exp(-q0) I_k(d) e^-d`` (Zeltner & Jakob 2018 eq. (23);
  Jakob's layerlab tutorial sec. 5.2).
  We evaluate them with a real FFT of ``N >= 2 K`` samples of the entire function
  ``exp(d (cos phi - 1))``: the trapezoidal rule is spectrally exact for it (the aliasing error is
  the coefficient at index ``N - k``, below rounding once ``N/2`` exceeds the series length), and
  it is several times faster than ``scipy.special.ive`` for hundreds of orders.
* GGX: ``1/(1+q)^2 = 1/(a - d cos phi)^2`` with ``a = 1 + c``; from
  ``1/(a - d cos phi) = (1/s)(1 + 2 sum r^k cos k phi)``, ``s = sqrt(a^2 - d^2)``,
  ``r = d / (a + s)`` (Gradshteyn & Ryzhik 1.447.3) and differentiation in ``a``:
  ``c_0 = a / s^3``, ``c_k = 2 r^k (k s + a) / s^3``.

Smooth factor
-------------
Fitted by :func:`fit_restricted`: a weighted least-squares cosine fit on the support of the peak,
with soft zero constraints outside it (Zeltner & Jakob 2018 sec. 4.1.2), solved by batched QR.
Unlike the paper, the in-support rows are weighted by the peak factor itself, so the fit is
accurate where the product matters (the worst coefficient errors are orders of magnitude lower
than with uniform weights).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import scipy.special

from ..kernels import pointwise

#: Largest FFT used for a Beckmann peak series; longer series use scipy.special.ive.
FFT_MAX = 1 << 15


def _qcd(q0, qpi):
    q0 = np.asarray(q0, float)
    qpi = np.maximum(np.asarray(qpi, float), q0)
    return q0, qpi, 0.5 * (q0 + qpi), 0.5 * (qpi - q0)


def peak_values(q: np.ndarray, dist: str) -> np.ndarray:
    """Peak factor of the NDF at slope-space form ``q``, shape of ``q``: ``physics.ndf_peak``
    evaluated by :func:`layersim.kernels.pointwise.ndf_peak` (used for weights and bounds, never
    as a BSDF value)."""
    return pointwise.ndf_peak(q, dist)


def peak_support(q0, qpi, dist: str, tol: float) -> np.ndarray:
    """Azimuth ``phi_max`` in [0, pi] beyond which the peak factor is below ``tol`` times its
    value at phi = 0."""
    q0, qpi, c, d = _qcd(q0, qpi)
    with np.errstate(divide="ignore", invalid="ignore"):
        if dist == "ggx":
            a = 1.0 + c
            cosmax = (a - (a - d) / math.sqrt(tol)) / d
        else:
            cosmax = 1.0 + math.log(tol) / d
    cosmax = np.where(d > 0, cosmax, -1.0)
    return np.arccos(np.clip(cosmax, -1.0, 1.0))


def peak_length(q0, qpi, dist: str, relerr: float) -> np.ndarray:
    """Upper estimate of the number of cosine coefficients of the peak factor above ``relerr``
    times the zeroth one."""
    q0, qpi, c, d = _qcd(q0, qpi)
    lg = math.log(1.0 / relerr)
    if dist == "ggx":
        a = 1.0 + c
        s = np.sqrt((1.0 + q0) * (1.0 + qpi))
        r = d / (a + s)
        with np.errstate(divide="ignore"):
            k = np.where(r > 0, (lg + np.log1p(8.0 * d / np.maximum(s, 1e-300))) /
                         -np.log(np.maximum(r, 1e-300)), 0.0)
        return np.ceil(k).astype(np.int64) + 4
    # I_k(d)/I_0(d) ~ exp(-k^2 / 2d) for large d, (d/2)^k / k! for small d
    return (np.ceil(np.sqrt(2.0 * d * lg) + lg / 2.0) + 8).astype(np.int64)


def peak_series(q0, qpi, dist: str, K: int, relerr: float = 1e-16) -> np.ndarray:
    """Cosine coefficients ``0..K-1`` of the peak factor, shape (P, K) (absolute values).

    For Beckmann, the FFT length follows the *full* series length (at ``relerr``), not ``K``:
    sampling with fewer points than the series has would alias the tail onto every coefficient.
    Rows whose full length would need more than :data:`FFT_MAX` samples use
    ``scipy.special.ive`` for the ``K`` requested orders instead.
    """
    q0, qpi, c, d = _qcd(q0, qpi)
    k = np.arange(K)
    if dist == "ggx":
        a = 1.0 + c
        s = np.sqrt((1.0 + q0) * (1.0 + qpi))
        r = d / (a + s)
        with np.errstate(under="ignore"):
            out = 2.0 * (r[:, None] ** k[None, :]) * (k[None, :] * s[:, None] + a[:, None])
        out[:, 0] = a
        return out / (s ** 3)[:, None]
    out = np.empty((q0.size, K))
    full = peak_length(q0, qpi, dist, relerr)
    N = np.maximum(8, 1 << np.ceil(np.log2(2 * np.maximum(full, K) + 2)).astype(int))
    for size in np.unique(N):
        rows = np.flatnonzero(N == size)
        if size > FFT_MAX:
            with np.errstate(under="ignore"):
                vals = scipy.special.ive(k[None, :], d[rows, None])
            vals[:, 1:] *= 2.0
            out[rows] = vals
            continue
        phi = np.arange(size) * (2.0 * np.pi / size)
        with np.errstate(under="ignore"):
            samples = np.exp(d[rows, None] * (np.cos(phi)[None, :] - 1.0))
        coef = np.fft.rfft(samples, axis=1).real[:, :K] / size
        coef[:, 1:] *= 2.0
        out[rows] = coef
    with np.errstate(under="ignore"):
        return out * np.exp(-q0)[:, None]


def cos_product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cosine coefficients of the product of two batched cosine series ``a`` (P, La) and ``b``
    (P, Lb) (Lb short), shape (P, La + Lb - 1). Uses
    ``cos(j x) cos(k x) = (cos((j+k) x) + cos((j-k) x)) / 2``."""
    P, La = a.shape
    Lb = b.shape[1]
    out = np.zeros((P, La + Lb - 1))
    for k in range(Lb):
        bk = 0.5 * b[:, k:k + 1]
        out[:, k:k + La] += a * bk                       # j + k
        n = La - k
        if n > 0:
            out[:, :n] += a[:, k:] * bk                  # j - k >= 0
        t = min(k, La)
        if t > 0:
            out[:, k - t + 1:k + 1] += a[:, :t][:, ::-1] * bk  # k - j, j < k
    return out


def taper_factors(m: int) -> np.ndarray:
    """Jackson kernel factors ``g_0 .. g_{m-1}`` (``g_0 = 1``) that a cosine series cut at
    ``m`` orders is multiplied with, so that it blurs instead of ringing.

    ``sum_l g_l c_l cos(l phi)`` is the series of ``f`` convolved with the Jackson kernel
    ``K_m(phi) = (1 / 2 pi) (1 + 2 sum_{0 < l < m} g_l cos(l phi))``, which is non-negative
    (the squared modulus of a trigonometric polynomial of degree ``m - 1``, by construction;
    Weisse, Wellein, Alvermann & Fehske 2006, Rev. Mod. Phys. 78, 275, sec. II.C.3, eq. (71)
    with ``N = m``): the tapered series of a non-negative ``f`` is non-negative at every
    azimuth, whatever ``m``. Lanczos sigma factors ``sinc(l / m)``, whose kernel has side
    lobes down to -4.8 % of its peak, are not. Order 0, hence energy, is unchanged; order
    ``l`` changes by ``1 - g_l ~ (pi l / m)^2 / 2``, and the kernel's half-maximum width
    is ~``2.4 pi / m`` (1.36 times that of the sigma factors).

    Parameters
    ----------
    m : int
        Orders kept (>= 1).

    Returns
    -------
    ndarray, shape (m,)
    """
    n = np.arange(m)
    a = math.pi / (m + 1)
    return ((m - n + 1) * np.cos(a * n) + np.sin(a * n) / math.tan(a)) / (m + 1)


@functools.lru_cache(maxsize=16)
def _gl(n):
    """Gauss-Legendre nodes and weights on [0, 1] (cached: computing them is an eigenproblem)."""
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def fit_nodes(phi_max: np.ndarray, q_in: int, q_out: int):
    """Sample azimuths for :func:`fit_restricted`: ``q_in`` Gauss-Legendre nodes on
    [0, phi_max] and ``q_out`` on [phi_max, pi], with their quadrature weights."""
    t_in, w_in = _gl(q_in)
    t_out, w_out = _gl(q_out)
    span_out = np.pi - phi_max
    phi = np.concatenate([phi_max[:, None] * t_in[None, :],
                          phi_max[:, None] + span_out[:, None] * t_out[None, :]], axis=1)
    w = np.concatenate([phi_max[:, None] * w_in[None, :], span_out[:, None] * w_out[None, :]],
                       axis=1)
    return phi, w


def fit_restricted(phi: np.ndarray, weights: np.ndarray, values: np.ndarray, peak: np.ndarray,
                   q_in: int, L: int, eps: float = 1e-5):
    """Batched weighted least-squares cosine fit of the smooth factor.

    Parameters
    ----------
    phi, weights : ndarray (P, Q)
        Nodes and quadrature weights from :func:`fit_nodes` (first ``q_in`` columns inside the
        support).
    values : ndarray (P, Q)
        Smooth factor at the nodes (only the first ``q_in`` are fitted).
    peak : ndarray (P, Q)
        Peak factor at the nodes relative to its value at phi = 0 (in [0, 1]).
    L : int
        Number of cosine terms.
    eps : float
        Weight of the soft constraint ``fit = 0`` outside the support (Zeltner & Jakob 2018
        sec. 4.1.2).

    Returns
    -------
    coef : ndarray (P, L)
    residual : ndarray (P,)
        Relative weighted RMS residual of the in-support rows (used to detect pairs whose smooth
        factor is not smooth, e.g. a Fresnel kink at the critical angle).
    """
    P, Q = phi.shape
    rw = np.sqrt(weights)
    rw[:, :q_in] *= np.sqrt(peak[:, :q_in])
    rw[:, q_in:] *= eps
    basis = np.empty((P, Q, L))
    cos1 = np.cos(phi)
    basis[:, :, 0] = 1.0
    if L > 1:
        basis[:, :, 1] = cos1
    for j in range(2, L):  # Chebyshev recurrence: cos(j phi) = 2 cos(phi) cos((j-1) phi) - ...
        basis[:, :, j] = 2.0 * cos1 * basis[:, :, j - 1] - basis[:, :, j - 2]
    basis *= rw[:, :, None]
    rhs = np.zeros((P, Q))
    rhs[:, :q_in] = values[:, :q_in] * rw[:, :q_in]
    qm, r = np.linalg.qr(basis)
    proj = np.einsum("pqj,pq->pj", qm, rhs)
    # R is upper triangular; guard exactly singular rows (all-zero samples)
    diag = np.abs(np.diagonal(r, axis1=1, axis2=2))
    r = r + np.eye(L)[None] * (1e-300 + 1e-14 * diag.max(axis=1, keepdims=True)[..., None]
                               * (diag[..., None] < 1e-14 * diag.max(axis=1)[:, None, None]))
    coef = np.linalg.solve(r, proj[..., None])[..., 0]
    fitted = np.einsum("pqj,pj->pq", basis[:, :q_in], coef)
    num = np.sqrt(np.sum((fitted - rhs[:, :q_in]) ** 2, axis=1))
    den = np.sqrt(np.sum(rhs[:, :q_in] ** 2, axis=1))
    residual = np.where(den > 0, num / np.maximum(den, 1e-300), 0.0)
    return coef, residual
