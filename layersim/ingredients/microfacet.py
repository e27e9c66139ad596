"""Rough dielectric and conductor interfaces: semi-analytic Fourier projection (isotropic).

For every ordinate pair (mu_i, mu_o) of every block, the BSDF is split by the kernels into
``f(phi) = S(phi) * peak(q(phi))`` (see :mod:`layersim.kernels.physics`); the cosine series of
the peak factor is exact (:func:`layersim.operators.fourier.peak_series`), the smooth factor ``S``
is fitted with a short cosine series on the support of the peak
(:func:`layersim.operators.fourier.fit_restricted`), and the two are multiplied in coefficient space
(Jakob's layerlab tutorial sec. 5.2; Zeltner & Jakob 2018 sec. 4.1; Jakob et al. 2014). Pairs are
processed in batches grouped by series length, so the work is proportional to the number of
coefficients kept.

Accuracy (``tests/test_projection.py``, against composite Gauss-Legendre quadrature graded around
the peak, including every grazing pair of a 64-ordinate grid): away from total internal
reflection, each pair's energy (zeroth order) is right to < 1e-6 of a beam's energy and every
coefficient to < 1e-4 of f_0 (median 1e-7 .. 1e-15). For light inside the dense medium, the
Fresnel factor has a square-root kink at the critical angle inside the lobe, which the smooth fit
only approximates: up to 1e-2 of f_0 for a few pairs, 1.3e-4 of a beam's energy.

The number of fitted terms follows the width of the support (:func:`fit_terms`): the cosine
basis on a narrow interval is ill-conditioned, and grazing lobes are a few hundredths of a radian
wide.
"""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ..operators import fourier
from ..config import settings
from ..kernels import projection as kproj
from ..kernels.runtime import device_for
from ..operators.operator import Grid, IsoOperator
from ..threads import parallel_map

#: Relative truncation of each pair's cosine series (|f_l| < RELERR |f_0| are dropped).
RELERR = 1e-7
#: A series cut at m orders is tapered (Jackson kernel factors, :func:`fourier.taper_factors`)
#: only if the lobe still has coefficients above this fraction of f_0 at order m: smaller tails
#: ring far less than the taper would blur every order (it changes order l by
#: ~(pi l / m)^2 / 2). The decision uses
#: the analytically known length of the pair's peak series (:func:`fourier.peak_length`), not
#: the computed tail, so that numerical noise in the tail cannot trigger it and both projection
#: paths taper the same pairs.
TAPER_THRESHOLD = 1e-4
#: The smooth factor is fitted where the peak factor exceeds this fraction of its maximum.
SUPPORT_TOLERANCE = 1e-14
#: Pairs whose BSDF bound carries less than this fraction of a beam's energy are skipped.
ENERGY_DROP = 1e-14
#: Cosine orders of a pair's series per radian of a thin film's phase scale, where the lobe
#: is wide (:func:`film_orders`).
FILM_ORDERS_PER_RADIAN = 1.5
#: Cosine terms and samples of the smooth-factor fit; larger refit for kinked pairs.
L_FIT, Q_IN, Q_OUT = 16, 40, 12
L_HARD, Q_IN_HARD, Q_OUT_HARD = 48, 192, 32
FIT_RESIDUAL = 1e-4
#: Refits with L_HARD terms only on supports at least this wide (radians): on narrower ones the
#: cosine basis is too ill-conditioned for that many terms.
REFIT_MIN_SUPPORT = 1.0


def fit_terms(phi_max: np.ndarray, limit: int) -> np.ndarray:
    """Number of cosine terms for the smooth-factor fit on [0, phi_max].

    {cos(j phi)}_{j < L} restricted to [0, phi_max] behaves like polynomials of degree L - 1 in
    cos(phi) on an interval of length ~phi_max^2 / 2: its condition number grows like
    (2 pi / phi_max)^(2 (L - 1)). Narrow supports (grazing or very smooth lobes, where the smooth
    factor is also nearly constant) get few terms, keeping it below ~1e16.
    """
    ratio = np.log10(2.0 * np.pi / np.maximum(phi_max, 1e-12))
    return np.clip(1 + np.floor(8.0 / np.maximum(ratio, 1e-12)), 3, limit).astype(int)
