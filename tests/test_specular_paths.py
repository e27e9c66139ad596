"""Specular paths (layersim.specular_paths) against closed forms, conservation, reciprocity,
its own sampler and a save/load round trip (the comparisons with the walk are in
tests/test_specular_paths_walk.py)."""

import math

import numpy as np
import pytest

import layersim
from layersim.kernels.pointwise import microfacet_bsdf
from layersim.plan import make_plan
from layersim.solved.lobe import NearSpecularLobe
from layersim.specular_paths import SpecularPathsBSDF
from layersim.specular_paths.lobes import PathLobe
from layersim.specular_paths.model import PathModel
from layersim.specular_paths.stack import Chain, Face, chain_of

GOLD = [[0.143552, 3.98397], [0.374967, 2.38489], [1.44248, 1.60319]]


def _scene(*layers, **stack):
    return layersim.Scene.from_dict({"stack": stack, "layer": list(layers)})


def _d(eta, rough, dist="beckmann", **kw):
    return {"kind": "dielectric", "ior": eta, "roughness": rough, "distribution": dist, **kw}


def _dir(theta_deg, phi=0.3, up=True):
    t = math.radians(theta_deg)
    return np.array([math.sin(t) * math.cos(phi), math.sin(t) * math.sin(phi),
                     math.cos(t) if up else -math.cos(t)])


def _near(w, d_theta, d_phi):
    """Directions near ``w`` (3,), offset in elevation and azimuth (arrays)."""
    th = math.acos(abs(w[2])) + np.asarray(d_theta)
    ph = math.atan2(w[1], w[0]) + np.asarray(d_phi)
    z = np.sign(w[2]) * np.cos(th)
    return np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), z], axis=-1)


# built directly: the plan's look at the Fourier alternative costs seconds (test_plan below)
@pytest.fixture(scope="module")
def frosted():
    return SpecularPathsBSDF(_scene(_d(1.5, 0.02, "ggx")))


@pytest.fixture(scope="module")
def pane():
    return SpecularPathsBSDF(_scene(_d(1.5, 0.01), _d(1.0, 0.01)))


def test_a_single_interface_is_the_exact_microfacet_model(frosted):
    """Reflection and transmission, from above and below, equal the microfacet BSDF of the
    interface (kernels.pointwise.microfacet_bsdf)."""
    assert isinstance(frosted, SpecularPathsBSDF)
    rng = np.random.default_rng(0)
    for up, eta in ((True, 1.5), (False, 1.0 / 1.5)):
        wi = _dir(35.0, up=up)
        refl = _near(np.array([-wi[0], -wi[1], wi[2]]), rng.normal(0, .02, 50),
                     rng.normal(0, .05, 50))
        wo_t = np.array([-wi[0], -wi[1], 0.0]) * (1.0 / eta if up else 1.0 / eta)
        wo_t[2] = -np.sign(wi[2]) * math.sqrt(1 - wo_t[0] ** 2 - wo_t[1] ** 2)
        trans = _near(wo_t, rng.normal(0, .01, 50), rng.normal(0, .02, 50))
        for wo in (refl, trans):
            wib = np.broadcast_to(wi, wo.shape)
            flip = np.array([1, 1, 1 if up else -1])
            ref = microfacet_bsdf(wib * flip, wo * flip, eta, 0.02, "ggx", "separable")
            got = frosted.eval(wib, wo)
            assert np.allclose(got, ref, rtol=1e-12, atol=0), np.max(np.abs(got / ref - 1))
            assert ref.max() > 1.0


@pytest.mark.slow
def test_a_single_interface_has_the_rough_energies(frosted):
    """The traced albedo of one interface equals the facet quadrature of its energies
    (NearSpecularLobe, 256 x 512 nodes: converged to 1e-6) within the tracing's error."""
    wi = _dir(50.0)
    R, T = NearSpecularLobe(1.5, 0.02, 0.02, "ggx", nodes=(256, 512)).energies(wi[None])
    r, t = frosted.albedo(wi)
    assert abs(r - R[0]) < 1e-5 and abs(t - T[0]) < 1e-4, (r - R[0], t - T[0])


