"""Fourier-series tools for the projection of anisotropic microfacet BSDFs (Zeltner & Jakob
2018, sec. 4.1).

All series are batched over rows. A real ``2 pi``-periodic function is represented by its
complex coefficients for non-negative frequencies only, ``g(t) = sum_n G_n exp(i n t)`` with
``G_{-n} = conj(G_n)`` (one-sided storage, shape (rows, N)). Physics never appears here: the
peak factors are those of :mod:`layersim.operators.fourier` (exact series of ``peak(q)`` for
``q = c - d cos(t)``), shifted to the peak's azimuth.

* :func:`peak_shift_params` -- ``q(phi_d)`` at fixed ``phi_s`` is ``a + b cos(phi_d) +
  c sin(phi_d)`` (the phasor form of Zeltner & Jakob 2018, eq. (24)); from its values at
  ``0, pi/2, pi`` we get the peak azimuth ``theta0`` and the endpoints ``q0 = min q``,
  ``qpi = max q``, so that
  ``q = (q0 + qpi)/2 - (qpi - q0)/2 cos(phi_d - theta0)``.
* :func:`peak_series_shifted` -- the exact series of the peak factor about a chosen centre
  (phase-shifted Jacobi-Anger / Bessel series for Beckmann, their eq. (23); geometric series
  for GGX), and :func:`peak_samples`, the same function sampled (its FFT is that series).
* :func:`fit_restricted` -- weighted least-squares fit of the smooth factor on the support of
  the peak (Chebyshev basis, batched QR, several right-hand sides per factorisation).
* :func:`product` -- coefficients of the product of two real series.
"""

from __future__ import annotations

import numpy as np

from ..operators import fourier


def peak_shift_params(q_0, q_half, q_pi):
    """Peak azimuth and extreme values of ``q(phi) = a + b cos(phi) + c sin(phi)``.

    Parameters
    ----------
    q_0, q_half, q_pi : ndarray
        ``q`` at ``phi = 0, pi/2, pi``.

    Returns
    -------
    theta0 : ndarray
        Azimuth of the minimum of ``q`` (the peak of the NDF factor), in (-pi, pi].
    q0, qpi : ndarray
        Minimum and maximum of ``q``.
    """
    a = 0.5 * (q_0 + q_pi)
    b = 0.5 * (q_0 - q_pi)
    c = q_half - a
    r = np.hypot(b, c)
    theta0 = np.arctan2(-c, -b)
    return theta0, a - r, a + r


def peak_series_shifted(q0, qpi, shift, dist: str, K: int) -> np.ndarray:
    """One-sided complex series (``n = 0..K-1``) of ``peak(q(t - shift))`` where
    ``q(t') = (q0 + qpi)/2 - (qpi - q0)/2 cos(t')`` peaks at ``t' = 0``.

    The cosine coefficients ``c_n`` come from :func:`layersim.operators.fourier.peak_series` (FFT
    length following the full series length, GGX in closed form); ``cos(n (t - shift))`` contributes
    ``c_n / 2 exp(-i n shift)`` to frequency ``n``. Shape (P, K).
    """
    c = fourier.peak_series(q0, qpi, dist, K)
    c[:, 1:] *= 0.5
    n = np.arange(K)
    return c * np.exp(-1j * np.outer(shift, n))


def peak_samples(q0, qpi, shift, dist: str, t: np.ndarray, trig=None) -> np.ndarray:
    """Peak factor at azimuths ``t`` (rows x samples) for ``q(t) = c - d cos(t - shift)``,
    ``c = (q0 + qpi)/2``, ``d = (qpi - q0)/2``, written as in
    :func:`layersim.operators.fourier.peak_series`: ``exp(-q0) exp(-d (1 - cos))`` for Beckmann (its
    FFT gives the Jacobi-Anger/Bessel coefficients ``exp(-q0) I_k(d) e^-d``, phase-shifted by
    ``exp(-i k shift)``: Zeltner & Jakob 2018, eq. (23)-(24)), ``1 / (1 + q)^2`` for GGX
    (geometric series).

    ``trig = (cos t, sin t)``, precomputed by a caller that samples the same azimuths for
    many shifts (every ``phi_s`` sample of a batch), gives ``cos(t - shift)`` by the angle
    difference formula: two products instead of a cosine per sample (cosines dominate the
    cost of sampling the peak otherwise); its rounding error, a few
    ulp of 1, changes the exponent ``d (1 - cos)`` by ``~d 1e-16``, far below the projection's
    tolerances for any ``d`` a double-precision peak can have."""
    q0 = np.asarray(q0, float)[:, None]
    d = 0.5 * (np.maximum(np.asarray(qpi, float)[:, None], q0) - q0)
    shift = np.asarray(shift, float)[:, None]
    if trig is None:
        x = np.cos(t - shift)
    else:
        x = trig[0] * np.cos(shift)
        x += trig[1] * np.sin(shift)
    x -= 1.0                                    # x = -(1 - cos), in place from here on
    x *= d
    with np.errstate(under="ignore", over="ignore"):
        if dist == "ggx":
            x -= 1.0 + q0                       # -(1 + q)
            np.square(x, out=x)
            return np.reciprocal(x, out=x)
        x -= q0
        return np.exp(x, out=x)