#: Coarse azimuths used to bound the smooth factor before projecting a pair.
N_COARSE = 17
#: Pairs per batch (bounds the temporary memory of the fit: ~Q*L*8 bytes per pair; small
#: enough that a block gives the thread pool several batches).
BATCH = 1024
#: Azimuths (on [0, pi]) at which the plan's pre-pass (:func:`series_lengths`) samples each pair.
N_PREPASS = 9


@dataclass
class ProjectionStats:
    """What the projection did, for the plan report."""

    pairs: int = 0
    projected: int = 0
    refit: int = 0
    truncated: int = 0
    """Pairs whose series needed more than ``m`` orders (truncated and tapered)."""
    aliased: int = 0
    """Pairs whose series the numeric path could not sample without aliasing (projected
    semi-analytically instead)."""
    tapered: int = 0
    """Truncated pairs whose discarded tail was large enough to taper."""
    orders_needed: int = 0
    seconds: float = 0.0
    series_seconds: float = 0.0
    """Time spent computing series of pairs (the ``method`` calls, summed over threads); the
    rest of ``seconds`` is pair selection, mirroring and assembly, shared by both paths."""
    notes: list = field(default_factory=list)

    def merge(self, other: "ProjectionStats") -> None:
        self.notes.extend(other.notes)
        self.pairs += other.pairs
        self.projected += other.projected
        self.refit += other.refit
        self.truncated += other.truncated
        self.aliased += other.aliased
        self.tapered += other.tapered
        self.orders_needed = max(self.orders_needed, other.orders_needed)
        self.seconds += other.seconds
        self.series_seconds += other.series_seconds


def block_pairs(grid: Grid, name: str, triangle: bool):
    """Signed (mu_i, mu_o) of the pairs of a block and their node indices (o, i); with
    ``triangle`` only pairs with ``o <= i`` (reflection blocks are symmetric)."""
    h = grid.h
    if triangle:
        o, i = np.triu_indices(h)
    else:
        o, i = np.meshgrid(np.arange(h), np.arange(h), indexing="ij")
        o, i = o.ravel(), i.ravel()
    mu = grid.mu
    sign_i = 1.0 if name in ("Rt", "Ttb") else -1.0
    sign_o = 1.0 if name in ("Rb", "Ttb") else -1.0
    return sign_i * mu[i], sign_o * mu[o], o, i


def significant_pairs(grid: Grid, name: str, triangle: bool, eta: complex, alpha: float,
                      dist: str, device=None, film=None, shadowing="separable"):
    """The pairs of a block (see :func:`block_pairs`) and which of them can carry more than
    :data:`ENERGY_DROP` of a beam's energy, from a coarse bound on the device (``film``: the
    interface's, :func:`interface_setup`).

    Returns
    -------
    mu_i, mu_o, o, i : ndarray (P,)
    q0, qpi : ndarray (P,)
        Slope-space form of the peak at azimuth 0 and pi (they set each pair's series length).
    keep : int ndarray
        Indices of the significant pairs.
    """
    mu_i, mu_o, o, i = block_pairs(grid, name, triangle)
    fw = grid.flux_weight
    smax, q0, qpi = kproj.coarse_bound(mu_i, mu_o, eta, alpha, alpha, dist, N_COARSE,
                                       device=device, film=film, shadowing=shadowing)
    # Bound on f over phi: peak <= peak(q0); S bounded by its coarse maximum (x10 margin).
    bound = 10.0 * fourier.peak_values(q0, dist) * smax
    energy = bound * 2.0 * np.pi * np.maximum(fw[i], fw[o])
    return mu_i, mu_o, o, i, q0, qpi, np.flatnonzero(energy > ENERGY_DROP)


