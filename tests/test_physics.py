"""The Warp physics functions (single source of the BSDF formulas) against independent
oracles: Fresnel from complex amplitude coefficients, normalisation of the NDFs, the Smith
projected-area identity, generalized reciprocity, and Henyey-Greenstein moments."""

import numpy as np
import pytest
import warp as wp

from layersim.kernels import physics
from layersim.kernels.runtime import device_for

from conftest import random_directions

DIST = {"beckmann": 0, "ggx": 1}


@wp.kernel
def _fresnel(c: wp.array(dtype=wp.float64), eta: wp.float64, k: wp.float64,
             out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    if k > wp.float64(0.0):
        out[i] = physics.fresnel_conductor(c[i], eta, k)
    else:
        out[i] = physics.fresnel_dielectric(c[i], eta)


@wp.kernel
def _ndf_g1(m: wp.array(dtype=wp.vec3d), w: wp.vec3d, au: wp.float64, av: wp.float64,
            dist: int, d: wp.array(dtype=wp.float64), g1: wp.array(dtype=wp.float64)):
    i = wp.tid()
    d[i] = physics.ndf(m[i], au, av, dist)
    g1[i] = physics.smith_g1(w, m[i], au, av, dist)


@wp.kernel
def _bsdf(wi: wp.array(dtype=wp.vec3d), wo: wp.array(dtype=wp.vec3d), eta: wp.float64,
          k: wp.float64, au: wp.float64, av: wp.float64, dist: int,
          out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    out[i] = physics.microfacet_eval(wi[i], wo[i], eta, k, au, av, dist)


@wp.kernel
def _hg(c: wp.array(dtype=wp.float64), g: wp.float64, out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    out[i] = physics.hg_eval(c[i], g)


def _run(kernel, n, inputs, outs):
    dev = device_for()
    arrays = [wp.zeros(n, dtype=wp.float64, device=dev) for _ in range(outs)]
    wp.launch(kernel, dim=n, inputs=inputs, outputs=arrays, device=dev)
    return [a.numpy() for a in arrays]


def fresnel(c, eta, k=0.0):
    c = np.asarray(c, float)
    return _run(_fresnel, c.size, [wp.array(c, dtype=wp.float64), wp.float64(eta),
                                   wp.float64(k)], 1)[0]


def reference_fresnel(cos_i, n):
    """Unpolarised reflectance from the complex amplitude coefficients (Born & Wolf 1.5)."""
    n = complex(n)
    sin2 = 1 - cos_i ** 2
    root = np.sqrt(n * n - sin2 + 0j)
    rs = (cos_i - root) / (cos_i + root)
    rp = (n * n * cos_i - root) / (n * n * cos_i + root)
    return 0.5 * (abs(rs) ** 2 + abs(rp) ** 2)


def test_dielectric_fresnel_matches_amplitude_coefficients():
    c = np.linspace(0.001, 1.0, 200)
    for eta in (1.5, 1.0001, 4.0, 1 / 1.5):
        ours = fresnel(c, eta)
        ref = reference_fresnel(c, eta)
        if eta < 1:  # total internal reflection beyond the critical angle
            ref = np.where(1 - c ** 2 > eta ** 2, 1.0, ref)
        np.testing.assert_allclose(ours, ref, rtol=1e-12, atol=1e-14)
    assert fresnel([1.0], 1.5)[0] == pytest.approx(0.04, abs=1e-15)


def test_dielectric_fresnel_is_the_same_from_both_sides():
    # light arriving from the dense side (cos < 0 relative to the normal) sees 1/eta
    c = np.linspace(0.05, 1.0, 50)
    np.testing.assert_allclose(fresnel(-c, 1.5), fresnel(c, 1 / 1.5), rtol=1e-14)
    # Stokes relation: R(theta_i) == R(theta_t) for the refracted angle
    ct = np.sqrt(1 - (1 - c ** 2) / 1.5 ** 2)
    np.testing.assert_allclose(fresnel(c, 1.5), fresnel(-ct, 1.5), rtol=1e-10)


@pytest.mark.parametrize("eta,k", [(0.143552, 3.98397), (1.43825, 1.60434), (0.2, 10.0),
                                   (2.5, 0.3), (0.0, 1.0)])
def test_conductor_fresnel_matches_amplitude_coefficients(eta, k):
    c = np.linspace(0.001, 1.0, 200)
    np.testing.assert_allclose(fresnel(c, eta, k), reference_fresnel(c, complex(eta, k)),
                               rtol=1e-10)


def _slope_grid(au, av, lim, n=801):
    """Microfacet normals on a grid of slopes s = sinh(t) (t uniform: dense near the peak,
    reaching far into heavy tails), with solid-angle weights."""
    t = np.linspace(-np.arcsinh(lim), np.arcsinh(lim), n)
    s, ds = np.sinh(t), np.cosh(t) * (t[1] - t[0])
    x, y = np.meshgrid(au * s, av * s, indexing="ij")
    m = np.stack([-x, -y, np.ones_like(x)], axis=-1)
    m /= np.linalg.norm(m, axis=-1, keepdims=True)
    # d omega_m = cos^3(theta_m) dx dy
    dA = np.outer(ds, ds) * au * av * m[..., 2] ** 3
    return m.reshape(-1, 3), dA.ravel()


def _ndf_g1_values(m, w, au, av, dist):
    return _run(_ndf_g1, m.shape[0], [wp.array(m, dtype=wp.vec3d), wp.vec3d(*w), wp.float64(au),
                                      wp.float64(av), DIST[dist]], 2)


@pytest.mark.parametrize("dist", ["beckmann", "ggx"])
@pytest.mark.parametrize("au,av", [(0.1, 0.1), (0.3, 0.05), (0.5, 0.5)])
def test_ndf_projected_area_is_one_and_smith_identity_holds(dist, au, av):
    m, dA = _slope_grid(au, av, lim=9.0 if dist == "beckmann" else 2000.0)
    for theta, phi in [(0.0, 0.0), (40.0, 20.0), (75.0, 100.0)]:
        th, ph = np.radians(theta), np.radians(phi)
        w = np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])
        D, G1 = _ndf_g1_values(m, w, au, av, dist)
        if theta == 0.0:
            # integral of D(m) cos(theta_m) over the hemisphere = 1
            assert np.sum(D * m[:, 2] * dA) == pytest.approx(1.0, rel=2e-4)
        # Smith: integral of G1(w, m) <w, m>^+ D(m) d omega_m = w.z (Heitz 2014, eq. 43)
        proj = np.sum(G1 * np.clip(m @ w, 0, None) * D * dA)
        assert proj == pytest.approx(w[2], rel=1e-3)


def _eval_pairs(wi, wo, eta, k, au, av, dist):
    return _run(_bsdf, wi.shape[0], [wp.array(wi, dtype=wp.vec3d), wp.array(wo, dtype=wp.vec3d),
                                     wp.float64(eta), wp.float64(k), wp.float64(au),
                                     wp.float64(av), DIST[dist]], 1)[0]


@pytest.mark.parametrize("dist", ["beckmann", "ggx"])
@pytest.mark.parametrize("au,av", [(0.2, 0.2), (0.1, 0.4)])
def test_microfacet_bsdf_obeys_generalized_reciprocity(dist, au, av):
    rng = np.random.default_rng(3)
    eta = 1.5
    n = 400
    for lower_i, lower_o in [(False, False), (True, True), (False, True), (True, False)]:
        wi = random_directions(rng, n, lower_i)
        wo = random_directions(rng, n, lower_o)
        f_io = _eval_pairs(wi, wo, eta, 0.0, au, av, dist)
        f_oi = _eval_pairs(wo, wi, eta, 0.0, au, av, dist)
        eta_i = np.where(wi[:, 2] < 0, eta, 1.0)
        eta_o = np.where(wo[:, 2] < 0, eta, 1.0)
        assert np.any(f_io > 0)
        np.testing.assert_allclose(f_io / eta_o ** 2, f_oi / eta_i ** 2, rtol=1e-10, atol=1e-300)
    # conductors reflect from the top only, symmetrically
    wi, wo = random_directions(rng, n), random_directions(rng, n)
    f = _eval_pairs(wi, wo, 0.2, 3.0, au, av, dist)
    np.testing.assert_allclose(f, _eval_pairs(wo, wi, 0.2, 3.0, au, av, dist), rtol=1e-12)
    assert np.all(_eval_pairs(wi, -wo, 0.2, 3.0, au, av, dist) == 0)


@pytest.mark.parametrize("dist", ["beckmann", "ggx"])
def test_single_scattering_microfacet_never_creates_energy(dist):
    # hemispherical integral of f |cos| over a fine (mu, phi) grid, both sides
    nmu, nphi = 1200, 720
    mu = (np.arange(nmu) + 0.5) / nmu
    phi = (np.arange(nphi) + 0.5) * 2 * np.pi / nphi
    M, P = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - M ** 2)
    up = np.stack([s * np.cos(P), s * np.sin(P), M], -1).reshape(-1, 3)
    dw = (1 / nmu) * (2 * np.pi / nphi)
    for theta in (0.0, 45.0, 80.0):
        th = np.radians(theta)
        wi = np.array([np.sin(th), 0, np.cos(th)])
        wis = np.broadcast_to(wi, up.shape).copy()
        R = np.sum(_eval_pairs(wis, up, 1.5, 0.0, 0.3, 0.3, dist) * up[:, 2]) * dw
        down = up * np.array([1, 1, -1])
        T = np.sum(_eval_pairs(wis, down, 1.5, 0.0, 0.3, 0.3, dist) * up[:, 2]) * dw
        assert 0.0 < R + T <= 1.0 + 1e-3
        assert R + T > 0.85  # alpha = 0.3 loses only a few percent to single scattering