def gl_nodes(half_width: np.ndarray, q: int):
    """Gauss-Legendre nodes ``t`` (P, q) on ``[-w, w]`` and their weights."""
    x, w = np.polynomial.legendre.leggauss(q)
    hw = np.asarray(half_width, float)[:, None]
    return hw * x[None, :], hw * w[None, :]


def chebyshev(x: np.ndarray, L: int) -> np.ndarray:
    """Chebyshev polynomials ``T_0..T_{L-1}`` at ``x`` (in [-1, 1]), shape x.shape + (L,)."""
    out = np.empty(x.shape + (L,))
    out[..., 0] = 1.0
    if L > 1:
        out[..., 1] = x
    for n in range(2, L):
        out[..., n] = 2.0 * x * out[..., n - 1] - out[..., n - 2]
    return out


def fit_restricted(x: np.ndarray, weights: np.ndarray, values: np.ndarray,
                   envelope: np.ndarray, L: int, floor: float = 1e-8):
    """Batched weighted least-squares fit of the smooth factor on the support of the peak.

    The support ``[-w, w]`` is mapped to ``x in [-1, 1]`` and the fit uses Chebyshev
    polynomials ``T_n(x)``, ``n < L``: unlike cosines on a small interval (the basis of
    Zeltner & Jakob 2018, sec. 4.1.2, whose conditioning grows like ``(pi / w)^L``), they
    stay well conditioned however narrow the support. The fit is only ever evaluated inside
    the support (the product with the peak factor is formed in sample space, where the peak is
    below the support tolerance outside), so the soft zero constraints of the paper, which
    keep a coefficient-space product from picking up the extrapolated fit, are not needed.
    Rows are weighted by the peak factor (``envelope``, floored at ``floor``) so that the fit
    is accurate where the product matters; solved by batched QR (not SVD), several right-hand
    sides per factorisation.

    Parameters
    ----------
    x, weights : ndarray (P, Q)
        Nodes in [-1, 1] and quadrature weights.
    values : ndarray (P, Q, R)
        Smooth factor at the nodes for ``R`` right-hand sides (the ``phi_s`` samples of a pair).
    envelope : ndarray (P, Q)
        Peak factor relative to its maximum, in [0, 1].
    L : int

    Returns
    -------
    coef : ndarray (P, L, R)
        Chebyshev coefficients.
    residual : ndarray (P, R)
        Relative weighted RMS residual.
    """
    rw = np.sqrt(weights * np.clip(envelope, floor, 1.0))
    A = chebyshev(x, L) * rw[:, :, None]
    rhs = values * rw[:, :, None]
    qm, r = np.linalg.qr(A)
    proj = np.einsum("pqj,pqr->pjr", qm, rhs)
    diag = np.abs(np.diagonal(r, axis1=1, axis2=2))
    big = diag.max(axis=1, keepdims=True)
    tiny = diag < 1e-13 * big
    r = r + np.eye(L)[None] * (1e-300 + 1e-13 * big[..., None] * tiny[:, None, :])
    coef = np.linalg.solve(r, proj)
    fitted = np.einsum("pqj,pjr->pqr", A, coef)
    num = np.sqrt(np.sum((fitted - rhs) ** 2, axis=1))
    den = np.sqrt(np.sum(rhs ** 2, axis=1))
    residual = np.where(den > 0, num / np.maximum(den, 1e-300), 0.0)
    return coef, residual