def series_lengths(grid: Grid, layer, eta_above: float, relerr: float = RELERR,
                   blocks: tuple | None = None):
    """Pre-pass of the projection for the plan: how many cosine orders each significant pair
    of an isotropic interface needs, from one cheap kernel launch per block.

    The peak factor's series length is known analytically (:func:`fourier.peak_length`); the
    smooth factor adds up to :data:`L_FIT` orders. Pairs whose bound (from
    :data:`N_PREPASS` azimuths) carries less than :data:`ENERGY_DROP` of a beam's energy are
    left out, as the projection leaves them out.

    Parameters
    ----------
    grid : Grid
    layer : Dielectric or Conductor
        Validated isotropic rough interface.
    eta_above : float
        Absolute index of the medium above the interface.
    relerr : float
        Relative truncation of the series (the projection's :data:`RELERR`).
    blocks : tuple of str, optional
        Only these of the interface's blocks (as :func:`interface_operator` projects them).

    Returns
    -------
    lengths : int ndarray (P,)
        Orders each significant pair of the interface's blocks needs.
    mu_min : ndarray (P,)
        ``min(|mu_i|, |mu_o|)`` of each of those pairs (the elevation closer to the horizon,
        which sets how wide the lobe is in azimuth).
    """
    eta = complex(layer.ior) / eta_above
    film, shadowing = layer.film_params(eta_above), layer.shadowing
    names = ("Rt",) if layer.opaque else ("Rt", "Rb", "Ttb", "Tbt")
    names = names if blocks is None else tuple(n for n in names if n in blocks)
    dist = layer.distribution
    fw = grid.flux_weight
    lengths, mu_min = [], []
    for name in names:
        mu_i, mu_o, o, i = block_pairs(grid, name, triangle=False)
        phi = np.broadcast_to(np.linspace(0.0, np.pi, N_PREPASS), (mu_i.size, N_PREPASS))
        s, q = kproj.microfacet_split(mu_i, mu_o, phi, eta, layer.alpha, layer.alpha, dist,
                                      film=film, shadowing=shadowing)
        q0, qpi = q[:, 0], q[:, -1]
        bound = 10.0 * fourier.peak_values(q0, dist) * np.abs(s).max(axis=1)
        sig = bound * 2.0 * np.pi * np.maximum(fw[i], fw[o]) > ENERGY_DROP
        lengths.append(fourier.peak_length(q0[sig], qpi[sig], dist, relerr) + L_FIT
                       + film_orders(film, layer.alpha))
        mu_min.append(np.minimum(np.abs(mu_i[sig]), np.abs(mu_o[sig])))
    return np.concatenate(lengths), np.concatenate(mu_min)


def _project_block(grid: Grid, name: str, m: int, eta: complex, alpha: float, dist: str,
                   stats: ProjectionStats, triangle: bool = False, method=None,
                   batch: int = BATCH, device=None, film=None, shadowing="separable"):
    """Project the significant pairs of one block, in batches of similar series length.

    ``method(mu_i, mu_o, o, i, q0, qpi, K, m, eta, alpha, dist, stats, film=film,
    shadowing=shadowing) -> (o, i, series)`` computes the series of a batch (default: the
    semi-analytic :func:`pair_series`) of at most ``batch`` pairs; ``device`` runs the coarse
    sampling that bounds each pair's energy; ``film`` and ``shadowing`` are the interface's
    (:func:`interface_setup`).
    """
    method = method or project_pairs
    mu_i, mu_o, o, i, q0, qpi, keep = significant_pairs(grid, name, triangle, eta, alpha, dist,
                                                        device, film, shadowing)
    stats.pairs += mu_i.size
    chunks = []
    if keep.size == 0:
        return chunks
    kest = fourier.peak_length(q0[keep], qpi[keep], dist, RELERR)
    order = keep[np.argsort(kest, kind="stable")]
    kest = np.sort(kest)
    # batches run on a thread pool (layersim.threads), each with its own statistics
    def work(start):
        part = ProjectionStats()
        sel = order[start:start + batch]
        K = int(min(kest[start:start + batch].max(), m + L_HARD))
        t0 = time.perf_counter()
        out = method(mu_i[sel], mu_o[sel], o[sel], i[sel], q0[sel], qpi[sel], K, m,
                     eta, alpha, dist, part, film=film, shadowing=shadowing)
        part.series_seconds += time.perf_counter() - t0
        return out, part

    starts = range(0, order.size, batch)
    # one launch already fills a GPU: batches for it run in the calling thread
    results = [work(x) for x in starts] if on_gpu(device) else parallel_map(work, starts)
    for chunk, part in results:
        chunks.append(chunk)
        stats.merge(part)
    stats.projected += keep.size
    return chunks


