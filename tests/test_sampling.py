"""Samplers of layersim.kernels.sampling against the physics they sample (Warp CPU, float64 and
float32)."""

import numpy as np
import pytest
from scipy import integrate, optimize, special

from layersim.kernels import physics, sampling

from probes import ProbeSet

V, T, I = "double3", "double", "int"
CASES = [
    (sampling.sample_microfacet, [V, T, T, T, T, I, T, T, T, T]),     # 0
    (sampling.microfacet_pdf, [V, V, T, T, T, T, I]),                # 1
    (physics.microfacet_eval, [V, V, T, T, T, T, I]),                # 2
    (sampling.beckmann_visible_slope, [T, T]),                       # 3
    (sampling.sample_hg_cos, [T, T]),                                # 4
    (sampling.sample_hg_cos, ["float", "float"]),                    # 5
    (sampling.refract, [V, V, T]),                                   # 6
    (sampling.sample_cosine_hemisphere, ["float", "float"]),         # 7
    (sampling.sample_vndf, [V, T, T, I, T, T, T]),                   # 8
    (sampling.vndf_pdf, [V, V, T, T, I]),                            # 9
]


@pytest.fixture(scope="module")
def probes(tmp_path_factory):
    return ProbeSet(CASES, tmp_path_factory.mktemp("sampling"),
                    name="layersim_test_sampling_probes")


def _unit(r, n, upper=False):
    v = r.normal(size=(n, 3))
    if upper:
        v[:, 2] = np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@pytest.mark.parametrize("dist", [0, 1])
@pytest.mark.parametrize("conductor", [False, True])
def test_sampling_weight_is_eval_cos_over_pdf(probes, dist, conductor):
    """weight == f(wi, wo) |wo.z| / pdf(wo) pointwise, for reflection and refraction, both
    sides, anisotropic roughness; and weight == 0 exactly where the model loses energy."""
    r = np.random.default_rng(7 + dist + 2 * conductor)
    n = 4000
    wi = _unit(r, n, upper=conductor)
    eta = np.where(r.random(n) < 0.5, r.uniform(1.1, 2.0, n), r.uniform(0.5, 0.9, n))
    k = r.uniform(1, 4, n) if conductor else np.zeros(n)
    au, av = r.uniform(0.05, 0.8, n), r.uniform(0.05, 0.8, n)
    d = np.full(n, dist)
    us = [r.uniform(1e-9, 1 - 1e-9, n) for _ in range(4)]
    wo, weight = probes.warp(0, wi, eta, k, au, av, d, *us)
    pdf = probes.warp(1, wi, wo, eta, k, au, av, d)[0]
    f = probes.warp(2, wi, wo, eta, k, au, av, d)[0]
    live = weight > 0
    assert live.mean() > 0.8
    assert np.all(pdf[live] > 0)
    np.testing.assert_allclose(weight[live], f[live] * np.abs(wo[live, 2]) / pdf[live],
                               rtol=1e-7)
    assert np.all(weight <= 1 + 1e-12)
    if not conductor:
        refracted = wi[:, 2] * wo[:, 2] < 0
        assert 0.2 < refracted.mean() < 0.98        # both events are exercised


@pytest.mark.parametrize("dist", [0, 1])
def test_vndf_matches_its_density(probes, dist):
    """Histogram of sampled visible normals (in the projected disk) against the integral of
    vndf_pdf over each cell, for an oblique anisotropic configuration (4 sigma per cell)."""
    r = np.random.default_rng(3 + dist)
    n = 200_000
    wi1 = np.array([0.6, -0.3, 0.0])
    wi1[2] = np.sqrt(1 - wi1 @ wi1)
    au, av = 0.5, 0.25
    wi = np.tile(wi1, (n, 1))
    m = probes.warp(8, wi, np.full(n, au), np.full(n, av), np.full(n, dist),
                    *[r.uniform(1e-9, 1 - 1e-9, n) for _ in range(3)])[0]
    theta_edges = np.array([0, 0.15, 0.3, 0.45, 0.7, np.pi / 2])
    phi_edges = np.linspace(-np.pi, np.pi, 7)
    th, ph = np.arccos(np.clip(m[:, 2], -1, 1)), np.arctan2(m[:, 1], m[:, 0])
    counts = np.histogram2d(th, ph, bins=[theta_edges, phi_edges])[0] / n
    # expected: quadrature of the density over each cell (dω = sin θ dθ dφ)
    x, w = np.polynomial.legendre.leggauss(24)
    expect = np.zeros_like(counts)
    for a in range(len(theta_edges) - 1):
        for b in range(len(phi_edges) - 1):
            t0, t1, p0, p1 = theta_edges[a], theta_edges[a + 1], phi_edges[b], phi_edges[b + 1]
            tt = 0.5 * (t1 - t0) * x + 0.5 * (t1 + t0)
            pp = 0.5 * (p1 - p0) * x + 0.5 * (p1 + p0)
            TT, PP = np.meshgrid(tt, pp, indexing="ij")
            mm = np.stack([np.sin(TT) * np.cos(PP), np.sin(TT) * np.sin(PP), np.cos(TT)],
                          axis=-1).reshape(-1, 3)
            pdf = probes.warp(9, np.tile(wi1, (len(mm), 1)), mm, np.full(len(mm), au),
                              np.full(len(mm), av), np.full(len(mm), dist))[0]
            ww = np.outer(w, w).ravel() * np.sin(TT).ravel()
            expect[a, b] = np.sum(pdf * ww) * 0.25 * (t1 - t0) * (p1 - p0)
    assert abs(expect.sum() - 1) < 2e-3                 # the VNDF integrates to one
    sigma = np.sqrt(np.maximum(expect * (1 - expect), 1e-12) / n)
    assert np.all(np.abs(counts - expect) < 4 * sigma + 1e-6), (counts - expect) / sigma


