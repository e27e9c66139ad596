"""Specular paths of a dispersive stack (an index per channel, issue 33): each channel equals
the single-channel stack of its index, sampling draws with its pdf, the plan routes it, and
the walk agrees on the albedos per channel."""

import math

import numpy as np
import pytest

import layersim
import layersim.montecarlo as mc
from layersim.plan import make_plan
from layersim.specular_paths import SpecularPathsBSDF, why_not
from layersim.errors import InfeasibleError
from layersim.specular_paths.stack import chain_of, channel_groups

ETA = (1.48, 1.50, 1.53)
MU_EDGES, PHI_EDGES = np.linspace(0, 1, 11), np.linspace(0, 2 * np.pi, 13)


def _glass(eta, alpha=0.005, **layer):
    return layersim.Scene.from_dict({"layer": [{"kind": "dielectric", "ior": eta,
                                                "roughness": alpha, **layer}]})


def _wi(theta_deg, phi=0.0):
    t = math.radians(theta_deg)
    return np.array([math.sin(t) * math.cos(phi), math.sin(t) * math.sin(phi), math.cos(t)])


@pytest.fixture(scope="module")
def rgb():
    return SpecularPathsBSDF(_glass(list(ETA)))


@pytest.fixture(scope="module")
def singles():
    return [SpecularPathsBSDF(_glass(e)) for e in ETA]


def _lobe_directions(wi, eta, rng, n=30):
    """Directions near the mirror and the refracted direction of ``wi`` into index ``eta``."""
    h = -wi[:2] / eta
    out = []
    for w in (np.array([-wi[0], -wi[1], wi[2]]),
              np.array([h[0], h[1], -np.sign(wi[2]) * math.sqrt(1 - h @ h)])):
        d = w[None, :] + rng.normal(0, 0.004, (n, 3))
        d[:, 2] = np.sign(w[2]) * np.abs(d[:, 2])
        out.append(d / np.linalg.norm(d, axis=1, keepdims=True))
    return np.concatenate(out)


def test_channels_are_grouped_by_their_indices():
    """Three indices: three groups; a per-channel tau under one index: one group; a chain of
    channels of different indices is refused."""
    assert why_not(_glass(list(ETA))) is None
    assert channel_groups(_glass(list(ETA))) == [(0,), (1,), (2,)]
    lacquer = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.01},
        {"kind": "medium", "albedo": 0.0, "tau": [0.1, 0.5, 2.0]}]})
    assert channel_groups(lacquer) == [(0, 1, 2)]
    assert channel_groups(_glass([1.5, 1.5, 1.53])) == [(0, 1), (2,)]
    with pytest.raises(InfeasibleError, match="different indices"):
        chain_of(_glass(list(ETA)), (0, 2))


def test_each_channel_evaluates_as_the_stack_of_its_index(rgb, singles):
    """eval (both lobes, from above and below) and specular of the RGB stack equal, channel
    by channel, the single-channel stacks of each index."""
    rng = np.random.default_rng(5)
    for c, one in enumerate(singles):
        for wi in (_wi(40.0, 0.3), -_wi(25.0, 1.1)):
            wo = _lobe_directions(wi, ETA[c] if wi[2] > 0 else 1 / ETA[c], rng)
            wib = np.broadcast_to(wi, wo.shape)
            ref = one.eval(wib, wo)
            assert ref.max() > 10.0
            assert np.allclose(rgb.eval(wib, wo)[:, c], ref, rtol=1e-12, atol=0)
            assert np.allclose(rgb.specular(wi)["top"][0][c], one.specular(wi)["top"][0])


@pytest.mark.slow
def test_each_channel_has_the_energies_of_the_stack_of_its_index(rgb, singles):
    """Albedo and bin energies of the RGB stack equal, channel by channel, the
    single-channel stacks of each index (1 s)."""
    wi = _wi(40.0, 0.3)
    R, T = rgb.albedo(wi)
    bins = rgb.bin_energies(wi, MU_EDGES, PHI_EDGES)
    for c, one in enumerate(singles):
        r, t = one.albedo(wi)
        assert R[c] == pytest.approx(r, rel=1e-12) and T[c] == pytest.approx(t, rel=1e-12)
        ref = one.bin_energies(wi, MU_EDGES, PHI_EDGES)
        for side in ("top", "bottom"):
            assert np.allclose(bins[side][..., c], ref[side], rtol=1e-12, atol=1e-300)
    # the channels differ: dispersion is not averaged away
    assert R[2] - R[0] > 5e-3


