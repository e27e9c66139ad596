"""Importance sampling: sample() against pdf() (chi-square goodness of fit, Mitsuba style),
normalisation of pdf(), consistency of weights with eval() and pdf(), perfect importance sampling
where nothing is clamped, the clamped sampling density next to undershoot, and invalid queries."""

import numpy as np
import pytest
import scipy.stats

import layersim
# piecewise-cubic-exact
from layersim.operators.interpolation import bin_quadrature as _bin_quadrature
from layersim.solved.channels import LUMINANCE
from layersim.operators.operator import Grid, IsoOperator

from conftest import random_directions, unit

#: Family-wise significance of the chi-square tests (Sidak-corrected per test).
ALPHA = 0.01
CHI2_CASES = [("coated_gold", 10.0), ("coated_gold", 60.0), ("coated_gold", 85.0),
              ("rough_glass", 30.0), ("rough_glass", 140.0)]


def _directions(z, phi):
    s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=-1)


def bin_integrals(bsdf, wi, z_edges, phi_edges, gl_z=3, gl_phi=32):
    """Integral of bsdf.pdf over (z = cos theta_o, phi_o) bins: Gauss-Legendre in z on pieces cut
    at the ordinates (where the density is piecewise polynomial) and in phi per bin."""
    nodes = np.concatenate([-bsdf.grid.mu[::-1], bsdf.grid.mu])
    zs, zw, zb = _bin_quadrature(nodes, z_edges, gl_z)
    xp, wp = np.polynomial.legendre.leggauss(gl_phi)
    a, c = phi_edges[:-1], phi_edges[1:]
    ps = (((a + c) / 2)[:, None] + ((c - a) / 2)[:, None] * xp).ravel()
    pw = (((c - a) / 2)[:, None] * wp).ravel()
    pb = np.repeat(np.arange(a.size), gl_phi)
    Z, P = np.meshgrid(zs, ps, indexing="ij")
    W = zw[:, None] * pw[None, :] * bsdf.pdf(wi, _directions(Z, P))
    out = np.zeros((z_edges.size - 1, phi_edges.size - 1))
    np.add.at(out, (np.broadcast_to(zb[:, None], W.shape), np.broadcast_to(pb[None, :], W.shape)),
              W)
    return out


def chi2_pvalue(bsdf, wi_sample, wi_pdf=None, n=50_000, seed=0, n_z=20, n_phi=36):
    """p-value of the samples of ``wi_sample`` against the density of ``wi_pdf`` (bins over the
    whole sphere; bins expecting fewer than 5 samples are pooled)."""
    wi_pdf = wi_sample if wi_pdf is None else wi_pdf
    rng = np.random.default_rng(seed)
    wo, _, pdf = bsdf.sample(wi_sample, rng.random((n, 2)))
    assert np.all(pdf > 0)
    z_edges = np.linspace(-1, 1, n_z + 1)
    phi_edges = np.linspace(-np.pi, np.pi, n_phi + 1)
    obs, _, _ = np.histogram2d(wo[:, 2], np.arctan2(wo[:, 1], wo[:, 0]), [z_edges, phi_edges])
    exp = n * bin_integrals(bsdf, wi_pdf, z_edges, phi_edges)
    small = exp < 5
    o = np.append(obs[~small], obs[small].sum())
    e = np.append(exp[~small], exp[small].sum())
    if e[-1] == 0 and o[-1] == 0:
        o, e = o[:-1], e[:-1]
    stat = np.sum((o - e) ** 2 / np.maximum(e, 1e-300))
    return scipy.stats.chi2.sf(stat, o.size - 1)


@pytest.mark.parametrize("name,theta", CHI2_CASES)
def test_chi2_sample_follows_pdf(request, name, theta):
    bsdf = request.getfixturevalue(name)
    p = chi2_pvalue(bsdf, unit(theta, 40.0))
    assert p > 1.0 - (1.0 - ALPHA) ** (1.0 / len(CHI2_CASES))