def on_gpu(device) -> bool:
    """Whether ``device`` (a Warp device name or None for the configured one) is a GPU."""
    return device_for(device).is_cuda


def _mirror(chunks, scale: float = 1.0, skip_diagonal: bool = True):
    """Chunks of the transposed block (``f(o <- i) -> f(i <- o)``), times ``scale``. The
    coefficients are shared, not copied, where no row is left out and ``scale`` is 1 (the
    assembly only reads them)."""
    out = []
    for o, i, c in chunks:
        if skip_diagonal and (o == i).any():
            sel = o != i
            o, i, c = o[sel], i[sel], c[sel]
        out.append((i, o, c if scale == 1.0 else c * scale))
    return out


def _prefactor_poly(q0, qpi, alpha):
    """Cosine coefficients of ``(1 + alpha^2 q(phi))^2`` = ``|h|^4 / hz^4`` (isotropic), a
    degree-2 cosine polynomial since ``q = c - d cos(phi)``."""
    c, d = 0.5 * (q0 + qpi), 0.5 * (qpi - q0)
    u, v = 1.0 + alpha * alpha * c, alpha * alpha * d
    return np.stack([u * u + 0.5 * v * v, -2.0 * u * v, 0.5 * v * v], axis=1)


def _fit(mu_i, mu_o, q0, qpi, eta, alpha, dist, L, q_in, q_out, precondition, film=None,
         shadowing="separable"):
    """Fit the smooth factor of each pair with at most ``L`` cosine terms (fewer on narrow
    supports, see :func:`fit_terms`). Returns coefficients (P, L) (zero-padded) and the
    relative weighted residuals (P,)."""
    if precondition:
        phi_max = np.full(q0.shape, np.pi)
    else:
        phi_max = fourier.peak_support(q0, qpi, dist, SUPPORT_TOLERANCE)
    phi, w = fourier.fit_nodes(phi_max, q_in, q_out)
    s, q = kproj.microfacet_split(mu_i, mu_o, phi, eta, alpha, alpha, dist, film=film,
                                  shadowing=shadowing)
    weight = fourier.peak_values(q, dist)
    if precondition:
        factor = (1.0 + alpha * alpha * q) ** 2
        s = s / factor
        weight = weight * factor
    with np.errstate(under="ignore", invalid="ignore"):
        rel = weight / np.max(weight[:, :q_in], axis=1, keepdims=True)
    rel = np.nan_to_num(np.clip(rel, 0.0, 1.0))
    terms = fit_terms(phi_max, L)
    coef = np.zeros((q0.size, L))
    resid = np.zeros(q0.size)
    for t in np.unique(terms):
        rows = np.flatnonzero(terms == t)
        coef[rows, :t], resid[rows] = fourier.fit_restricted(phi[rows], w[rows], s[rows],
                                                             rel[rows], q_in, int(t))
    return coef, resid, phi_max


