"""Numeric projection of interfaces: the BSDF sampled on a uniform azimuth grid by a kernel, then
a discrete Fourier transform (on the device for CUDA, numpy's FFT on the CPU).

This path needs nothing but ``physics.microfacet_eval``, so it projects any BSDF the kernels can
evaluate, and it cross-checks the semi-analytic path (:mod:`.microfacet`). Its cost is set by
the number of azimuth samples: the trapezoidal rule with N samples aliases coefficient
``l`` onto ``N - l``, so a pair whose series has ``K`` significant orders needs
``N >= m + K`` for its first ``m`` orders to be clean. Pairs are grouped by that N (a power of
two), capped at ``max_samples``; pairs that would need more (counted in ``stats.aliased``) are
projected by the semi-analytic path instead. On a GPU this path is far cheaper than the
semi-analytic one (no fits, one launch per group); on a single CPU thread it is usually slower.

Everything else (pairs, energy pruning, reciprocity shortcut, truncation with tapering by the
Jackson kernel factors, assembly) follows the semi-analytic path. On a CUDA device a whole
operator is built without leaving it (:func:`device_interface_operator`): per block, one
coarse-bound launch, sampling with each pair's own power-of-two sample count, one DCT and one
truncation launch, then the assembly kernels of :mod:`layersim.kernels.sparse` (scatter with
reciprocity, per-order drop threshold, scan, compaction); only the three coarse numbers per
pair, the row pointers and the nonzeros come back. The host keeps the decisions that need the
analytic series lengths (:func:`layersim.operators.fourier.peak_length`) and the few pairs too
peaked to sample.
"""

from __future__ import annotations

import functools
import time

import numpy as np
import scipy.fft

from ..operators import fourier
from ..kernels import projection as kproj
from ..kernels.sparse import BlockAssembler
from ..operators.operator import DROP_TOLERANCE, Grid, IsoOperator, OrderStack
from . import microfacet
from .microfacet import ProjectionStats

#: Largest azimuth sample count per pair.
MAX_SAMPLES = 1 << 14
#: Series length (relative to f_0) the sample count must resolve without aliasing.
ALIAS_RELERR = 1e-12
#: Orders computed past m to decide truncation.
EXTRA_ORDERS = 8
#: Pairs per batch on a GPU.
GPU_BATCH = 1 << 20
#: Largest (orders x h x h) scratch block of the device assembly (entries; 2 GiB of float64);
#: larger operators are assembled on the host.
DEVICE_DENSE_MAX = 1 << 28


def _half_period_needed(q0, qpi, dist: str, m: int, min_samples: int, film=None,
                        alpha: float = 0.0):
    """Series length of each pair (peak factor at :data:`ALIAS_RELERR` plus the smooth factor's
    orders, a thin film's included: :func:`~layersim.ingredients.microfacet.film_orders` at
    roughness ``alpha``) and the smallest half period ``M`` (samples of [0, pi]
    minus one) whose trapezoidal rule keeps the first ``m + EXTRA_ORDERS`` orders clean of
    aliasing; callers round ``M`` up (FFT-friendly on the host, powers of two on the
    device)."""
    length = (fourier.peak_length(q0, qpi, dist, ALIAS_RELERR) + microfacet.L_FIT
              + microfacet.film_orders(film, alpha))
    return length, np.maximum(min_samples, m + EXTRA_ORDERS + length + 1) // 2 + 1


