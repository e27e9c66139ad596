"""Anisotropic rough dielectric and conductor interfaces: semi-analytic projection onto the
coupled-mode basis (Zeltner & Jakob 2018, sec. 4.1, eq. (17)-(24)).

For every ordinate pair ``(mu_i, mu_o)`` of a block we need ``f_{d,s}``, the 2-D Fourier
coefficients of the BSDF in ``phi_d = phi_o - phi_i`` and ``phi_s = phi_o + phi_i`` (interface
frame). The BSDF is split by the kernels into ``f = smooth * peak(q)``
(:func:`layersim.kernels.projection.microfacet_split_ds`), and:

1. ``phi_s`` is sampled at ``Q_s`` equispaced azimuths (trapezoidal rule = FFT, spectrally
   accurate for the smooth periodic dependence on ``phi_s``; Zeltner & Jakob use Filon
   quadrature).
   Aligned interfaces are mirror symmetric, ``f(phi_d, -phi_s) = f(-phi_d, phi_s)``, so only
   ``phi_s in [0, pi]`` is sampled and the coefficients are real.
2. At fixed ``phi_s``, ``q`` is ``a + b cos(phi_d) + c sin(phi_d)`` (their eq. (22), (24));
   the constants come from the kernel's ``q`` at ``phi_d = 0, pi/2, pi`` (no formula is repeated
   on the host). The peak factor then has an exact series about its azimuth ``theta0``
   (phase-shifted Jacobi-Anger/Bessel for Beckmann, eq. (23); geometric series for GGX), with
   the FFT length following the *full* series length
   (:func:`layersim.operators.fourier.peak_series`).
3. The smooth factor (Fresnel, shadowing-masking, Jacobian) is fitted per pair with a short
   trigonometric series on the union of the peak's supports over ``phi_s``, weighted by the
   envelope of the peak factor, with soft zero constraints outside, by QR (one factorisation per
   pair, all ``phi_s`` samples as right-hand sides; their sec. 4.1.2). Pairs whose fit
   residual is large (a Fresnel kink at the critical angle) are refitted with more terms.
4. The two series are multiplied in coefficient space, shifted to ``phi_d``, and transformed
   over the ``phi_s`` samples. Aliasing in ``phi_s`` is controlled a posteriori: pairs whose
   coefficients at ``|s| ~ Q_s / 2`` exceed :data:`S_ALIAS` of their largest are recomputed with
   twice as many samples.
5. ``|s| <= ms`` is kept (the L2 fraction dropped is recorded, see
   ``benchmarks/accuracy/ms_study.py``); ``d`` is truncated at the series length (``relerr``, see
   :data:`layersim.aniso.plan.COUPLED_RELERR`) and at
   ``md`` (Jackson kernel factors, as for isotropic interfaces).

Reflection blocks are projected on one triangle of pairs and mirrored with reciprocity
(``f_{d,s}(o <- i) = f_{-d,s}(i <- o)``); ``Tbt`` follows from ``Ttb`` by generalized
reciprocity. The operator of a rotated interface is the projected one rotated
(:meth:`~layersim.aniso.operator.AnisoOperator.rotated`: ``f_{d,s} exp(-2 i s rot)``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sps

from ..operators import fourier
from ..aniso import basis, series
from ..aniso.operator import AnisoOperator, rotate_block, slot_column_scale
from ..aniso.reciprocity import reciprocal_image, with_reciprocal_image
from ..config import settings
from ..kernels import projection as kproj
from ..operators.operator import Grid
from ..outofcore.assemble import from_parts
from ..outofcore.workspace import Workspace
from ..threads import parallel_map
from .microfacet import L_FIT as ISO_L_FIT
from .microfacet import (ENERGY_DROP, RELERR, SUPPORT_TOLERANCE, TAPER_THRESHOLD,
                         ProjectionStats, block_pairs, film_orders)

#: Smallest number of phi_s samples (a power of two; mirror symmetry samples half + 1 of them).
QS_MIN = 16
QS_MAX = 256
#: phi_s aliasing criterion: the predicted coefficients at |s| >= Q_s - ms (which fold onto the
#: kept |s| <= ms) must stay below this fraction of the pair's largest (see _aliases).
S_ALIAS = 1e-6
#: Smooth-factor fit: Chebyshev terms and Gauss-Legendre nodes on the support; pairs whose
#: residual exceeds FIT_RESIDUAL are refitted once with L_REFIT terms on Q_REFIT nodes (smooth
#: but structured factors: grazing shadowing, wide supports).
L_FIT, Q_IN = 24, 64
L_REFIT, Q_REFIT = 48, 128
#: Pairs still above FIT_RESIDUAL have a kink (the Fresnel edge at the critical angle, a
#: shadowing edge inside a broad lobe): refitting with more polynomial terms converges slowly
#: across it (~5e-2 residual at 40 terms for internal reflection at alpha 0.4), so their smooth
#: factor is sampled directly at the FFT nodes, with at least N_KINK nodes per period (the
#: series of a square-root kink decays like k^-1.5: aliasing ~N_KINK^-1.5 of the kink's size).
FIT_RESIDUAL = 1e-5
N_KINK = 512
#: Orders kept for the tail of a kinked smooth factor (beyond the peak's own length): the
#: truncated series of a square-root kink rings by ~K^-1/2 of the kink's size next to it, so
#: the kink limits the accuracy there at any practical md, while more orders cost storage and
#: time in every later operation (kinked pairs are a large share of a rough dielectric's).
K_KINK = 160
#: Coarse samples used to bound the BSDF of a pair before projecting it.
N_COARSE_D = 17
#: Pairs x coarse samples evaluated at once by _coarse: the kernel's inputs and outputs take
#: about six arrays of 8 bytes per element (~48 MiB a chunk), where all pairs of a large block
#: at once would take several times that.
COARSE_ELEMENTS = 1 << 20
#: Bound on (pairs x (phi_s samples + fit terms) x FFT length) per batch, one batch per
#: thread. The temporaries take several times 8 bytes per element; smaller batches hold less
#: memory but make the projection slower (more, shorter FFTs and fits).
BATCH_ELEMENTS = 4_000_000


@dataclass
class AnisoProjectionStats(ProjectionStats):
    """:class:`ProjectionStats` plus the anisotropic quantities."""

    qs_max: int = 0
    """Largest number of phi_s samples any pair needed."""
    s_dropped: float = 0.0
    """Largest relative L2 norm (over all d, s of a pair) of the coefficients with |s| > ms."""
    s_dropped_energy: float = 0.0
    """Relative cosine-weighted L2 norm of the dropped coefficients over all pairs: the error
    of truncating at ms, in the sense of Zeltner & Jakob 2018, eq. (25)."""
    _num: float = 0.0
    _den: float = 0.0

    def merge(self, other) -> None:
        super().merge(other)
        if isinstance(other, AnisoProjectionStats):
            self.qs_max = max(self.qs_max, other.qs_max)
            self.s_dropped = max(self.s_dropped, other.s_dropped)
            self._num += other._num
            self._den += other._den
            self.s_dropped_energy = math.sqrt(self._num / self._den) if self._den else 0.0


def _qs_for(ms: int) -> int:
    return max(QS_MIN, 1 << math.ceil(math.log2(4 * ms + 4)))


def _coarse(mu_i, mu_o, eta, au, av, dist, qs, film=None, shadowing="separable"):
    """Peak parameters at every phi_s sample and a bound of the BSDF per pair, evaluated
    for :data:`COARSE_ELEMENTS` pair samples at a time (``film``: the interface's thin film,
    :meth:`layersim.layers.Interface.film_params`, and ``shadowing``, its Smith term, as in
    every function of this module that takes them)."""
    step = max(1, COARSE_ELEMENTS // ((qs // 2 + 1) * N_COARSE_D))
    if mu_i.size <= step:
        return _coarse_chunk(mu_i, mu_o, eta, au, av, dist, qs, film, shadowing)
    parts = [_coarse_chunk(mu_i[at:at + step], mu_o[at:at + step], eta, au, av, dist, qs,
                           film, shadowing)
             for at in range(0, mu_i.size, step)]
    return tuple(np.concatenate(x) for x in zip(*parts))


def _coarse_chunk(mu_i, mu_o, eta, au, av, dist, qs, film=None, shadowing="separable"):
    """:func:`_coarse` of one chunk of pairs."""
    P = mu_i.size
    ns = qs // 2 + 1
    phi_s = np.arange(ns) * (2.0 * np.pi / qs)
    three = np.array([0.0, 0.5 * np.pi, np.pi])
    pd = np.broadcast_to(np.tile(three, ns), (P, 3 * ns))
    ps = np.broadcast_to(np.repeat(phi_s, 3), (P, 3 * ns))
    _, q = kproj.microfacet_split_ds(mu_i, mu_o, pd, ps, eta, au, av, dist)
    q = q.reshape(P, ns, 3)
    theta0, q0, qpi = series.peak_shift_params(q[..., 0], q[..., 1], q[..., 2])
    q0 = np.maximum(q0, 0.0)
    qpi = np.maximum(qpi, q0)
    # bound of the smooth factor on a coarse (phi_d, phi_s) grid
    cd = np.linspace(0.0, 2.0 * np.pi, N_COARSE_D, endpoint=False)
    pd = np.broadcast_to(np.tile(cd, ns), (P, N_COARSE_D * ns))
    ps = np.broadcast_to(np.repeat(phi_s, N_COARSE_D), (P, N_COARSE_D * ns))
    s, _ = kproj.microfacet_split_ds(mu_i, mu_o, pd, ps, eta, au, av, dist, film=film,
                                     shadowing=shadowing)
    smax = np.abs(s).max(axis=1)
    bound = 10.0 * fourier.peak_values(q0.min(axis=1), dist) * smax
    return theta0, q0, qpi, bound


def series_lengths(grid: Grid, layer, eta_above: float, ms: int, relerr: float,
                   blocks: tuple | None = None):
    """Pre-pass of the projection for the plan: how many orders in ``phi_d`` each significant
    pair of an anisotropic interface needs (the maximum over coarse ``phi_s`` samples, plus the
    smooth factor's terms), from one cheap kernel pass per block (:func:`_coarse`).

    Parameters
    ----------
    grid : Grid
    layer : Dielectric or Conductor
        Validated rough interface (``alpha_u``, ``alpha_v``; its rotation does not change the
        lengths).
    eta_above : float
        Absolute index of the medium above the interface.
    ms : int
        Coupling half-width the layer is projected with (sets the ``phi_s`` sampling).
    relerr : float
        Relative truncation of each pair's coefficients
        (:data:`layersim.aniso.plan.COUPLED_RELERR` on the coupled path).
    blocks : tuple of str, optional
        Only these of the interface's blocks (as :func:`aniso_interface_operator` projects
        them with ``only``).

    Returns
    -------
    lengths : int ndarray (P,)
        Orders each significant pair of the interface's blocks needs.
    mu_min : ndarray (P,)
        ``min(|mu_i|, |mu_o|)`` of each of those pairs, as
        :func:`layersim.ingredients.microfacet.series_lengths` returns it.
    """
    eta = complex(layer.ior) / eta_above
    film, shadowing = layer.film_params(eta_above), layer.shadowing
    names = ("Rt",) if layer.opaque else ("Rt", "Rb", "Ttb", "Tbt")
    names = names if blocks is None else tuple(n for n in names if n in blocks)
    fw = grid.flux_weight
    lengths, mu_min = [], []
    qs = max(8, _qs_for(ms) // 2)
    for name in names:
        mu_i, mu_o, o, i = block_pairs(grid, name, triangle=False)
        _, q0, qpi, bound = _coarse(mu_i, mu_o, eta, layer.alpha_u, layer.alpha_v,
                                    layer.distribution, qs, film, shadowing)
        sig = bound * 2.0 * np.pi * np.maximum(fw[i], fw[o]) > ENERGY_DROP
        n = fourier.peak_length(q0[sig].ravel(), qpi[sig].ravel(), layer.distribution, relerr)
        lengths.append(n.reshape(-1, q0.shape[1]).max(axis=1) + L_FIT
                       + film_orders(film, max(layer.alpha_u, layer.alpha_v)))
        mu_min.append(np.minimum(np.abs(mu_i[sig]), np.abs(mu_o[sig])))
    return np.concatenate(lengths), np.concatenate(mu_min)


def _supports(theta0, q0, qpi, dist):
    """Common centre ``theta_c`` and half width of the union of the peaks' supports over the
    phi_s samples of each pair."""
    peak = fourier.peak_values(q0, dist)
    w = peak / np.maximum(peak.max(axis=1, keepdims=True), 1e-300)
    theta_c = np.angle(np.sum(w * np.exp(1j * theta0), axis=1))
    half = fourier.peak_support(q0.ravel(), qpi.ravel(), dist, SUPPORT_TOLERANCE)
    half = half.reshape(q0.shape)
    off = np.abs(np.angle(np.exp(1j * (theta0 - theta_c[:, None]))))
    width = np.minimum(np.pi, np.max(np.where(w > 1e-300, off + half, 0.0), axis=1))
    return theta_c, np.maximum(width, 1e-3)


def _tau_params(mu_i, mu_o, eta, dist):
    """``tau(phi_d) = A + B cos(phi_d)`` with ``tau = |h_t|^2 / h_z^2`` (the microfacet
    prefactor is ``|h|^4 / h_z^4 = (1 + tau)^2``), read from the kernel's slope form with unit
    roughness at ``phi_d = 0, pi`` (pure geometry; no formula is repeated on the host)."""
    _, tau = kproj.microfacet_split_ds(mu_i, mu_o, np.array([[0.0, np.pi]]).repeat(mu_i.size, 0),
                                       0.0, eta, 1.0, 1.0, dist)
    return 0.5 * (tau[:, 0] + tau[:, 1]), 0.5 * (tau[:, 0] - tau[:, 1])


def _fit_smooth(mu_i, mu_o, theta_c, width, tau_ab, q_pars, phi_s, eta, au, av, dist, L,
                q_nodes, film=None, shadowing="separable"):
    """Chebyshev fit (on the support ``theta_c +- width``) of the preconditioned smooth factor
    ``smooth / (1 + tau)^2`` at every phi_s sample: coefficients (P, L, ns), residual (P, ns)."""
    theta0, q0, qpi = q_pars
    P, ns = q0.shape
    t, wt = series.gl_nodes(width, q_nodes)
    Q = t.shape[1]
    pd = np.tile(theta_c[:, None] + t, (1, ns))            # columns: phi_s sample major
    ps = np.broadcast_to(np.repeat(phi_s, Q)[None, :], (P, ns * Q))
    s, _ = kproj.microfacet_split_ds(mu_i, mu_o, pd, ps, eta, au, av, dist, film=film,
                                     shadowing=shadowing)
    s = s.reshape(P, ns, Q)
    tau = tau_ab[0][:, None] + tau_ab[1][:, None] * np.cos(theta_c[:, None] + t)
    factor = (1.0 + np.maximum(tau, 0.0)) ** 2
    s = s / factor[:, None, :]
    # envelope of the (prefactor-weighted) peak over the phi_s samples, relative
    rel = np.zeros((P, Q))
    trig = (np.cos(t), np.sin(t))
    for j in range(ns):
        pk = series.peak_samples(q0[:, j], qpi[:, j], theta0[:, j] - theta_c, dist, t,
                                 trig) * factor
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = np.maximum(rel, np.nan_to_num(pk / pk.max(axis=1, keepdims=True)))
    x = t / width[:, None]
    return series.fit_restricted(x, wt, s.transpose(0, 2, 1), rel, L)


def _project_pairs(mu_i, mu_o, eta, au, av, dist, ms, md, qs, geometry, relerr, film=None,
                   shadowing="separable"):
    """Coefficients ``F[p, d, ms + s] = f_{d,s}`` (d >= 0, |s| <= ms) of a batch of pairs
    (series length in ``d`` at ``relerr``), the pairs whose phi_s sampling aliases, the dropped
    |s| > ms fraction and the total L2."""
    theta0, q0, qpi, theta_c, width = geometry
    P, ns = q0.shape
    phi_s = np.arange(ns) * (2.0 * np.pi / qs)
    tau_ab = _tau_params(mu_i, mu_o, eta, dist)
    coef, resid = _fit_smooth(mu_i, mu_o, theta_c, width, tau_ab, (theta0, q0, qpi), phi_s,
                              eta, au, av, dist, L_FIT, Q_IN, film, shadowing)
    hard = np.any(resid > FIT_RESIDUAL, axis=1)
    if hard.any():
        redo = np.flatnonzero(hard)
        c2, r2 = _fit_smooth(mu_i[redo], mu_o[redo], theta_c[redo], width[redo],
                             (tau_ab[0][redo], tau_ab[1][redo]),
                             (theta0[redo], q0[redo], qpi[redo]), phi_s, eta, au, av, dist,
                             L_REFIT, Q_REFIT, film, shadowing)
        wide = np.zeros((P, L_REFIT, ns))
        wide[:, :L_FIT] = coef
        wide[redo] = c2
        coef = wide
        hard[redo] = np.any(r2 > FIT_RESIDUAL, axis=1)
    L = coef.shape[1]
    K = min(int(fourier.peak_length(q0.ravel(), qpi.ravel(), dist, relerr).max()) + L + 2,
            md + L_FIT)
    if hard.any():
        # a kinked smooth factor has a slowly decaying spectrum (~k^-1.5): keep its tail up
        # to K_KINK orders (and at least the peak's)
        K = max(K, min(md, K_KINK) + L_FIT)
    prod = np.zeros((P, ns, K), complex)
    for sel, direct in ((np.flatnonzero(~hard), False), (np.flatnonzero(hard), True)):
        if sel.size:
            geo = (theta0[sel], q0[sel], qpi[sel], theta_c[sel], width[sel])
            prod[sel] = _product_series(mu_i[sel], mu_o[sel], geo, phi_s, eta, au, av, dist, K,
                                        None if direct else coef[sel],
                                        (tau_ab[0][sel], tau_ab[1][sel]), film, shadowing)
    # phi_s transform with the mirror symmetry F(-phi_s)_d = conj(F(phi_s)_d)
    s_all = np.arange(-(qs // 2), qs // 2 + 1)
    wj = np.full(ns, 2.0)
    wj[0] = wj[-1] = 1.0
    ph = np.exp(-1j * np.outer(phi_s, s_all)) * (wj / qs)[:, None]      # (ns, S)
    F = np.matmul(prod.transpose(0, 2, 1), ph).real                  # (P, K, S)
    F[:, :, 0] *= 0.5   # s = -qs/2 and +qs/2 are the same sample frequency: split evenly
    F[:, :, -1] *= 0.5
    alias = _aliases(F, s_all, ms, qs)
    c0 = qs // 2
    kept = F[:, :, c0 - ms:c0 + ms + 1]
    wd = np.full(K, 2.0)
    wd[0] = 1.0
    tot = np.einsum("pds,d->p", F * F, wd)
    kep = np.einsum("pds,d->p", kept * kept, wd)
    dropped = np.sqrt(np.maximum(tot - kep, 0.0) / np.maximum(tot, 1e-300))
    # taper decision shared with the isotropic paths (microfacet.needs_taper): the analytic
    # length of the peak series at TAPER_THRESHOLD, plus the smooth factor's orders
    peak_len = (fourier.peak_length(q0.ravel(), qpi.ravel(), dist, TAPER_THRESHOLD)
                + ISO_L_FIT).reshape(P, ns)
    return kept, alias, dropped, tot, peak_len.max(axis=1), int(hard.sum())


def _product_series(mu_i, mu_o, geometry, phi_s, eta, au, av, dist, K, coef, tau_ab,
                    film=None, shadowing="separable"):
    """One-sided series in ``phi_d`` (P, ns, K) of ``smooth * peak`` at every phi_s sample,
    formed in sample space: exact peak samples times the smooth factor (the Chebyshev fit
    ``coef`` times the prefactor, or, when ``coef`` is None, the kernel's smooth factor sampled
    directly at the FFT nodes, for pairs whose smooth factor has a kink), then an FFT whose
    length follows the *full* series length (fewer samples would alias the tail onto every
    coefficient) and at least :data:`N_KINK` for directly sampled pairs."""
    theta0, q0, qpi, theta_c, width = geometry
    P, ns = q0.shape
    full = int(fourier.peak_length(q0.ravel(), qpi.ravel(), dist, 1e-16).max()) + \
        (coef.shape[1] if coef is not None else L_FIT) + 2
    full = max(full, K)
    N = max(64 if coef is not None else N_KINK, 1 << math.ceil(math.log2(2 * full + 2)))
    half = min(N // 2, int(math.ceil(width.max() * N / (2.0 * np.pi))) + 1)
    idx = np.concatenate([np.arange(half + 1), np.arange(N - half, N)]) if half < N // 2 \
        else np.arange(N)
    t = idx * (2.0 * np.pi / N)
    t = np.where(t > np.pi, t - 2.0 * np.pi, t)                       # (-pi, pi]
    n_w = t.size
    inside = np.abs(t)[None, :] <= width[:, None]                    # (P, n_w)
    if coef is not None:
        x = np.clip(t[None, :] / width[:, None], -1.0, 1.0)
        L = coef.shape[1]
        basis_ = np.empty((P, L, n_w))
        basis_[:, 0] = 1.0
        if L > 1:
            basis_[:, 1] = x
        for n in range(2, L):
            np.multiply(2.0 * x, basis_[:, n - 1], out=basis_[:, n])
            basis_[:, n] -= basis_[:, n - 2]
        smooth = np.matmul(coef.transpose(0, 2, 1), basis_)          # (P, ns, n_w)
        tau = tau_ab[0][:, None] + tau_ab[1][:, None] * np.cos(theta_c[:, None] + t[None, :])
        smooth *= ((1.0 + np.maximum(tau, 0.0)) ** 2 * inside)[:, None, :]
    else:
        pd = np.tile(theta_c[:, None] + t[None, :], (1, ns))
        ps = np.broadcast_to(np.repeat(phi_s, n_w)[None, :], (P, ns * n_w))
        smooth, _ = kproj.microfacet_split_ds(mu_i, mu_o, pd, ps, eta, au, av, dist,
                                              film=film, shadowing=shadowing)
        smooth = smooth.reshape(P, ns, n_w) * inside[:, None, :]
    trig = (np.cos(t)[None, :], np.sin(t)[None, :])       # the same azimuths for all pairs
    buf = np.zeros((P, N))
    prod = np.empty((P, ns, K), complex)
    for j in range(ns):
        buf[:, idx] = series.peak_samples(q0[:, j], qpi[:, j], theta0[:, j] - theta_c, dist,
                                          t, trig) * smooth[:, j]
        # numpy's fft sums x_n exp(-i k t_n): the coefficient of exp(i k t)
        prod[:, j] = np.fft.rfft(buf, axis=1)[:, :K] / N
    prod *= np.exp(-1j * np.outer(theta_c, np.arange(K)))[:, None, :]   # t -> phi_d
    return prod


def _aliases(F, s_all, ms, qs):
    """True for pairs whose phi_s sampling may alias onto the kept coefficients.

    Sampling ``phi_s`` at ``qs`` points folds frequency ``s + j qs`` onto ``s``; for the kept
    ``|s| <= ms`` the nearest offenders are ``|s'| >= qs - ms``. Fourier coefficients of the
    (analytic, periodic) ``phi_s`` dependence decay at least geometrically, so the envelope
    ``E(s) = max_d |f_{d,s}|`` is extrapolated geometrically from ``qs/4`` and ``qs/2 - 2``
    (where aliasing is still small) to ``qs - ms``, and compared with
    :data:`S_ALIAS` times the pair's largest coefficient.
    """
    env = np.abs(F).max(axis=1)                                      # (P, S)
    a = np.abs(s_all)
    e = lambda k: env[:, a == k].max(axis=1)
    sa, sb = qs // 4, qs // 2 - 2
    ea, eb = e(sa), e(sb)
    big = np.maximum(env.max(axis=1), 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        rate = np.where(ea > 0, (eb / np.maximum(ea, 1e-300)) ** (1.0 / (sb - sa)), 0.0)
    rate = np.minimum(np.nan_to_num(rate, nan=1.0), 1.0)
    predicted = eb * rate ** (qs - ms - sb)
    return predicted > S_ALIAS * big


def _truncate(F, md, stats, peak_len, relerr):
    """Zero coefficients below ``relerr`` times the pair's largest (this also ends each pair's
    series in d); taper series whose *peak* is cut at ``md`` (``peak_len``: the rule of
    :func:`layersim.ingredients.microfacet.needs_taper`, shared by all projection paths) with
    the Jackson kernel factors in d (:func:`layersim.operators.fourier.taper_factors`), so that they
    blur instead of ringing: a convolution in ``phi_d`` with a non-negative kernel at every
    ``phi_s``. A long tail from a kink of the smooth factor (critical angle) is cut at ``md``
    without taper: tapering would blur the whole lobe by ~(d / md)^2 to remove a ringing of the
    tail's size."""
    mag = np.abs(F)
    big = mag.max(axis=(1, 2), keepdims=True)
    small = mag < relerr * np.maximum(big, 1e-300)
    F = np.where(small, 0.0, F)
    above = ~small.all(axis=2)                                       # (P, K)
    length = F.shape[1] - np.argmax(above[:, ::-1], axis=1)
    length[~above.any(axis=1)] = 0
    stats.orders_needed = max(stats.orders_needed, int(length.max(initial=0)))
    stats.truncated += int(np.count_nonzero(length > md))
    cut = peak_len > md
    F = F[:, :md].copy()
    if cut.any():
        F[cut] *= fourier.taper_factors(md)[None, :F.shape[1], None]
    return F