def test_chi2_detects_a_wrong_density(coated_gold):
    """The chi-square test has power: samples at 10 degrees against the density at 13."""
    assert chi2_pvalue(coated_gold, unit(10.0, 40.0), unit(13.0, 40.0), n=20_000) < 1e-6


def _sphere_integral(bsdf, wi, k_phi=600):
    """Integral of pdf over the sphere: 3-point Gauss-Legendre between ordinates (exact for the
    piecewise-quartic elevation density) and the periodic trapezoid rule in phi (exact for
    trigonometric polynomials of degree < k_phi). Also returns the negative mass of the cosine-
    weighted luminance of the interpolant (eval before its positive part) relative to its total,
    on the same points."""
    mu = bsdf.grid.mu
    nodes = np.concatenate([[0.0], mu, [1.0] if mu[-1] < 1 else []])
    x, w = np.polynomial.legendre.leggauss(3)
    a, c = nodes[:-1], nodes[1:]
    z = (((a + c) / 2)[:, None] + ((c - a) / 2)[:, None] * x).ravel()
    wz = (((c - a) / 2)[:, None] * w).ravel()
    z = np.concatenate([z, -z])
    wz = np.concatenate([wz, wz])
    phi = np.arange(k_phi) * 2 * np.pi / k_phi
    Z, P = np.meshgrid(z, phi, indexing="ij")
    wo = _directions(Z, P)
    total = float(np.sum(wz[:, None] * bsdf.pdf(wi, wo)) * 2 * np.pi / k_phi)
    f = bsdf.interpolant(wi, wo)
    f = f @ LUMINANCE if f.ndim == 3 else f
    fc = wz[:, None] * f * np.abs(Z)
    return total, float(np.sum(np.maximum(-fc, 0)) / np.sum(fc))


@pytest.mark.parametrize("name,theta", [("coated_gold", 45.0), ("coated_gold", 85.0),
                                        ("rough_glass", 30.0), ("rough_glass", 140.0)])
def test_pdf_integrates_to_one(request, name, theta):
    """To rounding, plus at most the negative mass of the interpolant: where an azimuthal
    series dips below zero, the density max(g, 0) / (2 pi g_0) integrates to 1 + that part of the
    mass (measured: 1 to rounding for coated gold, whose interpolant is non-negative, also at
    85 degrees; 1 + 4.6e-5 for rough glass lit from inside at 140 degrees, whose interpolant
    has a negative mass of 3.6e-4 next to the critical angle)."""
    bsdf = request.getfixturevalue(name)
    total, negative = _sphere_integral(bsdf, unit(theta, 25.0))
    assert negative < 1e-3
    assert 1.0 - 1e-10 <= total <= 1.0 + 1e-10 + min(negative, 1e-4)


def test_weights_and_pdf_are_consistent_with_eval(rough_glass):
    rng = np.random.default_rng(3)
    wi = np.concatenate([random_directions(rng, 2000), random_directions(rng, 2000, lower=True)])
    wo, weight, pdf = rough_glass.sample(wi, rng.random((wi.shape[0], 2)))
    ok = pdf > 0
    assert ok.mean() > 0.999
    np.testing.assert_allclose(rough_glass.pdf(wi[ok], wo[ok]), pdf[ok], rtol=1e-9)
    f = rough_glass.eval(wi[ok], wo[ok])
    np.testing.assert_allclose(weight[ok], np.maximum(f, 0) * np.abs(wo[ok, 2]) / pdf[ok],
                               rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(wo[ok], axis=-1), 1.0, atol=1e-12)


def test_one_channel_sampling_is_perfect_where_nothing_is_clamped(coated_gold):
    """weight = f |cos| / pdf is the same for every sample: the cosine-weighted integral of the
    interpolated BSDF, which agrees with the quadrature albedo to the discretisation error."""
    rng = np.random.default_rng(4)
    for theta in (0.0, 30.0, 70.0):
        wi = unit(theta, 10.0)
        _, weight, _ = coated_gold.sample(wi, rng.random((5000, 2)))
        assert np.ptp(weight) < 1e-9 * weight.max()
        assert weight[0] == pytest.approx(float(coated_gold.albedo(wi)[0]), rel=1e-4)