def _numeric_batch(mu_i, mu_o, o, i, q0, qpi, K, m, eta, alpha, dist, stats, *, device,
                   max_samples, min_samples=16, film=None, shadowing="separable"):
    length, half = _half_period_needed(q0, qpi, dist, m, min_samples, film, alpha)
    # even sample counts whose half (the DCT length) is FFT-friendly, not powers of two: less
    # oversampling for the same aliasing bound
    N = 2 * np.array([scipy.fft.next_fast_len(int(x)) for x in half])
    aliased = N > max_samples
    if aliased.any():
        # too peaked to sample (near-specular lobes at grazing ordinates: ~1 / (alpha mu)
        # orders): uniform samples would miss or overweight the azimuthal peak, and with it the
        # pair's energy (order 0). Their exact peak series comes from the semi-analytic path.
        stats.aliased += int(np.count_nonzero(aliased))
        rest = np.flatnonzero(~aliased)
        out = np.zeros((mu_i.size, m))
        out[aliased] = microfacet.project_pairs(
            mu_i[aliased], mu_o[aliased], o[aliased], i[aliased], q0[aliased], qpi[aliased],
            K, m, eta, alpha, dist, stats, film=film, shadowing=shadowing)[2]
        if rest.size:
            out[rest] = _numeric_batch(mu_i[rest], mu_o[rest], o[rest], i[rest], q0[rest],
                                       qpi[rest], K, m, eta, alpha, dist, stats, device=device,
                                       max_samples=max_samples, min_samples=min_samples,
                                       film=film, shadowing=shadowing)[2]
        return o, i, out
    # a few orders past m decide truncation exactly as the semi-analytic path does (the series
    # decays monotonically beyond its peak: a significant coefficient at or past m means the
    # pair needs more than m orders)
    extra = m + EXTRA_ORDERS
    series = np.zeros((mu_i.size, extra))
    for n in np.unique(N):
        rows = np.flatnonzero(N == n)
        series[rows] = kproj.uniform_cosine_series(mu_i[rows], mu_o[rows], eta, alpha, alpha,
                                                   dist, int(n), extra, device=device,
                                                   film=film, shadowing=shadowing)
    mag = np.abs(series)
    above = mag >= microfacet.RELERR * np.maximum(mag[:, :1], 1e-300)
    cut = above[:, m:].any(axis=1)
    stats.truncated += int(np.count_nonzero(cut))
    stats.orders_needed = max(stats.orders_needed, int(length.max(initial=0)))
    length_m = np.where(cut, m, extra - np.argmax(above[:, ::-1], axis=1))
    series = series[:, :m]
    series[np.arange(m)[None, :] >= length_m[:, None]] = 0.0
    microfacet.apply_taper(series, microfacet.needs_taper(q0, qpi, dist, m), stats)
    return o, i, series


def numeric_interface_operator(grid: Grid, m: int, layer, eta_above: float,
                               stats: ProjectionStats | None = None, device=None,
                               max_samples: int = MAX_SAMPLES, min_samples: int = 16,
                               reciprocity: bool = True,
                               on_device: bool | None = None,
                               blocks: tuple | None = None) -> IsoOperator:
    """Operator of an isotropic rough interface by sampling and FFT (see module docstring).

    Parameters are those of :func:`layersim.ingredients.microfacet.interface_operator`
    (``blocks`` included: only those blocks, on the host path), plus ``device`` (Warp device
    for the sampling and, on CUDA, the transform), ``max_samples`` and ``min_samples``
    (bounds on the azimuth samples per pair), and ``on_device``: build the whole operator on
    ``device`` (:func:`device_interface_operator`; default: on CUDA devices, when its scratch
    block fits :data:`DEVICE_DENSE_MAX`, and all blocks are asked for).
    """
    fits = m * grid.h * grid.h <= DEVICE_DENSE_MAX
    if microfacet.on_gpu(device) and on_device is None:
        on_device = fits and blocks is None
    if on_device and blocks is not None:
        raise ValueError("the device assembly projects every block: use on_device=False "
                         "with blocks")
    if on_device:
        if not fits:
            raise ValueError(f"device assembly of {m} orders on {grid.h} nodes needs more than "
                             f"DEVICE_DENSE_MAX = {DEVICE_DENSE_MAX} scratch entries; use "
                             "on_device=False")
        return device_interface_operator(grid, m, layer, eta_above, stats, device=device,
                                         max_samples=max_samples, min_samples=min_samples,
                                         reciprocity=reciprocity)
    method = functools.partial(_numeric_batch, device=device, max_samples=max_samples,
                               min_samples=min_samples)
    # on a GPU a whole block is one batch (a few launches, one per sample count); on the CPU
    # the semi-analytic path's batches keep the temporaries small and the thread pool busy
    batch = GPU_BATCH if microfacet.on_gpu(device) else microfacet.BATCH
    return microfacet.interface_operator(grid, m, layer, eta_above, stats,
                                         reciprocity=reciprocity, method=method, batch=batch,
                                         device=device, blocks=blocks)