def test_henyey_greenstein_is_normalised_with_mean_cosine_g():
    # Gauss-Legendre in t with cos(Theta) = 1 - 2 t^2 clusters nodes at the forward peak
    t, wt = np.polynomial.legendre.leggauss(4000)
    t, wt = 0.5 * (t + 1), 0.5 * wt
    x, w = 1 - 2 * t ** 2, 4 * t * wt
    for g in (0.0, 0.5, -0.3, 0.9):
        p = _run(_hg, x.size, [wp.array(x, dtype=wp.float64), wp.float64(g)], 1)[0]
        assert 2 * np.pi * np.sum(w * p) == pytest.approx(1.0, abs=1e-10)
        assert 2 * np.pi * np.sum(w * p * x) == pytest.approx(g, abs=1e-9)


@pytest.mark.parametrize("g", [0.3, -0.5, 0.8])
def test_the_solvers_henyey_greenstein_series_sums_to_hg_eval(g):
    """The discrete ordinates use HG through its Legendre series (moments g^k and the addition
    theorem, :func:`layersim.ingredients.medium.hg_components`), not through ``hg_eval``: the
    Fourier sum of its components between directions in the same and in opposite hemispheres
    is the Warp function, to the series' truncation tolerance (relative to the peak)."""
    from layersim.ingredients import medium
    mu = np.cos(np.linspace(0.05, 1.5, 9))
    s = np.sqrt(1.0 - mu * mu)
    dphi = np.linspace(0.0, np.pi, 7)
    same, opp = medium.hg_components(mu, g, medium.legendre_terms(g))
    peak = (1 + abs(g)) / ((1 - abs(g)) ** 2 * 4 * np.pi)
    for comp, sign in ((same, 1.0), (opp, -1.0)):
        series = np.einsum("lab,lp->abp", comp,
                           np.cos(np.outer(np.arange(comp.shape[0]), dphi)))
        c = (sign * mu[:, None, None] * mu[None, :, None]
             + s[:, None, None] * s[None, :, None] * np.cos(dphi))
        ref = _run(_hg, c.size, [wp.array(c.ravel(), dtype=wp.float64), wp.float64(g)],
                   1)[0].reshape(c.shape)
        assert np.abs(series - ref).max() < medium.PHASE_TOLERANCE * peak