def _project_block(grid: Grid, name: str, md: int, ms: int, eta: complex, au: float, av: float,
                   dist: str, stats: AnisoProjectionStats, triangle: bool = False,
                   relerr: float = RELERR, convert=None, out=None, film=None,
                   shadowing="separable"):
    """Project the pairs of block ``name`` (one triangle of them with ``triangle``).

    Returns
    -------
    list or Spool
        Chunks ``(o, i, F)``: node indices (P,) and ``F[p, d, ms + s] = f_{d,s}`` (P, md,
        2 ms + 1), or ``convert(o, i, F)`` of each chunk, applied as soon as the chunk is
        projected (the dense chunks of a block take several times the memory of its sparse
        entries), appended to ``out`` (a new list by default; a
        :class:`~layersim.outofcore.spool.Spool` keeps them in a file, where the entries of a
        large block do not compete with the projection's temporaries). Batches are projected
        ``layersim.config.settings().threads`` at a time, so that only those batches' dense
        temporaries are alive at once.
    """
    threads = settings().threads
    mu_i, mu_o, o, i = block_pairs(grid, name, triangle)
    stats.pairs += mu_i.size
    fw = grid.flux_weight
    qs = _qs_for(ms)
    chunks = [] if out is None else out
    todo = np.arange(mu_i.size)
    first = True
    while todo.size:
        theta0, q0, qpi, bound = _coarse(mu_i[todo], mu_o[todo], eta, au, av, dist, qs, film,
                                         shadowing)
        if first:
            energy = bound * 2.0 * np.pi * np.maximum(fw[i[todo]], fw[o[todo]])
            keep = energy > ENERGY_DROP
            todo, theta0, q0, qpi = todo[keep], theta0[keep], q0[keep], qpi[keep]
            stats.projected += todo.size
            first = False
        if not todo.size:
            break
        theta_c, width = _supports(theta0, q0, qpi, dist)
        # batch sizes follow the FFT length, which follows the full series (not ``relerr``)
        kest = fourier.peak_length(q0.max(axis=1), qpi.max(axis=1), dist, RELERR)
        order = np.argsort(kest, kind="stable")
        redo = []
        ns = q0.shape[1]
        batches = []
        start = 0
        while start < order.size:
            # largest batch (sorted by series length) whose temporaries fit BATCH_ELEMENTS
            n = order.size - start
            # (the FFT length is ~4x the series length: full length at 1e-16, power of 2)
            while n > 1 and (ns + L_FIT) * n * 4 * (kest[order[start + n - 1]] + L_FIT) \
                    > BATCH_ELEMENTS:
                n = max(1, n // 2)
            batches.append(order[start:start + n])
            start += n

        def work(sel, qs=qs):
            geo = (theta0[sel], q0[sel], qpi[sel], theta_c[sel], width[sel])
            return _project_pairs(mu_i[todo[sel]], mu_o[todo[sel]], eta, au, av, dist, ms, md,
                                  qs, geo, relerr, film, shadowing)

        # groups of `threads` batches on the pool (numpy and Warp release the GIL)
        for sel, (F, alias, dropped, tot, plen, nrefit) in (
                (sel, res) for g in range(0, len(batches), threads)
                for sel, res in zip(batches[g:g + threads],
                                    parallel_map(work, batches[g:g + threads]))):
            stats.refit += nrefit
            ok = ~alias if qs < QS_MAX else np.ones(sel.size, bool)
            if (~ok).any():
                redo.append(todo[sel[~ok]])
            if ok.any():
                pp = todo[sel[ok]]
                stats.qs_max = max(stats.qs_max, qs)
                stats.s_dropped = max(stats.s_dropped, float(dropped[ok].max()))
                # cosine-weighted L2 norm of the BSDF (Parseval over both azimuths)
                w = fw[i[pp]] * fw[o[pp]]
                stats._num += float(np.sum(w * dropped[ok] ** 2 * tot[ok]))
                stats._den += float(np.sum(w * tot[ok]))
                Fk = _truncate(F[ok], md, stats, plen[ok], relerr)
                chunks.append((o[pp], i[pp], Fk) if convert is None else
                              convert(o[pp], i[pp], Fk))
                del Fk
            del F
        todo = np.concatenate(redo) if redo else np.zeros(0, np.int64)
        qs *= 2
    if stats._den:
        stats.s_dropped_energy = math.sqrt(stats._num / stats._den)
    return chunks


def _entries(grid: Grid, md: int, ms: int, o, i, F):
    """Real slot-basis entries ``(rows, cols, values)`` (32-bit indices, duplicates to be
    summed) of one chunk ``(o, i, F)`` with ``F[p, d, ms + s] = f_{d,s}`` for ``d >= 0`` (real;
    ``f_{-d,s} = f_{d,-s}``): ``B_{l,k}[o, i] = 2 pi f_{d,s} w_i mu_i`` with ``l = d + s``,
    ``k = d - s``."""
    h = grid.h
    fw = grid.flux_weight
    s = np.arange(-ms, ms + 1)
    rows, cols, vals = [], [], []
    K = F.shape[1]
    for sign in (1, -1):
        if sign > 0:
            d, G = np.arange(K), F
        else:
            d, G = -np.arange(1, K), F[:, 1:, ::-1]      # f_{-d,s} = f_{d,-s}
        l = d[:, None] + s[None, :]
        k = d[:, None] - s[None, :]
        ok = (np.abs(l) < md) & (np.abs(k) < md) & ((l > 0) | ((l == 0) & (k >= 0)))
        dd, ss = np.nonzero(ok)
        if not dd.size:
            continue
        vp = G[:, dd, ss]                                   # (P, E)
        pp, ee = np.nonzero(vp)
        if not pp.size:
            continue
        b = vp[pp, ee] * (2.0 * np.pi) * fw[i[pp]]
        del vp
        rs, cs, v, src = basis.real_entries_real(l[dd[ee], ss[ee]], k[dd[ee], ss[ee]], b)
        nz = v != 0.0
        rows.append((rs[nz] * h + o[pp[src[nz]]]).astype(np.int32))
        cols.append((cs[nz] * h + i[pp[src[nz]]]).astype(np.int32))
        vals.append(v[nz])
    if not rows:
        return np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros(0)
    return np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)