def test_a_pane_of_smooth_faces_has_the_closed_form_reflectance():
    """A tinted pane of smooth faces (its delta paths): R = R1 + T1^2 R1 a^2 / (1 - R1^2 a^2),
    T = T1^2 a / (1 - R1^2 a^2) with a = exp(-tau / mu_t), pruned at 1e-14."""
    smooth = Face((1.5 + 0j,), 0.0, 0.0, "beckmann", 0.0)
    back = Face((1 / 1.5 + 0j,), 0.0, 0.0, "beckmann", 0.0)
    chain = Chain((smooth, (0.3,), back), (1.0, 1.5, 1.5, 1.0), 1)
    model = PathModel(chain, 1e-14)
    wi = _dir(40.0)
    spec = model.specular(wi[None])
    mu, mut = wi[2], math.sqrt(1 - (1 - wi[2] ** 2) / 2.25)
    rs = ((mu - 1.5 * mut) / (mu + 1.5 * mut)) ** 2
    rp = ((1.5 * mu - mut) / (1.5 * mu + mut)) ** 2
    R1 = 0.5 * (rs + rp)
    a = math.exp(-0.3 / mut)
    R = R1 + (1 - R1) ** 2 * R1 * a * a / (1 - R1 * R1 * a * a)
    T = (1 - R1) ** 2 * a / (1 - R1 * R1 * a * a)
    assert spec["top"][0][0, 0] == pytest.approx(R, rel=1e-10)
    assert spec["bottom"][0][0, 0] == pytest.approx(T, rel=1e-10)
    assert np.allclose(spec["bottom"][1][0], [wi[0] * 0 - wi[0], -wi[1], -wi[2]])


def test_a_two_event_beckmann_chain_is_its_gaussian(pane):
    """The lobe of the pane's straight-through path (two Beckmann refractions, c = |n_a mu_a -
    n_b mu_b| each) is the Gaussian of the summed variances, and eval is E n_out^2 times it."""
    x = next(e for e in pane.model.models[0].entries[True]
             if len(e.rough) == 2 and not e.path.exit_top)
    p = np.array([[0.2, 0.1]])
    mu0, mu1 = math.sqrt(1 - 0.05), math.sqrt(1 - 0.05 / 2.25)
    c = abs(mu0 - 1.5 * mu1)
    S2 = 2 * (c * 0.01) ** 2
    dp = np.array([[0.004, -0.002], [0.0, 0.0], [0.01, 0.006]])
    ref = np.exp(-np.sum(dp ** 2, axis=1) / S2) / (math.pi * S2)
    # (1e-4: the shape table is piecewise linear in t between 200 nodes)
    assert np.allclose(x.lobe.density(dp, np.repeat(p, 3, axis=0)), ref, rtol=1e-4)


def test_a_two_event_ggx_chain_is_the_convolution_of_its_slopes():
    """Two GGX refractions of different scales: the tabulated radial shape (inverse Hankel
    transform of s K1(s) products) against a direct 2-D convolution of the two slope
    densities."""
    f1 = Face((1.5 + 0j,), 0.02, 0.02, "ggx", 0.0)
    f2 = Face((1 / 1.5 + 0j,), 0.01, 0.01, "ggx", 0.0)
    lobe = PathLobe([(f1, "T", 0, 1), (f2, "T", 1, 2)], (1.0, 1.5, 1.0))
    p = np.zeros((1, 2))
    c = 0.5
    s1, s2 = c * 0.02, c * 0.01
    g = np.linspace(-40 * s1, 40 * s1, 1601)
    X, Y = np.meshgrid(g, g)
    q1 = 1 / (math.pi * s1 ** 2 * (1 + (X ** 2 + Y ** 2) / s1 ** 2) ** 2)
    dA = (g[1] - g[0]) ** 2
    for d in ([0.0, 0.0], [0.01, 0.0], [0.02, 0.01]):
        q2 = 1 / (math.pi * s2 ** 2 * (1 + ((d[0] - X) ** 2 + (d[1] - Y) ** 2) / s2 ** 2) ** 2)
        ref = np.sum(q1 * q2) * dA
        got = lobe.density(np.array([d]), p)[0]
        assert got == pytest.approx(ref, rel=5e-3)


@pytest.mark.slow
def test_energy_is_conserved_without_absorption(pane):
    """R + T = 1 less the pruned energy and the single-scattering loss (both below 1e-4
    here), and never above 1."""
    for th in (0.0, 30.0, 60.0):
        R, T = pane.albedo(_dir(th))
        assert 1 - 1e-4 < R + T <= 1 + 1e-6, (th, R + T)


