"""Homogeneous slabs (isotropic or Henyey-Greenstein scattering) by adding-doubling.

Discrete-ordinates equations of Fourier order ``l`` (solver convention: ``I+`` propagates down,
``I-`` up, optical depth ``t`` increasing downwards; Chandrasekhar 1960, ch. VI)::

    d I+/dt = -A I+ + B I-,      d I-/dt = -B I+ + A I-,
    A = M^-1 (I - omega c_l P_same W),   B = M^-1 omega c_l P_opp W

with ``M = diag(mu)``, ``W = diag(w)``, ``c_0 = 2 pi``, ``c_l = pi`` and ``P_same/opp`` the
azimuthal Fourier components of the phase function between ordinates in the same/opposite
hemispheres. The operator of a slab is built as in Jakob's layerlab tutorial sec. 4.4 (van de
Hulst 1963):

1. an initial thin slab of thickness ``tau0 = tau / 2^k <= mu_min / 2`` whose operator is exact
   (to rounding) for the discrete equations: the transfer matrix ``expm(tau0 K)`` converted to
   reflection/transmission form (this replaces the single-scattering start of layerlab, whose
   O(tau0) error forces ~50 doublings; any rational approximant of exp with r(0) = 1 conserves the
   discrete flux exactly);
2. ``k`` doublings with the adding equations specialised to a symmetric slab, batched over orders.

Orders beyond the reach of the phase function carry only the unscattered beam,
``T = diag(exp(-tau / mu))`` and ``R = 0``, in closed form.

Henyey-Greenstein components come from the Legendre expansion ``p = sum_k (2k + 1) g^k P_k / 4 pi``
and the addition theorem (normalised associated Legendre functions by their stable three-term
recurrence). The order-0 phase matrix is rescaled symmetrically (Sinkhorn) so that the discrete
phase function integrates to exactly one under the grid's quadrature: a conservative slab then
conserves energy to rounding, and reciprocity is kept.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg as sla

from ..operator import Grid, IsoOperator

#: Relative truncation of the Legendre series of the phase function.
PHASE_TOLERANCE = 1e-10


def legendre_terms(g: float, tol: float = PHASE_TOLERANCE) -> int:
    """Number of Legendre terms K (degrees 0..K-1) of HG(g) so that the neglected tail is below
    ``tol`` times the forward peak value."""
    if g == 0.0:
        return 1
    a = abs(g)
    peak = (1 + a) / (1 - a) ** 2
    k = 1
    # tail sum_{j>=k} (2j+1) a^j <= (2k+1) a^k / (1-a)^2
    while (2 * k + 1) * a ** k / (1 - a) ** 2 > tol * peak:
        k += 1
    return k


def hg_orders(g: float, tol: float = PHASE_TOLERANCE) -> int:
    """Number of azimuthal Fourier orders on which HG(g) scatters (= its Legendre terms)."""
    return legendre_terms(g, tol)


def _normalized_legendre(mu: np.ndarray, K: int, L: int) -> np.ndarray:
    """Normalised associated Legendre functions ``Lam[l, k, j] = sqrt((k-l)!/(k+l)!) P_k^l(mu_j)``
    for ``l < L``, ``k < K`` (zero for k < l), by the stable recurrences in k."""
    n = mu.size
    s = np.sqrt(np.clip(1.0 - mu * mu, 0.0, None))
    out = np.zeros((L, K, n))
    diag = np.ones(n)  # Lam_l^l
    for l in range(L):
        if l > 0:
            diag = diag * s * math.sqrt((2 * l - 1) / (2 * l))
        if l >= K:
            break
        out[l, l] = diag
        if l + 1 < K:
            out[l, l + 1] = math.sqrt(2 * l + 1) * mu * diag
        for k in range(l + 2, K):
            out[l, k] = ((2 * k - 1) * mu * out[l, k - 1]
                         - math.sqrt((k - 1) ** 2 - l * l) * out[l, k - 2]) / math.sqrt(k * k - l * l)
    return out


def hg_components(mu: np.ndarray, g: float, L: int, K: int | None = None):
    """Azimuthal Fourier components of HG between positive ordinates ``mu`` (h,).

    Returns ``(same, opp)`` of shape (L, h, h): ``p_l(mu_a, mu_b)`` for two directions in the same
    hemisphere, and for opposite hemispheres (``p_l(mu_a, -mu_b)``), such that
    ``p(cos Theta) = sum_l p_l cos(l dphi)`` (1/sr).
    """
    K = legendre_terms(g) if K is None else K
    L = min(L, K)
    lam = _normalized_legendre(mu, K, L)             # (L, K, h)
    k = np.arange(K)
    coef = (2 * k + 1) * g ** k / (4 * np.pi)        # (K,)
    parity = (-1.0) ** k                             # Lam_k^l(-mu) = (-1)^(k+l) Lam_k^l(mu)
    same = np.einsum("lka,k,lkb->lab", lam, coef, lam, optimize=True)
    opp = np.einsum("lka,k,lkb->lab", lam, coef * parity, lam, optimize=True)
    sign = (-1.0) ** np.arange(L)
    opp *= sign[:, None, None]
    factor = np.where(np.arange(L) == 0, 1.0, 2.0)[:, None, None]
    return same * factor, opp * factor


def _normalize_order0(same: np.ndarray, opp: np.ndarray, w: np.ndarray) -> None:
    """Symmetric Sinkhorn scaling of the order-0 phase matrix (in place) so that
    ``2 pi sum_b w_b (same + opp)[a, b] = 1`` for every ``a``."""
    full = same + opp
    d = np.ones(w.size)
    for _ in range(100):
        row = 2 * np.pi * (d[:, None] * full * d[None, :]) @ w
        if np.max(np.abs(row - 1.0)) < 1e-15:
            break
        d /= np.sqrt(row)
    same *= np.outer(d, d)
    opp *= np.outer(d, d)


def _thin_slab(grid: Grid, albedo: float, same: np.ndarray, opp: np.ndarray, tau0: float):
    """Exact (R, T) of a thin symmetric slab for each order, shape (L, h, h)."""
    L, h = same.shape[0], grid.h
    c = np.where(np.arange(L) == 0, 2 * np.pi, np.pi)[:, None, None]
    minv = (1.0 / grid.mu)[None, :, None]
    wrow = grid.w[None, None, :]
    A = minv * (np.eye(h)[None] - albedo * c * same * wrow)
    B = minv * (albedo * c * opp * wrow)
    K = np.empty((L, 2 * h, 2 * h))
    K[:, :h, :h], K[:, :h, h:] = -A, B
    K[:, h:, :h], K[:, h:, h:] = -B, A
    X = sla.expm(tau0 * K)
    T11, T12, T21, T22 = X[:, :h, :h], X[:, :h, h:], X[:, h:, :h], X[:, h:, h:]
    R = -np.linalg.solve(T22, T21)
    T = T11 + T12 @ R
    return R, T


def _double(R: np.ndarray, T: np.ndarray, times: int):
    """Symmetric-slab doubling, batched over orders: with Y = (I - R R)^-1 T,
    ``T' = T Y`` and ``R' = R + T R Y``."""
    eye = np.eye(R.shape[-1])
    for _ in range(times):
        Y = np.linalg.solve(eye - R @ R, T)
        R, T = R + T @ (R @ Y), T @ Y
    return R, T


def medium_operator(grid: Grid, m: int, albedo: float, g: float, tau: float,
                    eta: float) -> IsoOperator:
    """Operator of a homogeneous slab in a medium of index ``eta`` (both sides).

    Parameters
    ----------
    grid : Grid
    m : int
        Number of Fourier orders of the operator (the unscattered beam occupies all of them).
    albedo, g, tau : float
        Single-scattering albedo, HG asymmetry and optical thickness (validated by the scene).
    """
    h = grid.h
    mu = grid.mu
    direct = np.exp(-tau / mu)
    L = 0 if albedo == 0.0 or tau == 0.0 else min(m, hg_orders(g))
    R = np.zeros((m, h, h))
    T = np.zeros((m, h, h))
    T[:, np.arange(h), np.arange(h)] = direct
    if L > 0:
        same, opp = hg_components(mu, g, L)
        _normalize_order0(same[0], opp[0], grid.w)
        k = max(0, math.ceil(math.log2(tau / (0.5 * mu[0]))))
        Rl, Tl = _thin_slab(grid, albedo, same, opp, tau / 2.0 ** k)
        Rl, Tl = _double(Rl, Tl, k)
        R[:L], T[:L] = Rl, Tl
    blocks = {"Rt": R, "Rb": R, "Ttb": T, "Tbt": T}
    return IsoOperator.from_dense(grid, blocks, eta, eta, delta={"Ttb": direct, "Tbt": direct})