def test_save_and_load_keep_the_channels(tmp_path, rgb):
    back = layersim.BSDF.load(rgb.save(tmp_path / "rgb.lsim"))
    assert back.model.groups == rgb.model.groups and back.info["paths"] == rgb.info["paths"]
    wi = _wi(30.0)
    wo = _lobe_directions(wi, 1.5, np.random.default_rng(2))
    wib = np.broadcast_to(wi, wo.shape)
    assert np.array_equal(back.eval(wib, wo), rgb.eval(wib, wo))


def test_sampling_draws_with_its_pdf(rgb):
    """Transmitted samples (three refracted lobes, one per index) fall in cells of ``wo_h``
    with the probabilities the mixture pdf integrates to (``dOmega = d^2 wo_h / |wo.z|``),
    within 4 binomial standard errors; the pdf returned is ``pdf(wi, wo)``, the weight
    ``f |wo.z| / pdf`` per channel, and the mean weight the albedo per channel."""
    wi = _wi(45.0)
    N = 200_000
    s = rgb.sample(np.broadcast_to(wi, (N, 3)), np.random.default_rng(1).random((N, 2)))
    head = np.broadcast_to(wi, (2000, 3))
    assert np.allclose(rgb.pdf(head, s.wo[:2000]), s.pdf[:2000], rtol=1e-12)
    ok = s.pdf[:2000] > 0
    f = rgb.eval(head[ok], s.wo[:2000][ok])
    assert np.allclose(s.weight[:2000][ok], f * np.abs(s.wo[:2000][ok, 2:]) / s.pdf[:2000][ok, None])
    R, T = rgb.albedo(wi)
    se = s.weight.std(axis=0) / math.sqrt(N)
    assert np.all(np.abs(s.weight.mean(axis=0) - (R + T)) < 4 * se + 1e-4)
    below = s.wo[s.wo[:, 2] < 0, :2]
    x_edges = np.linspace(-0.485, -0.455, 11)     # the lobes: wo_x = -0.478, -0.471, -0.462
    y_edges = np.linspace(-0.006, 0.006, 5)
    H, _, _ = np.histogram2d(below[:, 0], below[:, 1], bins=[x_edges, y_edges])
    sub = (np.arange(10) + 0.5) / 10
    dx, dy = x_edges[1] - x_edges[0], y_edges[1] - y_edges[0]
    for i in range(x_edges.size - 1):
        for j in range(y_edges.size - 1):
            X, Y = np.meshgrid(x_edges[i] + sub * dx, y_edges[j] + sub * dy)
            h = np.stack([X.ravel(), Y.ravel()], axis=1)
            wo = np.concatenate([h, -np.sqrt(1 - np.sum(h ** 2, 1))[:, None]], axis=1)
            prob = np.mean(rgb.pdf(np.broadcast_to(wi, wo.shape), wo) / np.abs(wo[:, 2])) \
                * dx * dy
            assert abs(H[i, j] / N - prob) <= 4 * math.sqrt(prob / N) + 1e-5, (i, j)
    assert H.sum() / N > 0.9


@pytest.mark.slow
def test_the_plan_routes_a_dispersive_interface():
    """The RGB glass interface of alpha 0.005, refused by the Fourier plan, is planned as
    specular paths with a group of paths per channel (10 s: the Fourier plan is weighed
    first)."""
    plan = make_plan(_glass(list(ETA)))
    assert plan.representation == "specular-paths"
    assert "3 groups of channels" in plan.report()


def test_albedos_agree_with_the_walk_per_channel(rgb):
    """R and T per channel within max(4 standard errors, 1e-3) of a 1e5-path walk at 40
    degrees (warp-cpu)."""
    wi = _wi(40.0, 0.3)
    res = mc.simulate(_glass(list(ETA)), wi, 100_000, backend="warp-cpu", seed=3)
    R, T = rgb.albedo(wi)
    for got, ref, se in ((R, res.reflectance, res.reflectance_stderr),
                         (T, res.transmittance, res.transmittance_stderr)):
        assert np.all(np.abs(got - ref) <= np.maximum(4 * np.asarray(se), 1e-3)), (got, ref, se)
    # the walk resolves the dispersion that the check compares
    assert res.reflectance[2] - res.reflectance[0] > 4 * res.reflectance_stderr[2]