@pytest.mark.parametrize("which", ["frosted", "pane", "lacquer"])
def test_reciprocity(which, frosted, pane):
    """f(wi, wo) / n_o^2 = f(wo, wi) / n_i^2 (docs/conventions.md) near every lobe."""
    bsdf = {"frosted": frosted, "pane": pane,
            "lacquer": SpecularPathsBSDF(_scene(_d(1.5, 0.02),
                                                {"kind": "medium", "albedo": 0, "tau": 0.4}))
            }[which]
    n = bsdf.chains[0].n
    rng = np.random.default_rng(3)
    wi = _dir(30.0)
    for wo0, n_o in ((np.array([-wi[0], -wi[1], wi[2]]), n[0]),
                     (np.array([-wi[0] * n[0] / n[-1], -wi[1] * n[0] / n[-1], 0]), n[-1])):
        if wo0[2] == 0:
            wo0[2] = -math.sqrt(1 - wo0[0] ** 2 - wo0[1] ** 2)
        wo = _near(wo0, rng.normal(0, .01, 40), rng.normal(0, .02, 40))
        wib = np.broadcast_to(wi, wo.shape)
        a = bsdf.eval(wib, wo) / n_o ** 2
        b = bsdf.eval(wo, wib) / n[0] ** 2
        assert a.max() > 1.0
        assert np.allclose(a, b, rtol=1e-9, atol=1e-12)


@pytest.mark.slow
def test_sampling_draws_with_its_pdf(pane):
    """Samples of the pane's transmission fall in cells of wave-vector space with the
    probabilities the pdf integrates to (within 4 binomial standard errors), the pdf
    returned is pdf(wi, wo) and the weight f |wo.z| / pdf."""
    wi = _dir(45.0)
    N = 200_000
    s = pane.sample(np.broadcast_to(wi, (N, 3)), np.random.default_rng(1).random((N, 2)))
    assert np.allclose(pane.pdf(np.broadcast_to(wi, (2000, 3)), s.wo[:2000]), s.pdf[:2000],
                       rtol=1e-10)
    ok = s.pdf[:2000] > 0
    f = pane.eval(np.broadcast_to(wi, (2000, 3))[ok], s.wo[:2000][ok])
    assert np.allclose(s.weight[:2000][ok], f * np.abs(s.wo[:2000][ok, 2]) / s.pdf[:2000][ok])
    below = s.wo[:, 2] < 0
    pi = -wi[:2]
    dp = s.wo[below, :2] - pi
    edges = np.linspace(-0.03, 0.03, 7)
    H, _, _ = np.histogram2d(dp[:, 0], dp[:, 1], bins=[edges, edges])
    sub = (np.arange(12) + 0.5) / 12
    for i in range(6):
        for j in range(6):
            x = edges[i] + sub * (edges[1] - edges[0])
            y = edges[j] + sub * (edges[1] - edges[0])
            X, Y = np.meshgrid(x, y)
            po = pi + np.stack([X.ravel(), Y.ravel()], axis=1)
            wo = np.concatenate([po, -np.sqrt(1 - np.sum(po ** 2, 1))[:, None]], axis=1)
            # solid-angle density to wave-vector density: d^2 p = mu dOmega (n = 1)
            prob = np.mean(pane.pdf(np.broadcast_to(wi, wo.shape), wo) / np.abs(wo[:, 2])) \
                * (edges[1] - edges[0]) ** 2
            assert abs(H[i, j] / N - prob) <= 4 * math.sqrt(prob / N) + 1e-5, (i, j)


def test_save_and_load_rebuild_the_same_bsdf(tmp_path, pane, frosted):
    """eval, specular and albedo of the reloaded BSDF are bit-identical."""
    for bsdf in (pane, frosted):
        back = layersim.BSDF.load(bsdf.save(tmp_path / "x.lsim"))
        assert isinstance(back, SpecularPathsBSDF) and back.info["paths"] == bsdf.info["paths"]
        wi = _dir(20.0)
        wo = _near(np.array([-wi[0], -wi[1], -wi[2]]), np.linspace(-.01, .01, 9), 0.003)
        assert np.array_equal(back.eval(np.broadcast_to(wi, wo.shape), wo),
                              bsdf.eval(np.broadcast_to(wi, wo.shape), wo))
        assert np.array_equal(back.specular(wi)["top"][0], bsdf.specular(wi)["top"][0])
    assert np.array_equal(np.array(back.albedo(wi)), np.array(frosted.albedo(wi)))


def test_chain_of_a_stack():
    """Media between faces become slabs, gap indices follow the faces, a conductor ends it."""
    chain = chain_of(_scene(_d(1.5, 0.0), {"kind": "medium", "albedo": 0.0, "tau": [.1, .2, .3]},
                            {"kind": "conductor", "ior": GOLD, "roughness": 0.01}))
    assert chain.n == (1.0, 1.5, 1.5, 1.5) and chain.channels == 3 and chain.opaque
    assert chain.elements[1] == (0.1, 0.2, 0.3)
