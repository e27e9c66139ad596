"""Numeric projection of interfaces: the BSDF sampled on a uniform azimuth grid by a kernel, then
a discrete Fourier transform (on the device for CUDA, numpy's FFT on the CPU).

This path needs nothing but ``physics.microfacet_eval``, so it projects any BSDF the kernels can
evaluate, and it cross-checks the semi-analytic path (:mod:`.microfacet`). Its cost is set by
the number of azimuth samples: the trapezoidal rule with N samples aliases coefficient
``l`` onto ``N - l``, so a pair whose series has ``K`` significant orders needs
``N >= m + K`` for its first ``m`` orders to be clean. Pairs are grouped by that N (a power of
two), capped at ``max_samples``; pairs that would need more (counted in ``stats.aliased``) are
projected by the semi-analytic path instead. On a GPU this path is far cheaper than the semi-analytic one (no fits, one
launch per group); on a single CPU thread it is usually slower.

Everything else (pairs, energy pruning, reciprocity shortcut, truncation with Lanczos tapering,
assembly) is shared with the semi-analytic path.
"""

from __future__ import annotations

import functools

import numpy as np
import scipy.fft

from .. import fourier
from ..kernels import projection as kproj
from ..operator import Grid, IsoOperator
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


def _numeric_batch(mu_i, mu_o, o, i, q0, qpi, K, m, eta, alpha, dist, stats, *, device,
                   max_samples, min_samples=16):
    length = fourier.peak_length(q0, qpi, dist, ALIAS_RELERR) + microfacet.L_FIT
    need = m + EXTRA_ORDERS + length
    # even sample counts whose half (the DCT length) is FFT-friendly, not powers of two: less
    # oversampling for the same aliasing bound
    N = 2 * np.array([scipy.fft.next_fast_len(int(x)) for x in
                      np.maximum(min_samples, need + 1) // 2 + 1])
    aliased = N > max_samples
    if aliased.any():
        # too peaked to sample (near-specular lobes at grazing ordinates: ~1 / (alpha mu)
        # orders): uniform samples would miss or overweight the azimuthal peak, and with it the
        # pair's energy (order 0). Their exact peak series comes from the semi-analytic path.
        stats.aliased += int(np.count_nonzero(aliased))
        rest = np.flatnonzero(~aliased)
        out = np.zeros((mu_i.size, m))
        out[aliased] = microfacet._project_pairs(
            mu_i[aliased], mu_o[aliased], o[aliased], i[aliased], q0[aliased], qpi[aliased],
            K, m, eta, alpha, dist, stats)[2]
        if rest.size:
            out[rest] = _numeric_batch(mu_i[rest], mu_o[rest], o[rest], i[rest], q0[rest],
                                       qpi[rest], K, m, eta, alpha, dist, stats, device=device,
                                       max_samples=max_samples, min_samples=min_samples)[2]
        return o, i, out
    # a few orders past m decide truncation exactly as the semi-analytic path does (the series
    # decays monotonically beyond its peak: a significant coefficient at or past m means the
    # pair needs more than m orders)
    extra = m + EXTRA_ORDERS
    series = np.zeros((mu_i.size, extra))
    for n in np.unique(N):
        rows = np.flatnonzero(N == n)
        series[rows] = kproj.uniform_cosine_series(mu_i[rows], mu_o[rows], eta, alpha, alpha,
                                                   dist, int(n), extra, device=device)
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
                               reciprocity: bool = True) -> IsoOperator:
    """Operator of an isotropic rough interface by sampling and FFT (see module docstring).

    Parameters are those of :func:`layersim.ingredients.microfacet.interface_operator`, plus
    ``device`` (Warp device for the sampling and, on CUDA, the transform), ``max_samples`` and
    ``min_samples`` (bounds on the azimuth samples per pair).
    """
    method = functools.partial(_numeric_batch, device=device, max_samples=max_samples,
                               min_samples=min_samples)
    # on a GPU a whole block is one batch (a few launches, one per sample count); on the CPU
    # the semi-analytic path's batches keep the temporaries small and the thread pool busy
    batch = GPU_BATCH if microfacet._on_gpu(device) else microfacet.BATCH
    return microfacet.interface_operator(grid, m, layer, eta_above, stats,
                                         reciprocity=reciprocity, method=method, batch=batch,
                                         device=device)