def test_transmission_is_chosen_by_energy(rough_glass):
    rng = np.random.default_rng(5)
    for theta in (20.0, 60.0, 160.0):
        wi = unit(theta, 0.0)
        wo, _, _ = rough_glass.sample(wi, rng.random((40_000, 2)))
        R, T = rough_glass.albedo(wi)
        frac = np.mean(np.sign(wo[:, 2]) != np.sign(wi[2]))
        p = float(T / (R + T))
        assert abs(frac - p) < 4 * np.sqrt(p * (1 - p) / 40_000) + 1e-3


def test_opaque_stack_never_samples_below_the_horizon(coated_gold):
    rng = np.random.default_rng(6)
    wi = random_directions(rng, 20_000, min_z=0.0)
    u = rng.random((20_000, 2))
    u[:100] = 0.0                      # the edges of the unit square
    u[100:200] = 1.0
    wo, weight, pdf = coated_gold.sample(wi, u)
    assert np.all(wo[:, 2] >= 0.0)
    assert np.all((wo[:, 2] > 0.0) | ((pdf == 0.0) & (weight == 0.0)))
    assert np.mean(pdf > 0) > 0.99
    # light from below an opaque stack: no sample, density 0
    wo, weight, pdf = coated_gold.sample(unit(30.0, below=True), rng.random((10, 2)))
    assert np.all(pdf == 0) and np.all(weight == 0) and np.all(wo == 0)
    assert np.all(coated_gold.pdf(unit(30.0), unit(40.0, below=True)) == 0.0)