def test_beckmann_visible_slope_inverts_its_cdf(probes):
    r = np.random.default_rng(5)
    cot = np.exp(r.uniform(-7, 7, 400))
    u = np.concatenate([r.uniform(1e-9, 1 - 1e-9, 397), [1e-10, 0.5, 1 - 1e-9]])
    x = probes.warp(3, cot, u)[0]
    for c, uu, xx in zip(cot, u, x):
        cdf = lambda t: c * np.sqrt(np.pi) / 2 * special.erfc(-t) + np.exp(-t * t) / 2
        # what sampling needs: the probability below x is u (to double precision) ...
        assert abs(cdf(xx) / cdf(c) - uu) < 1e-13, (c, uu, xx)
        # ... and, where the density is not vanishing, x itself
        exact = optimize.brentq(lambda t: cdf(t) - uu * cdf(c), -40, c, xtol=1e-14)
        if 1e-6 < uu < 1 - 1e-6:
            assert abs(xx - exact) < 1e-8 * (1 + abs(exact)), (c, uu, xx, exact)


def test_hg_inversion_is_the_textbook_formula_without_cancellation(probes):
    u = np.linspace(0.001, 0.999, 999)
    for g in (-0.9, -0.3, 0.2, 0.7, 0.95):
        s = (1 - g * g) / (1 - g + 2 * g * u)
        textbook = (1 + g * g - s * s) / (2 * g)
        got = probes.warp(4, np.full(u.size, g), u)[0]
        np.testing.assert_allclose(got, textbook, rtol=0, atol=1e-12)
    # g = 0 is exactly isotropic; tiny g in float32 stays accurate (no 1/g blow-up)
    np.testing.assert_array_equal(probes.warp(4, np.zeros(u.size), u)[0], 2 * u - 1)
    g = 1e-4
    s = (1 - g * g) / (1 - g + 2 * g * u)
    ref = (1 + g * g - s * s) / (2 * g)
    got32 = probes.warp(5, np.full(u.size, g, np.float32), u.astype(np.float32))[0]
    assert np.max(np.abs(got32 - ref)) < 1e-6


@pytest.mark.parametrize("g", [0.0, 0.5, -0.7, 0.9])
def test_hg_samples_follow_hg_eval(probes, g):
    n = 200_000
    u = np.random.default_rng(11).uniform(1e-9, 1 - 1e-9, n).astype(np.float32)
    c = probes.warp(5, np.full(n, g, np.float32), u)[0].astype(np.float64)
    edges = np.linspace(-1, 1, 21)
    counts = np.histogram(c, bins=edges)[0] / n
    # expected mass: integral of 2 pi hg(cos) over each bin (closed form of the HG cdf)
    cdf = lambda x: ((1 - g * g) / (2 * g) * (1 / np.sqrt(1 + g * g - 2 * g * x)
                                               - 1 / (1 + g)) if g else (x + 1) / 2)
    expect = np.diff(cdf(edges))
    quad = [integrate.quad(lambda x: 2 * np.pi * (1 - g * g) / (4 * np.pi * (
        1 + g * g - 2 * g * x) ** 1.5), a, b)[0] for a, b in zip(edges[:-1], edges[1:])]
    np.testing.assert_allclose(expect, quad, rtol=1e-8, atol=1e-12)
    sigma = np.sqrt(expect * (1 - expect) / n)
    assert np.all(np.abs(counts - expect) < 4 * sigma + 1e-7)


def test_refract_obeys_snell_and_reports_total_internal_reflection(probes):
    r = np.random.default_rng(2)
    n = 2000
    wi, m = _unit(r, n), _unit(r, n, upper=True)
    eta = r.uniform(0.5, 2.0, n)
    wt, ok = probes.warp(6, wi, m, eta)
    ci = np.sum(wi * m, axis=1)
    ct = np.sum(wt * m, axis=1)
    eta_i = np.where(ci > 0, 1.0, eta)
    eta_t = np.where(ci > 0, eta, 1.0)
    sin_i = np.sqrt(1 - ci ** 2)
    tir = (eta_i * sin_i / eta_t) >= 1
    assert np.array_equal(ok == 0, tir)
    ok = ok == 1
    np.testing.assert_allclose(np.linalg.norm(wt[ok], axis=1), 1, atol=1e-12)
    np.testing.assert_allclose((eta_t * np.sqrt(1 - ct ** 2))[ok], (eta_i * sin_i)[ok],
                               atol=1e-10)
    assert np.all(ci[ok] * ct[ok] < 0)          # crossed the boundary
    # coplanar with wi and m
    np.testing.assert_allclose(np.sum(np.cross(wi[ok], m[ok]) * wt[ok], axis=1), 0, atol=1e-12)


def test_cosine_hemisphere(probes):
    n = 100_000
    r = np.random.default_rng(4)
    w = probes.warp(7, *r.uniform(1e-9, 1 - 1e-9, (2, n)).astype(np.float32))[0]
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1, atol=1e-6)
    edges = np.linspace(0, 1, 11)
    counts = np.histogram(w[:, 2], bins=edges)[0] / n
    expect = np.diff(edges ** 2)
    assert np.all(np.abs(counts - expect) < 4 * np.sqrt(expect * (1 - expect) / n))