def pair_series(mu_i, mu_o, eta: complex, alpha: float, dist: str, m: int, q0=None, qpi=None,
                K: int | None = None, taper: bool = True, stats: ProjectionStats | None = None,
                film=None, shadowing="separable"):
    """Cosine series ``f_0 .. f_{m-1}`` (1/sr) of the BSDF of an isotropic interface for
    ordinate pairs.

    Parameters
    ----------
    mu_i, mu_o : ndarray (P,)
        Signed ordinates (solver convention, :mod:`layersim.kernels.projection`).
    eta : complex
        Relative index below/above; ``alpha`` roughness; ``dist`` 'beckmann' or 'ggx'.
    m : int
        Orders to return.
    q0, qpi : ndarray (P,), optional
        Slope form at phi = 0 and pi, if already known.
    K : int, optional
        Peak-series orders to use (default: enough for every pair, at most ``m + L_HARD``).
    taper : bool
        Apply the Jackson kernel factors (:func:`layersim.operators.fourier.taper_factors`) to pairs
        whose series needs more than ``m`` orders (:func:`needs_taper`).
    film : (float, float), optional
        The interface's thin film (relative index, phase scale; :func:`interface_setup`).
    shadowing : str
        The Smith shadowing term, "separable" or "height-correlated" (:func:`interface_setup`).

    Returns
    -------
    series : ndarray (P, m)
    length : ndarray (P,)
        Orders each pair needs (above ``RELERR`` times its zeroth coefficient).
    """
    stats = stats if stats is not None else ProjectionStats()
    mu_i, mu_o = np.asarray(mu_i, float), np.asarray(mu_o, float)
    if q0 is None:
        _, q = kproj.microfacet_split(mu_i, mu_o, np.tile([0.0, np.pi], (mu_i.size, 1)), eta,
                                      alpha, alpha, dist, film=film, shadowing=shadowing)
        q0, qpi = q[:, 0], q[:, 1]
    if K is None:
        K = int(min(fourier.peak_length(q0, qpi, dist, RELERR).max(initial=1), m + L_HARD))
    # GGX reflection: the prefactor |h|^4/hz^4 = (1 + alpha^2 q)^2 grows like q^2 in the tails
    # (D -> alpha^2 / (pi sin^4)), so it is moved from the fitted smooth factor into the exact
    # series. (For Beckmann the exponential tail makes this unnecessary, and the polynomial's
    # large coefficients at grazing angles would only add cancellation.)
    precondition = dist == "ggx" and mu_i[0] * mu_o[0] < 0
    coef, resid, phi_max = _fit(mu_i, mu_o, q0, qpi, eta, alpha, dist, L_FIT, Q_IN, Q_OUT,
                                precondition, film, shadowing)
    peak = fourier.peak_series(q0, qpi, dist, max(K, 1))
    if precondition:
        peak = fourier.cos_product(peak, _prefactor_poly(q0, qpi, alpha))
    series = np.zeros((q0.size, peak.shape[1] + L_HARD - 1))
    base = fourier.cos_product(peak, coef)
    series[:, :base.shape[1]] = base
    hard = np.flatnonzero((resid > FIT_RESIDUAL) & (phi_max >= REFIT_MIN_SUPPORT))
    if hard.size:
        coef_h, resid_h, _ = _fit(mu_i[hard], mu_o[hard], q0[hard], qpi[hard], eta, alpha,
                                  dist, L_HARD, Q_IN_HARD, Q_OUT_HARD, precondition, film,
                                      shadowing)
        better = resid_h < resid[hard]
        rows = hard[better]
        series[rows] = fourier.cos_product(peak[rows], coef_h[better])
        stats.refit += int(better.sum())
    # per-pair length: last coefficient above RELERR * |f_0|
    mag = np.abs(series)
    above = mag >= RELERR * np.maximum(mag[:, :1], 1e-300)
    length = series.shape[1] - np.argmax(above[:, ::-1], axis=1)
    length[~above.any(axis=1)] = 0
    stats.orders_needed = max(stats.orders_needed, int(length.max(initial=0)))
    cut = length > m
    stats.truncated += int(np.count_nonzero(cut))
    out = np.zeros((series.shape[0], m))
    keep = min(m, series.shape[1])
    out[:, :keep] = series[:, :keep]
    out[np.arange(m)[None, :] >= length[:, None]] = 0.0
    if taper:
        apply_taper(out, needs_taper(q0, qpi, dist, m), stats)
    return out, length


