"""Rough dielectric and conductor interfaces: semi-analytic Fourier projection (isotropic).

For every ordinate pair (mu_i, mu_o) of every block, the BSDF is split by the kernels into
``f(phi) = S(phi) * peak(q(phi))`` (see :mod:`layersim.kernels.physics`); the cosine series of
the peak factor is exact (:func:`layersim.fourier.peak_series`), the smooth factor ``S`` is fitted
with a short cosine series on the support of the peak (:func:`layersim.fourier.fit_restricted`),
and the two are multiplied in coefficient space (seed 004 sec. 5.2, seed 000 sec. 4.1; Jakob et
al. 2014). Pairs are processed in batches grouped by series length, so the work is
proportional to the number of coefficients kept.

Accuracy (``benchmarks/projection_accuracy.py`` against 32768-point FFTs of the BSDF): median
relative error of f_0 ~1e-14, worst ~1e-7 for smooth factors; near a Fresnel critical angle
inside the lobe (light inside the denser medium), the smooth factor has a square-root kink and
the fit is refined (``L_HARD`` terms), leaving worst-case errors of ~1e-3 at those few pairs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .. import fourier
from ..kernels import projection as kproj
from ..operator import Grid, IsoOperator
from ..scene import Conductor, Dielectric

#: Relative truncation of each pair's cosine series (|f_l| < RELERR |f_0| are dropped).
RELERR = 1e-7
#: The smooth factor is fitted where the peak factor exceeds this fraction of its maximum.
SUPPORT_TOLERANCE = 1e-14
#: Pairs whose BSDF bound carries less than this fraction of a beam's energy are skipped.
ENERGY_DROP = 1e-14
#: Cosine terms and samples of the smooth-factor fit; larger refit for kinked pairs.
L_FIT, Q_IN, Q_OUT = 16, 40, 12
L_HARD, Q_IN_HARD, Q_OUT_HARD = 48, 192, 32
FIT_RESIDUAL = 1e-4
#: Coarse azimuths used to bound the smooth factor before projecting a pair.
N_COARSE = 17
#: Pairs per batch (bounds the temporary memory of the fit: ~Q*L*8 bytes per pair; small
#: enough that a block gives the thread pool several batches).
BATCH = 1024


@dataclass
class ProjectionStats:
    """What the projection did, for the plan report."""

    pairs: int = 0
    projected: int = 0
    refit: int = 0
    truncated: int = 0
    """Pairs whose series needed more than ``m`` orders (truncated and tapered)."""
    orders_needed: int = 0
    seconds: float = 0.0
    notes: list = field(default_factory=list)

    def merge(self, other: "ProjectionStats") -> None:
        self.pairs += other.pairs
        self.projected += other.projected
        self.refit += other.refit
        self.truncated += other.truncated
        self.orders_needed = max(self.orders_needed, other.orders_needed)
        self.seconds += other.seconds


def _block_pairs(grid: Grid, name: str, triangle: bool):
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


def _project_block(grid: Grid, name: str, m: int, eta: complex, alpha: float, dist: str,
                   stats: ProjectionStats, triangle: bool = False):
    mu_i, mu_o, o, i = _block_pairs(grid, name, triangle)
    stats.pairs += mu_i.size
    fw = grid.flux_weight
    coarse = np.broadcast_to(np.linspace(0.0, np.pi, N_COARSE), (mu_i.size, N_COARSE))
    s_c, q_c = kproj.microfacet_split(mu_i, mu_o, coarse, eta, alpha, alpha, dist)
    q0, qpi = q_c[:, 0], q_c[:, -1]
    # Bound on f over phi: peak <= peak(q0); S bounded by its coarse maximum (x10 margin).
    bound = 10.0 * fourier.peak_values(q0, dist) * np.abs(s_c).max(axis=1)
    energy = bound * 2.0 * np.pi * np.maximum(fw[i], fw[o])
    keep = np.flatnonzero(energy > ENERGY_DROP)
    chunks = []
    if keep.size == 0:
        return chunks
    kest = fourier.peak_length(q0[keep], qpi[keep], dist, RELERR)
    order = keep[np.argsort(kest, kind="stable")]
    kest = np.sort(kest)
    # batches run on a thread pool (layersim.threads), each with its own statistics
    def work(start):
        part = ProjectionStats()
        sel = order[start:start + BATCH]
        K = int(min(kest[start:start + BATCH].max(), m + L_HARD))
        return _project_pairs(mu_i[sel], mu_o[sel], o[sel], i[sel], q0[sel], qpi[sel], K, m,
                              eta, alpha, dist, part), part

    from ..threads import parallel_map
    for chunk, part in parallel_map(work, range(0, order.size, BATCH)):
        chunks.append(chunk)
        stats.merge(part)
    stats.projected += keep.size
    return chunks


def _mirror(chunks, scale: float = 1.0, skip_diagonal: bool = True):
    """Chunks of the transposed block (``f(o <- i) -> f(i <- o)``), times ``scale``."""
    out = []
    for o, i, c in chunks:
        sel = o != i if skip_diagonal else slice(None)
        out.append((i[sel], o[sel], c[sel] * scale))
    return out


def _prefactor_poly(q0, qpi, alpha):
    """Cosine coefficients of ``(1 + alpha^2 q(phi))^2`` = ``|h|^4 / hz^4`` (isotropic), a
    degree-2 cosine polynomial since ``q = c - d cos(phi)``."""
    c, d = 0.5 * (q0 + qpi), 0.5 * (qpi - q0)
    u, v = 1.0 + alpha * alpha * c, alpha * alpha * d
    return np.stack([u * u + 0.5 * v * v, -2.0 * u * v, 0.5 * v * v], axis=1)


def _fit(mu_i, mu_o, q0, qpi, eta, alpha, dist, L, q_in, q_out, precondition):
    if precondition:
        phi_max = np.full(q0.shape, np.pi)
    else:
        phi_max = fourier.peak_support(q0, qpi, dist, SUPPORT_TOLERANCE)
    phi, w = fourier.fit_nodes(phi_max, q_in, q_out)
    s, q = kproj.microfacet_split(mu_i, mu_o, phi, eta, alpha, alpha, dist)
    weight = fourier.peak_values(q, dist)
    if precondition:
        factor = (1.0 + alpha * alpha * q) ** 2
        s = s / factor
        weight = weight * factor
    with np.errstate(under="ignore", invalid="ignore"):
        rel = weight / np.max(weight[:, :q_in], axis=1, keepdims=True)
    rel = np.nan_to_num(np.clip(rel, 0.0, 1.0))
    return fourier.fit_restricted(phi, w, s, rel, q_in, L)


def _project_pairs(mu_i, mu_o, o, i, q0, qpi, K, m, eta, alpha, dist, stats):
    # GGX reflection: the prefactor |h|^4/hz^4 = (1 + alpha^2 q)^2 grows like q^2 in the tails
    # (D -> alpha^2 / (pi sin^4)), so it is moved from the fitted smooth factor into the exact
    # series. (For Beckmann the exponential tail makes this unnecessary, and the polynomial's
    # large coefficients at grazing angles would only add cancellation.)
    precondition = dist == "ggx" and mu_i[0] * mu_o[0] < 0
    coef, resid = _fit(mu_i, mu_o, q0, qpi, eta, alpha, dist, L_FIT, Q_IN, Q_OUT, precondition)
    hard = np.flatnonzero(resid > FIT_RESIDUAL)
    if hard.size:
        coef_h, _ = _fit(mu_i[hard], mu_o[hard], q0[hard], qpi[hard], eta, alpha, dist,
                         L_HARD, Q_IN_HARD, Q_OUT_HARD, precondition)
        wide = np.zeros((coef.shape[0], L_HARD))
        wide[:, :L_FIT] = coef
        wide[hard] = coef_h
        coef = wide
        stats.refit += hard.size
    peak = fourier.peak_series(q0, qpi, dist, max(K, 1))
    if precondition:
        peak = fourier.cos_product(peak, _prefactor_poly(q0, qpi, alpha))
    series = fourier.cos_product(peak, coef)
    # per-pair length: last coefficient above RELERR * |f_0|
    mag = np.abs(series)
    above = mag >= RELERR * np.maximum(mag[:, :1], 1e-300)
    length = series.shape[1] - np.argmax(above[:, ::-1], axis=1)
    length[~above.any(axis=1)] = 0
    stats.orders_needed = max(stats.orders_needed, int(length.max(initial=0)))
    cut = length > m
    stats.truncated += int(np.count_nonzero(cut))
    series = series[:, :m]
    cols = np.arange(series.shape[1])[None, :]
    series[cols >= length[:, None]] = 0.0
    if cut.any():
        # Lanczos sigma factors on series truncated at m: blur instead of Gibbs ringing
        # (order 0, hence energy, is unchanged).
        series[cut] *= np.sinc(np.arange(series.shape[1]) / m)[None, :]
    return o, i, series


def interface_operator(grid: Grid, m: int, layer, eta_above: float,
                       stats: ProjectionStats | None = None,
                       reciprocity: bool = True) -> IsoOperator:
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
    """
    if layer.anisotropic or layer.smooth:
        raise ValueError("interface_operator projects isotropic rough interfaces only")
    stats = stats if stats is not None else ProjectionStats()
    t0 = time.perf_counter()
    eta = complex(layer.ior) / eta_above
    dist, alpha = layer.distribution, layer.alpha
    opaque = isinstance(layer, Conductor)
    names = ("Rt",) if opaque else ("Rt", "Rb", "Ttb", "Tbt")
    series = {}
    if reciprocity:
        # Reflection blocks are symmetric, and Tbt[a, b] = Ttb[b, a] / eta^2 (generalized
        # reciprocity f(wi, wo) / eta_o^2 = f(wo, wi) / eta_i^2, radiance convention).
        for name in names:
            if name == "Tbt":
                series[name] = _mirror(series["Ttb"], 1.0 / eta.real ** 2, skip_diagonal=False)
            elif name == "Ttb":
                series[name] = _project_block(grid, name, m, eta, alpha, dist, stats)
            else:
                half = _project_block(grid, name, m, eta, alpha, dist, stats, triangle=True)
                series[name] = half + _mirror(half)
    else:
        for name in names:
            series[name] = _project_block(grid, name, m, eta, alpha, dist, stats)
    if opaque:
        series.update({"Rb": None, "Ttb": None, "Tbt": None})
    stats.seconds += time.perf_counter() - t0
    return IsoOperator.from_series(grid, m, series, eta_top=eta_above,
                                   eta_bottom=None if opaque else layer.ior.real)