def _device_block(grid: Grid, name: str, triangle: bool, m: int, eta: complex, alpha: float,
                  dist: str, stats: ProjectionStats, device, max_samples: int,
                  min_samples: int, film=None, shadowing="separable") -> list:
    """Series of the significant pairs of one block: ``[(o, i, coef)]`` with ``coef`` a Warp
    array on ``device`` (sampled pairs) or a host array (pairs too peaked to sample, projected
    semi-analytically as in :func:`_numeric_batch`)."""
    mu_i, mu_o, o, i, q0, qpi, keep = microfacet.significant_pairs(grid, name, triangle, eta,
                                                                   alpha, dist, device, film,
                                                                       shadowing)
    stats.pairs += mu_i.size
    stats.projected += keep.size
    t0 = time.perf_counter()
    length, need = _half_period_needed(q0[keep], qpi[keep], dist, m, min_samples, film, alpha)
    # power-of-two half periods: one cosine table serves every pair (the host path's
    # FFT-friendly lengths would need a table per length)
    half = 1 << np.ceil(np.log2(need)).astype(np.int64)
    aliased = 2 * half > max_samples
    parts = []
    if aliased.any():
        sel = keep[aliased]
        stats.aliased += sel.size
        K = int(min(fourier.peak_length(q0[sel], qpi[sel], dist, microfacet.RELERR).max(),
                    m + microfacet.L_HARD))
        parts.append(microfacet.project_pairs(mu_i[sel], mu_o[sel], o[sel], i[sel], q0[sel],
                                               qpi[sel], K, m, eta, alpha, dist, stats,
                                               film=film, shadowing=shadowing))
    rest = np.flatnonzero(~aliased)
    if rest.size:
        rest = rest[np.argsort(half[rest], kind="stable")]
        sel = keep[rest]
        stats.orders_needed = max(stats.orders_needed, int(length[rest].max()))
        taper = microfacet.needs_taper(q0[sel], qpi[sel], dist, m)
        stats.tapered += int(np.count_nonzero(taper))
        coef, cut = kproj.ragged_cosine_series(mu_i[sel], mu_o[sel], eta, alpha, alpha, dist,
                                               half[rest], m + EXTRA_ORDERS, m,
                                               microfacet.RELERR, taper,
                                               fourier.taper_factors(m), device=device,
                                               film=film, shadowing=shadowing)
        stats.truncated += int(cut.numpy().sum())
        parts.append((o[sel], i[sel], coef))
    stats.series_seconds += time.perf_counter() - t0
    return parts


def device_interface_operator(grid: Grid, m: int, layer, eta_above: float,
                              stats: ProjectionStats | None = None, device=None,
                              max_samples: int = MAX_SAMPLES, min_samples: int = 16,
                              reciprocity: bool = True) -> IsoOperator:
    """:func:`numeric_interface_operator` with every block built on ``device`` (see the module
    docstring): the same pairs, sample-count rule (rounded up to powers of two), truncation,
    tapering, reciprocity shortcut and drop threshold as the host assembly, so the two agree to
    rounding and aliasing below :data:`ALIAS_RELERR`. Runs on any Warp device (the tests use the
    CPU); it pays off on GPUs. The scratch block takes ``8 m h^2`` bytes of device memory."""
    stats = stats if stats is not None else ProjectionStats()
    t0 = time.perf_counter()
    eta, dist, alpha, opaque, names, film, shadowing = microfacet.interface_setup(layer, eta_above)
    h = grid.h
    asm = BlockAssembler(m, h, grid.flux_weight, device=device)
    blocks, ttb = {}, None
    for name in names:
        asm.reset()
        if reciprocity and name == "Tbt":
            # Tbt[a, b] = Ttb[b, a] / eta^2 (generalized reciprocity, radiance convention)
            for o, i, coef in ttb:
                asm.scatter(coef, o, i, direct=False, mirror=True, skip_diagonal=False,
                            scale=1.0 / eta.real ** 2)
        else:
            # reflection blocks are symmetric: one triangle, mirrored off the diagonal
            triangle = reciprocity and name != "Ttb"
            parts = _device_block(grid, name, triangle, m, eta, alpha, dist, stats, device,
                                  max_samples, min_samples, film, shadowing)
            for o, i, coef in parts:
                asm.scatter(coef, o, i, mirror=triangle)
            if name == "Ttb":
                ttb = parts
        blocks[name] = OrderStack(*asm.compact(DROP_TOLERANCE), h)
    stats.seconds += time.perf_counter() - t0
    return IsoOperator(grid, blocks, eta_top=eta_above,
                       eta_bottom=None if opaque else layer.ior.real)