def needs_taper(q0, qpi, dist: str, m: int) -> np.ndarray:
    """Pairs whose lobe still has Fourier coefficients above :data:`TAPER_THRESHOLD` of f_0 at
    order ``m`` (from the peak series' analytic length plus the smooth factor's few orders)."""
    return fourier.peak_length(q0, qpi, dist, TAPER_THRESHOLD) + L_FIT > m


def apply_taper(series: np.ndarray, rows: np.ndarray, stats: ProjectionStats) -> None:
    """Jackson kernel factors (:func:`layersim.operators.fourier.taper_factors`, in place) on the
    selected rows: blur instead of Gibbs ringing, and a lobe that is non-negative stays so.
    Order 0, hence energy, is unchanged."""
    m = series.shape[1]
    if rows.any():
        series[rows] *= fourier.taper_factors(m)[None, :]
        stats.tapered += int(np.count_nonzero(rows))


def project_pairs(mu_i, mu_o, o, i, q0, qpi, K, m, eta, alpha, dist, stats, film=None,
                  shadowing="separable"):
    """The default ``method`` of :func:`interface_operator`: :func:`pair_series` of a batch,
    returned as a chunk ``(o, i, series)``."""
    series, _ = pair_series(mu_i, mu_o, eta, alpha, dist, m, q0, qpi, K, stats=stats,
                            film=film, shadowing=shadowing)
    return o, i, series


def interface_setup(layer, eta_above: float):
    """What every isotropic interface projection needs: relative index ``eta`` (complex),
    distribution, roughness, whether it is opaque, the blocks it has, its thin film
    (relative index and phase scale, :meth:`layersim.layers.Interface.film_params`, or
    None) and its Smith shadowing term (:func:`layersim.kernels.physics.smith_g2`)."""
    if layer.anisotropic or layer.smooth:
        raise ValueError("interface_operator projects isotropic rough interfaces only")
    opaque = layer.opaque
    names = ("Rt",) if opaque else ("Rt", "Rb", "Ttb", "Tbt")
    return (complex(layer.ior) / eta_above, layer.distribution, layer.alpha, opaque, names,
            layer.film_params(eta_above), layer.shadowing)


def film_orders(film, alpha: float) -> int:
    """Cosine orders a thin film adds to the series of a pair's smooth factor (0 without a
    film): its Airy reflectance oscillates with the round-trip phase ``phase_scale
    cos(theta_film)``, of which the microfacet normals under a lobe of roughness ``alpha``
    sweep a fraction that grows with ``alpha``: :data:`FILM_ORDERS_PER_RADIAN` orders per
    radian of ``phase_scale min(1, 3 alpha)``. Set from the numeric projection of filmed
    Beckmann interfaces (gold and glass, ``alpha`` 0.1 to 0.8, phase scale 50 to 600, 48
    ordinates) against 8192 azimuth samples per pair: every coefficient of the conductors
    within 1e-8 of its pair's ``f_0``, the dielectrics no further off than the bare ones
    (up to 7e-6 in grazing transmission pairs); and every conductor pair within 80 degrees of
    the normal keeps the orders it needs above :data:`RELERR` in the plan's pre-pass."""
    if film is None:
        return 0
    return int(math.ceil(FILM_ORDERS_PER_RADIAN * film[1] * min(1.0, 3.0 * alpha)))


