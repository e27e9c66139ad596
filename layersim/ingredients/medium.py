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

Strongly forward-scattering media (``|g| >`` :data:`G_EXACT_MAX`) are delta-M scaled (Wiscombe
1977, J. Atmos. Sci. 34, 1408, eq. 2-7 and 13-15): the grid represents ``N`` Legendre moments
(:func:`grid_moments`), HG's moments are ``g^k``, and with ``f = g^N`` the phase function is
split into ``f`` times a forward delta and ``(1 - f)`` times a phase function with moments
``chi_k' = (g^k - f) / (1 - f)`` (``k < N``), which is solved with ``tau' = (1 - omega f) tau``
and ``omega' = omega (1 - f) / (1 - omega f)``. The delta part never leaves the beam, so the
unscattered transmission ``exp(-tau' / mu)`` carries the truncated forward peak. Without the
scaling, a series of thousands of terms aliased onto the grid gives discrete phase matrices of
Fourier orders >= 1 with eigenvalues above one (1.73 for g = 0.99 at n = 66: the discrete slab
amplifies, and the doubling meets a singular ``I - R R``); with ``N`` moments that the quadrature
integrates exactly, the eigenvalues are ``omega' chi_k' <= 1``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ..errors import InfeasibleError
from ..operators.operator import Grid, IsoOperator

#: Relative truncation of the Legendre series of the phase function.
PHASE_TOLERANCE = 1e-10

#: Largest |g| solved with the whole Legendre series (to :data:`PHASE_TOLERANCE`); above it the
#: phase function is delta-M scaled to the moments the grid represents. The series needs
#: ~1/(1 - g) terms (273 at g = 0.9, 574 at 0.95, 3092 at 0.99), each one more Fourier order of
#: the whole stack; ``benchmarks/features/forward_media.py`` measures both treatments (time and
#: albedo against Monte Carlo) and docs/method.md gives the figures behind this value.
G_EXACT_MAX = 0.9
#: Smallest g solved at all: a backward peak is not a forward delta, so delta-M does not apply,
#: and the whole series is used down to this value, where its discrete phase matrices are still
#: contractions at n = 64 and 196 (largest eigenvalue 1 + 3e-15; 1.013 at g = -0.97, n = 64).
G_BACKWARD_MIN = -0.95
#: Smallest grid on which the whole series is used without checking its discrete phase
#: matrices: g = 0.9 and -0.95 give contractions at n = 16 ... 196, g = 0.9 amplifies at n = 8
#: (largest eigenvalue 1.46); scene overrides below this are checked (:func:`hg_scaling`).
EXACT_MIN_N = 64
#: Rules whose polynomial exactness makes the discrete phase matrices of the moments the grid
#: represents contractions (other grids, e.g. Snell-matched ones, are checked).
GAUSS_RULES = ("gauss-lobatto", "gauss-legendre")


@dataclass(frozen=True)
class Scaling:
    """How a medium's phase function is represented on a grid (delta-M, Wiscombe 1977).

    Attributes
    ----------
    moments : int
        Legendre terms kept (degrees ``0 .. moments - 1``); also the Fourier orders on which
        the medium scatters.
    f : float
        Fraction of the phase function moved into the forward delta (0: not scaled).
    tau, albedo : float
        Optical thickness and single-scattering albedo the slab is solved with (the scaled
        ``tau'`` and ``omega'`` when ``f > 0``).
    """

    moments: int
    f: float
    tau: float
    albedo: float

    @property
    def scaled(self) -> bool:
        return self.f > 0.0

    def chi(self, g: float) -> np.ndarray:
        """The Legendre moments of the (scaled) phase function, shape (moments,)."""
        gk = g ** np.arange(self.moments, dtype=float)
        return (gk - self.f) / (1.0 - self.f) if self.scaled else gk


def grid_moments(grid: Grid, tol: float = 1e-8) -> int:
    """Number ``N`` of Legendre degrees ``0 .. N-1`` that the grid's quadrature (full range,
    both hemispheres) integrates with the right norm: ``sum_j w_j P_k(mu_j)^2 = 2 / (2k + 1)``
    within ``tol``. ``n - 1`` for Gauss-Lobatto (exact to degree 2n - 3), ``n`` for
    Gauss-Legendre; a Simpson grid gives fewer. Products ``P_j P_k`` with ``j, k < N`` are then
    integrated exactly for the Gauss rules, so the discrete phase matrices of a phase function
    with ``N`` moments have the moments as eigenvalues (no amplification)."""
    mu, w = grid.mu, grid.w
    p0, p1 = np.ones_like(mu), mu.copy()
    if abs(2.0 * w.sum() - 2.0) > tol:
        return 1
    for k in range(1, grid.n + 1):
        if abs(2.0 * (w * p1 * p1).sum() * (2 * k + 1) / 2.0 - 1.0) > tol:
            return k
        p0, p1 = p1, ((2 * k + 1) * mu * p1 - k * p0) / (k + 1)
    return grid.n


def hg_scaling(grid: Grid, g: float, albedo: float, tau: float) -> Scaling:
    """The representation of HG(g) on ``grid``: the whole series when it fits the grid, or for
    ``G_BACKWARD_MIN <= g <=`` :data:`G_EXACT_MAX` on Gauss grids of at least
    :data:`EXACT_MIN_N` ordinates (other grids: where its discrete phase matrices are checked
    to be contractions); else, for forward peaks, delta-M scaled to ``N = grid_moments(grid)``
    moments with ``f = g^N`` (Wiscombe 1977, eq. 13-15; HG's moments are ``g^k``), ``N``
    lowered on non-Gauss grids until the scaled phase matrices are contractions.

    Raises
    ------
    InfeasibleError
        For a backward peak (``g < 0``) whose whole series the grid cannot hold without
        amplification: delta-M moves forward peaks only (the truncated moments of a backward
        peak alternate in sign).
    """
    K = legendre_terms(g)
    N = grid_moments(grid)
    gauss = grid.rule in GAUSS_RULES
    hg = g ** np.arange(K, dtype=float)
    whole = Scaling(K, 0.0, tau, albedo)
    if K <= N and (gauss or _contracts(grid, hg)):
        return whole
    if G_BACKWARD_MIN <= g <= G_EXACT_MAX and ((gauss and grid.n >= EXACT_MIN_N)
                                               or _contracts(grid, hg)):
        return whole
    if g < 0:
        raise InfeasibleError(
            f"g = {g:g}: a strongly backward-scattering phase function needs {K} Legendre terms "
            f"and the grid (n = {grid.n}) represents {N}; delta-M scaling moves forward peaks "
            f"only; give g >= {G_BACKWARD_MIN:g} with n >= {EXACT_MIN_N}, or use "
            "layersim.montecarlo")
    while True:
        f = g ** N
        sc = Scaling(N, f, (1.0 - albedo * f) * tau, albedo * (1.0 - f) / (1.0 - albedo * f))
        # Gauss grids integrate the products of the N moments exactly; others are checked
        if gauss or N <= 1 or _contracts(grid, sc.chi(g)):
            return sc
        N = max(1, N * 3 // 4)


def _contracts(grid: Grid, chi: np.ndarray) -> bool:
    """Whether the discrete phase matrices of the phase function with Legendre moments ``chi``
    (every Fourier order, both parities) have spectral radius <= 1 on ``grid``: checked where
    the quadrature's exactness does not guarantee it (small or non-Gauss grids)."""
    same, opp = hg_components(grid.mu, 0.0, chi.size, chi=chi)
    _normalize_order0(same[0], opp[0], grid.w)
    c = np.where(np.arange(same.shape[0]) == 0, 2 * np.pi, np.pi)[:, None, None]
    for sign in (1.0, -1.0):
        eig = np.linalg.eigvals(c * (same + sign * opp) * grid.w[None, None, :])
        if np.max(np.abs(eig)) > 1.0 + 1e-9:
            return False
    return True


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


def hg_components(mu: np.ndarray, g: float, L: int, K: int | None = None,
                  chi: np.ndarray | None = None):
    """Azimuthal Fourier components of HG between positive ordinates ``mu`` (h,).

    Returns ``(same, opp)`` of shape (L, h, h): ``p_l(mu_a, mu_b)`` for two directions in the same
    hemisphere, and for opposite hemispheres (``p_l(mu_a, -mu_b)``), such that
    ``p(cos Theta) = sum_l p_l cos(l dphi)`` (1/sr). ``chi`` (K,) replaces HG's Legendre
    moments ``g^k`` (a delta-M scaled phase function, :meth:`Scaling.chi`).
    """
    if chi is None:
        K = legendre_terms(g) if K is None else K
        chi = g ** np.arange(K, dtype=float)
    K = chi.size
    L = min(L, K)
    lam = _normalized_legendre(mu, K, L)             # (L, K, h)
    k = np.arange(K)
    coef = (2 * k + 1) * chi / (4 * np.pi)           # (K,)
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
                    eta: float, name: str = "medium") -> IsoOperator:
    """Operator of a homogeneous slab in a medium of index ``eta`` (both sides).

    Parameters
    ----------
    grid : Grid
    m : int
        Number of Fourier orders of the operator (the unscattered beam occupies all of them).
    albedo, g, tau : float
        Single-scattering albedo, HG asymmetry and optical thickness (validated by the scene).
        Above :data:`G_EXACT_MAX` the phase function is delta-M scaled (:func:`hg_scaling`).
    eta : float
        Refractive index of the medium.
    name : str
        How error messages name the layer (e.g. ``"layer 1 (medium)"``).

    Raises
    ------
    InfeasibleError
        If the discrete slab equations are singular or give a non-finite operator (the
        message names the layer, its parameters and what to change).
    """
    h = grid.h
    mu = grid.mu
    sc = hg_scaling(grid, g, albedo, tau)
    direct = np.exp(-sc.tau / mu)       # unscattered beam, with the truncated forward peak
    L = 0 if sc.albedo == 0.0 or sc.tau == 0.0 else min(m, sc.moments)
    R = np.zeros((m, h, h))
    T = np.zeros((m, h, h))
    T[:, np.arange(h), np.arange(h)] = direct
    if L > 0:
        same, opp = hg_components(mu, g, L, chi=sc.chi(g))
        _normalize_order0(same[0], opp[0], grid.w)
        k = max(0, math.ceil(math.log2(sc.tau / (0.5 * mu[0]))))
        what = (f"{name}: tau={tau:g}, albedo={albedo:g}, g={g:g} on n = {grid.n} ordinates"
                + (f" (delta-M scaled: N = {sc.moments}, f = {sc.f:.3g})" if sc.scaled else ""))
        try:
            Rl, Tl = _thin_slab(grid, sc.albedo, same, opp, sc.tau / 2.0 ** k)
            Rl, Tl = _double(Rl, Tl, k)
        except np.linalg.LinAlgError as exc:
            raise InfeasibleError(
                f"{what}: the discrete slab equations are singular ({exc}); lower the albedo "
                "slightly below 1 or the optical thickness, or change n in [discretization]"
            ) from None
        if not (np.all(np.isfinite(Rl)) and np.all(np.isfinite(Tl))):
            raise InfeasibleError(
                f"{what}: the doubling gave a non-finite operator (ill-conditioned slab "
                "equations); lower the albedo slightly below 1 or the optical thickness, or "
                "change n in [discretization]")
        R[:L], T[:L] = Rl, Tl
    blocks = {"Rt": R, "Rb": R, "Ttb": T, "Tbt": T}
    return IsoOperator.from_dense(grid, blocks, eta, eta, delta={"Ttb": direct, "Tbt": direct})
