"""The peak factor of the anisotropic projection against its closed-form Fourier series.

Seed 000 eq. (23)-(24): at fixed ``phi_s`` the Beckmann peak ``exp(-q)`` with
``q(t) = c - d cos(t - shift)`` has the phase-shifted Jacobi-Anger series
``exp(-c) [I_0(d) + 2 sum_n I_n(d) cos(n (t - shift))]``. The projection samples the peak
(:func:`layersim.aniso.series.peak_samples`) and takes an FFT; these tests check that the
samples, with or without the precomputed azimuth cosines, transform to that series.
"""

import numpy as np
import pytest
from scipy import special

from layersim.aniso import series

N_FFT = 4096
ORDERS = 96


def _fft_one_sided(samples):
    """One-sided coefficients ``G_n`` of ``sum G_n exp(i n t)`` from samples at 2 pi k / N."""
    return np.fft.rfft(samples, axis=1)[:, :ORDERS] / samples.shape[1]


@pytest.fixture
def peaks():
    rng = np.random.default_rng(7)
    q0 = rng.uniform(0.0, 2.0, 12)
    d = np.concatenate([[0.0, 1e-3], rng.uniform(0.1, 300.0, 10)])   # lobes up to ~4 deg wide
    shift = rng.uniform(-np.pi, np.pi, 12)
    t = np.arange(N_FFT) * (2.0 * np.pi / N_FFT)
    return q0, q0 + 2.0 * d, shift, d, t


@pytest.mark.parametrize("shared", [False, True])
def test_beckmann_samples_transform_to_bessel_series(peaks, shared):
    q0, qpi, shift, d, t = peaks
    if shared:      # the azimuths of _product_series: one row for all pairs, trig precomputed
        got = series.peak_samples(q0, qpi, shift, "beckmann", t,
                                  (np.cos(t)[None, :], np.sin(t)[None, :]))
    else:           # the per-pair nodes of _fit_smooth
        tt = np.broadcast_to(t, (q0.size, t.size))
        got = series.peak_samples(q0, qpi, shift, "beckmann", tt)
    n = np.arange(ORDERS)
    # exp(-c) I_n(d) = exp(-q0) ive(n, d) with c = q0 + d
    want = np.exp(-q0)[:, None] * special.ive(n[None, :], d[:, None]) \
        * np.exp(-1j * np.outer(shift, n))
    G = _fft_one_sided(got)
    scale = np.abs(want).max(axis=1, keepdims=True)
    assert np.all(np.abs(G - want) <= 1e-12 * scale)
    # and the series the projection multiplies with (layersim.operators.fourier.peak_series)
    ref = series.peak_series_shifted(q0, qpi, shift, "beckmann", ORDERS)
    assert np.all(np.abs(ref - want) <= 1e-12 * scale)


def test_trig_form_equals_direct_cosine(peaks):
    q0, qpi, shift, _, t = peaks
    for dist in ("beckmann", "ggx"):
        direct = series.peak_samples(q0, qpi, shift, dist, t)
        shared = series.peak_samples(q0, qpi, shift, dist, t,
                                     (np.cos(t)[None, :], np.sin(t)[None, :]))
        big = direct.max(axis=1, keepdims=True)
        assert np.all(np.abs(shared - direct) <= 1e-12 * big)


def test_ggx_samples_transform_to_its_series(peaks):
    q0, qpi, shift, _, t = peaks
    got = series.peak_samples(q0, qpi, shift, "ggx", t,
                              (np.cos(t)[None, :], np.sin(t)[None, :]))
    # the closed form of the samples themselves: 1 / (1 + q)^2
    q = 0.5 * (q0 + qpi)[:, None] - 0.5 * (qpi - q0)[:, None] * np.cos(t - shift[:, None])
    np.testing.assert_allclose(got, 1.0 / (1.0 + q) ** 2, rtol=1e-11)   # cancellation in q
    ref = series.peak_series_shifted(q0, qpi, shift, "ggx", ORDERS)
    G = _fft_one_sided(got)
    scale = np.abs(ref).max(axis=1, keepdims=True)
    assert np.all(np.abs(G - ref) <= 1e-11 * scale)