def interface_operator(grid: Grid, m: int, layer, eta_above: float,
                       stats: ProjectionStats | None = None,
                       reciprocity: bool = True, method=None, batch: int = BATCH,
                       device=None, blocks: tuple | None = None) -> IsoOperator:
    """Operator of an isotropic rough interface.

    Parameters
    ----------
    grid : Grid
    m : int
        Fourier orders to keep.
    layer : Dielectric or Conductor
        Validated scene layer with ``alpha_u == alpha_v > 0``.
    eta_above : float
        Absolute index of the medium above the interface.
    stats : ProjectionStats, optional
        Accumulates what the projection did (pairs, refits, truncated series).
    reciprocity : bool
        Project one triangle of each reflection block and ``Ttb`` only, deriving the rest by
        reciprocity (half the work). ``False`` projects every block independently (used by the
        tests to check the physics and the projection against reciprocity).
    method : callable, optional
        Series of a batch of pairs (default semi-analytic; see
        :mod:`layersim.ingredients.numeric` for the sampled/FFT path).
    batch : int
        Pairs per call of ``method``.
    device : str, optional
        Warp device of the coarse sampling; a CUDA device also makes the blocks run one after
        the other (each launch already fills the GPU).
    blocks : tuple of str, optional
        Project only these blocks (``("Rt",)``: the reflection from above of an inner
        interface, :mod:`layersim.layers.near_specular_inner`); the others are left out
        (None). With ``reciprocity``, ``Tbt`` needs ``Ttb``, from which it is derived.
    """
    stats = stats if stats is not None else ProjectionStats()
    t0 = time.perf_counter()
    eta, dist, alpha, opaque, names, film, shadowing = interface_setup(layer, eta_above)
    left_out = () if blocks is None else tuple(n for n in names if n not in blocks)
    if reciprocity and "Ttb" in left_out and "Tbt" in names and "Tbt" not in left_out:
        raise ValueError("interface_operator derives Tbt from Ttb: blocks must name both")
    names = tuple(n for n in names if n not in left_out)
    series = {}
    # Blocks are independent: project them concurrently (Warp CPU launches, FFTs and LAPACK
    # release the GIL), one worker per thread of layersim.config (threads) up to the number of
    # blocks.
    def project(name, triangle):
        own = ProjectionStats()       # one per block: no counters shared between threads
        chunks = _project_block(grid, name, m, eta, alpha, dist, own, triangle=triangle,
                                method=method, batch=batch, device=device, film=film,
                                    shadowing=shadowing)
        return chunks, own

    if reciprocity:
        # Reflection blocks are symmetric, and Tbt[a, b] = Ttb[b, a] / eta^2 (generalized
        # reciprocity f(wi, wo) / eta_o^2 = f(wo, wi) / eta_i^2, radiance convention).
        jobs = {name: (name, name != "Ttb") for name in names if name != "Tbt"}
    else:
        jobs = {name: (name, False) for name in names}
    workers = 1 if on_gpu(device) else min(len(jobs), settings().threads)
    if workers > 1:
        with ThreadPoolExecutor(workers) as pool:
            done = dict(zip(jobs, pool.map(lambda job: project(*job), jobs.values())))
    else:
        done = {name: project(*job) for name, job in jobs.items()}
    for name in done:
        done[name], own = done[name]
        stats.merge(own)
    for name in names:
        if name not in done:
            series[name] = _mirror(done["Ttb"], 1.0 / eta.real ** 2, skip_diagonal=False)
        elif reciprocity and name != "Ttb":
            series[name] = done[name] + _mirror(done[name])
        else:
            series[name] = done[name]
    if opaque:
        series.update({"Rb": None, "Ttb": None, "Tbt": None})
    series.update({name: None for name in left_out})
    stats.seconds += time.perf_counter() - t0
    return IsoOperator.from_series(grid, m, series, eta_top=eta_above,
                                   eta_bottom=None if opaque else layer.ior.real)