def test_invalid_queries(coated_gold):
    wo, weight, pdf = coated_gold.sample(np.array([1.0, 0.0, 0.0]), [0.3, 0.4])
    assert pdf == 0 and weight == 0 and np.all(wo == 0)
    assert coated_gold.pdf(unit(20.0), np.array([0.0, 1.0, 0.0])) == 0.0
    with pytest.raises(ValueError, match=r"\(\.\.\., 2\)"):
        coated_gold.sample(unit(20.0), [0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="within"):
        coated_gold.sample(unit(20.0), [0.1, 1.2])
    with pytest.raises(ValueError, match="unit vectors"):
        coated_gold.pdf(unit(20.0), [0.0, 0.0, 2.0])


def test_samples_below_an_opaque_stack_are_flagged_invalid_row_by_row(coated_gold):
    """wi.z < 0 on an opaque stack: no light enters, so those rows are invalid samples (as
    Mitsuba 3 returns them: wo = 0, weight = 0, pdf = 0) and ``valid`` says so, while the
    rows lit from above in the same batch are drawn as usual; one direction alone behaves as
    a batch of one (no exception)."""
    assert coated_gold.opaque
    rng = np.random.default_rng(11)
    wi = np.concatenate([unit(np.array([20.0, 50.0, 70.0])),
                         unit(np.array([20.0, 50.0]), below=True)])
    s = coated_gold.sample(wi, rng.random((5, 2)))
    assert isinstance(s, layersim.solved.sampling.Sample) and len(s) == 3
    wo, weight, pdf = s
    np.testing.assert_array_equal(s.valid, [True, True, True, False, False])
    assert np.all(pdf[:3] > 0) and np.all(weight[:3] > 0)
    np.testing.assert_allclose(np.linalg.norm(wo[:3], axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(pdf[:3], coated_gold.pdf(wi[:3], wo[:3]), rtol=1e-10)
    assert np.all(wo[3:] == 0.0) and np.all(weight[3:] == 0.0) and np.all(pdf[3:] == 0.0)
    one = coated_gold.sample(unit(30.0, below=True), [0.3, 0.7])
    assert one.valid.shape == () and not one.valid and one.pdf == 0 and np.all(one.wo == 0)


def test_shapes_broadcast(coated_gold):
    wi = unit(np.array([10.0, 20.0, 30.0]))[:, None, :]           # (3, 1, 3)
    u = np.random.default_rng(7).random((4, 2))                     # (4, 2)
    wo, weight, pdf = coated_gold.sample(wi, u)
    assert wo.shape == (3, 4, 3) and weight.shape == (3, 4) and pdf.shape == (3, 4)


# ---- clamping next to undershoot ---------------------------------------------------------------

@pytest.fixture(scope="module")
def step_bsdf():
    """An opaque reflector whose zeroth order steps from 0 to 1/pi at mu_o = 0.6 (the cubic
    interpolant undershoots below zero there), with a first order 0.9 f_0 in azimuth."""
    grid = Grid.make("gauss-lobatto", 16)
    f0 = np.where(grid.mu[:, None] > 0.6, 1.0 / np.pi, 0.0) * np.ones(grid.h)[None, :]
    fw = grid.flux_weight[None, :]
    blocks = np.stack([2 * np.pi * f0 * fw, np.pi * 0.9 * f0 * fw])
    op = IsoOperator.from_dense(grid, {"Rt": blocks}, eta_top=1.0, eta_bottom=None)
    return layersim.BSDF([op])


def test_eval_is_the_positive_part_of_the_undershooting_interpolant(step_bsdf):
    wi = unit(35.0, 15.0)
    z = np.linspace(1e-4, 1.0, 4001)
    wo = _directions(z, np.full_like(z, 15.0 + 180.0) * np.pi / 180)
    f = step_bsdf.interpolant(wi, wo)
    assert f.min() < -1e-3 * f.max()                 # precondition: the interpolant undershoots
    np.testing.assert_array_equal(step_bsdf.eval(wi, wo), np.maximum(f, 0.0))


def test_sampling_density_is_clamped_next_to_undershoot(step_bsdf):
    wi = unit(35.0, 15.0)
    z = np.linspace(1e-4, 1.0, 4001)
    f = step_bsdf.interpolant(wi, _directions(z, np.full_like(z, 15.0 + 180.0) * np.pi / 180))
    assert f.min() < -1e-3 * f.max()                 # precondition: the interpolant undershoots
    phi = np.linspace(-np.pi, np.pi, 91)
    Z, P = np.meshgrid(z, phi, indexing="ij")
    pdf = step_bsdf.pdf(wi, _directions(Z, P))
    assert pdf.min() >= 0.0 and np.any(pdf[f < 0] == 0.0)
    assert _sphere_integral(step_bsdf, wi, k_phi=8)[0] == pytest.approx(1.0, abs=1e-12)
    assert chi2_pvalue(step_bsdf, wi, n=30_000) > 1e-3
    wo, weight, pdf = step_bsdf.sample(wi, np.random.default_rng(8).random((20_000, 2)))
    assert np.all(pdf > 0) and np.all(weight >= 0)


# ---- RGB ---------------------------------------------------------------------------------------

def test_rgb_is_sampled_by_luminance_with_per_channel_weights():
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
        {"kind": "conductor", "roughness": 0.3,
         "ior": [[0.143552, 3.98397], [0.377438, 2.38495], [1.43825, 1.60434]]}],
        "discretization": {"n": 48, "md": 64}})
    bsdf = layersim.solve(scene)
    rng = np.random.default_rng(9)
    wi = unit(40.0, 70.0)
    wo, weight, pdf = bsdf.sample(wi, rng.random((4000, 2)))
    assert weight.shape == (4000, 3) and pdf.shape == (4000,)
    f = bsdf.eval(wi, wo)
    np.testing.assert_allclose(weight, np.maximum(f, 0) * np.abs(wo[:, 2:]) / pdf[:, None],
                               rtol=1e-12)
    # the luminance of the weight is constant (perfect sampling of luminance); gold is red, so
    # the red weight varies around its mean and exceeds the blue one
    y = weight @ LUMINANCE
    assert np.ptp(y) < 1e-9 * y.max()
    assert np.all(weight[:, 0] > weight[:, 2]) and np.std(weight[:, 0]) > 1e-4