def aniso_interface_operator(grid: Grid, md: int, ms: int, layer, eta_above: float,
                             stats: AnisoProjectionStats | None = None,
                             reciprocity: bool = True, relerr: float = RELERR,
                             workspace: Workspace | None = None,
                             projector=None, only: tuple | None = None) -> AnisoOperator:
    """Operator of an anisotropic (or rotated) rough interface in the slot basis.

    Parameters
    ----------
    grid : Grid
    md : int
        Fourier orders (modes ``-(md-1)..md-1``).
    ms : int
        Coupling half-width kept (``|s| <= ms``).
    layer : Dielectric or Conductor
        Validated scene layer with ``alpha_u, alpha_v > 0``; ``layer.rotation`` (radians) turns
        its tangent frame about the normal.
    eta_above : float
        Absolute index of the medium above the interface.
    stats : AnisoProjectionStats, optional
    reciprocity : bool
        Project one triangle of the reflection blocks and ``Ttb`` only, deriving the rest by
        reciprocity (``False`` projects every block, for tests).
    relerr : float
        Coefficients below ``relerr`` times the largest of their ordinate pair are dropped
        (default: the isotropic projection's ``RELERR``; :func:`layersim.solve` passes the
        plan's :data:`layersim.aniso.plan.COUPLED_RELERR`). Truncation is per pair, and mirrored
        blocks reuse the projected pairs, so reciprocity stays exact at any ``relerr``.
    workspace : Workspace, optional
        Where the projected parts wait, and, if it is on disk, where each block is parked as
        soon as it is built (:mod:`layersim.outofcore.parking`, its slot-0 rows kept for the
        energy check), for a caller that hands the operator to an adding step that consumes
        it: the blocks of a coating wait on disk while the others are projected. Default: in
        memory, nothing parked.
    projector : callable, optional
        Projects the blocks instead of the analytic path: ``projector(grid, name, md, ms,
        triangle, stats, relerr, out)`` appends the real entries ``(rows, cols, values)`` of
        block ``name`` to ``out`` (a tabulated NDF:
        :func:`layersim.ingredients.tabulated.projector`).
    only : tuple of str, optional
        The blocks to project (default: all); the others are left empty (zero), for a caller
        that takes them from elsewhere (a brushed coat: :mod:`layersim.layers.brushed`).
        ``Tbt`` is the reciprocal image of ``Ttb``: the two are projected together or not at
        all.
    """
    if layer.smooth:
        raise ValueError("aniso_interface_operator needs a rough interface")
    if only is not None and ("Ttb" in only) != ("Tbt" in only):
        raise ValueError(f"only={only!r}: Tbt is the reciprocal image of Ttb; project both or "
                         "neither")
    stats = stats if stats is not None else AnisoProjectionStats()
    t0 = time.perf_counter()
    eta = complex(layer.ior) / eta_above
    au, av, dist = layer.alpha_u, layer.alpha_v, layer.distribution
    film, shadowing = layer.film_params(eta_above), layer.shadowing
    opaque = layer.opaque
    names = ("Rt",) if opaque else ("Rt", "Rb", "Ttb", "Tbt")
    N = basis.n_slots(md) * grid.h
    col_scale = slot_column_scale(grid, md)
    workspace = workspace or Workspace()

    def project(name, triangle=False):
        """The block's matrix from its (triangle of) pairs, assembled batch by batch."""
        if projector is not None:
            return from_parts(projector(grid, name, md, ms, triangle, stats, relerr,
                                        workspace.spool()), (N, N))
        parts = _project_block(grid, name, md, ms, eta, au, av, dist, stats, triangle=triangle,
                               relerr=relerr, convert=lambda o, i, F: _entries(grid, md, ms,
                                                                               o, i, F),
                               out=workspace.spool(), film=film, shadowing=shadowing)
        return from_parts(parts, (N, N))

    def done(*names):
        """Blocks complete (no other derives from them): rotated and parked if asked."""
        if not workspace.on_disk:
            return
        for name in names:
            blocks[name] = workspace.park(rotate_block(blocks[name], md, grid.h,
                                                       layer.rotation), head=grid.h)
        workspace.release()

    blocks = {}
    for name in names:
        if only is not None and name not in only:
            blocks[name] = sps.csr_matrix((N, N))
            done(name)
        elif not reciprocity or name == "Ttb":
            blocks[name] = project(name)
            if not (reciprocity and name == "Ttb"):     # else done with its image
                done(name)
        elif name == "Tbt":     # generalized reciprocity: Tbt = D Ttb^T D^-1 / eta^2
            blocks[name] = reciprocal_image(blocks["Ttb"], grid.h, col_scale,
                                            1.0 / eta.real ** 2)
            done("Ttb", "Tbt")
        else:                   # one triangle of pairs and its reciprocal image
            blocks[name] = with_reciprocal_image(project(name, triangle=True), grid.h,
                                                 col_scale, 1.0, 1.0, skip_diagonal=True,
                                                 directory=workspace.directory
                                                 ).to_csr(release=True)
            done(name)
        workspace.release()
    op = AnisoOperator(grid, md, blocks, eta_top=eta_above,
                       eta_bottom=None if opaque else layer.ior.real, ms=ms)
    if not workspace.on_disk:
        op = op.rotated(layer.rotation)
    stats.seconds += time.perf_counter() - t0
    return op
