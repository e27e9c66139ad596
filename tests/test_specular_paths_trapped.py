"""The light of the walked branches (layersim.specular_paths.frontier, .continuation): its
walk's face events against the faces' directional energies, walking or tracing the faint
branches alike where nothing is trapped, conservation in a lossless pane at grazing incidence,
and the glass pane's bins at 70 degrees against the Monte Carlo walk."""

import math

import numpy as np
import pytest

import layersim
import layersim.montecarlo as mc
from layersim.specular_paths import SpecularPathsBSDF
from layersim.specular_paths import frontier
from layersim.specular_paths import model as path_model
from layersim.specular_paths.continuation import (Exits, continue_frontier, exit_bins,
                                                  rough_event, standard_error)
from layersim.solved.lobe import NearSpecularLobe
from layersim.specular_paths.stack import Face

PANE = [{"kind": "dielectric", "ior": 1.5, "roughness": 0.01},
        {"kind": "dielectric", "ior": 1.0, "roughness": 0.01}]
MU_EDGES, PHI_EDGES = np.linspace(0, 1, 11), np.linspace(0, 2 * np.pi, 13)


def _wi(theta_deg, phi=0.3):
    t = math.radians(theta_deg)
    return np.array([math.sin(t) * math.cos(phi), math.sin(t) * math.sin(phi), math.cos(t)])


@pytest.fixture(scope="module")
def pane():
    return SpecularPathsBSDF(layersim.Scene.from_dict({"layer": PANE}))


def _without_continuation(monkeypatch, bsdf):
    """Make the model of ``bsdf`` carry nothing of the cut branches (the solver before
    continuation), forgetting the walk it shares between albedos and bins."""
    for m in bsdf.model.models:
        monkeypatch.setattr(m, "_walked", {})
    none = lambda model, *a, **k: Exits(np.zeros((0, 2)), np.zeros(0, bool),
                                        np.zeros((0, model.chain.channels)),
                                        np.zeros(model.chain.channels))
    monkeypatch.setattr(path_model, "continue_frontier", none)


@pytest.mark.parametrize("down, theta", [(True, 50.0), (False, 30.0), (False, 45.0)])
def test_a_walk_event_has_the_face_energies(down, theta):
    """Reflected and transmitted weights of many events at one rough glass face (alpha 0.05,
    from above, from below, from below beyond the critical angle) average to the face's
    directional energies (facet quadrature of :class:`NearSpecularLobe`) within 4 standard
    errors."""
    face = Face((1.5 + 0j,), 0.05, 0.05, "beckmann", 0.0)
    na, nb = (1.0, 1.5) if down else (1.5, 1.0)
    N = 200_000
    t = math.radians(theta)
    p = np.tile([na * math.sin(t), 0.0], (N, 1))
    u = np.random.default_rng(3).random((N, 4))
    _, refl, w = rough_event(face, p, na, nb, down, u)
    R, T = NearSpecularLobe(nb / na, 0.05, 0.05, "beckmann", 0.0).energies(
        np.array([[math.sin(t), 0.0, math.cos(t)]]))
    for got, ref in ((np.where(refl, w[:, 0], 0.0), R[0]), (np.where(refl, 0.0, w[:, 0]), T[0])):
        assert abs(got.mean() - ref) <= 4 * got.std() / math.sqrt(N), (got.mean(), ref)


@pytest.mark.slow
def test_walking_the_faint_branches_changes_nothing_where_nothing_is_trapped(pane, monkeypatch):
    """At 30 degrees nothing is trapped: walking the branches below WALK_BELOW (the default)
    or tracing every kept path (WALK_BELOW 0) gives the same albedos within 4 standard errors
    of the walk plus 2e-5 (the tracing's quadrature), and the same bins within 4 standard
    errors plus 1e-6."""
    wi = _wi(30.0)
    model = pane.model.models[0]
    p = model.p_in(wi[None])[0]
    kept = len(frontier.split(model, True, p)[0])
    ex = continue_frontier(model, True, p)
    se_albedo = math.sqrt(float(np.sum(ex.w ** 2)))
    se = standard_error(model, ex, MU_EDGES, PHI_EDGES)
    R, T = pane.albedo(wi)
    bins = pane.bin_energies(wi, MU_EDGES, PHI_EDGES)
    monkeypatch.setattr(frontier, "WALK_BELOW", 0.0)
    monkeypatch.setattr(model, "_walked", {})       # the walk it shares is the old split's
    assert len(frontier.split(model, True, p)[0]) > kept, "the test would not test it"
    R0, T0 = pane.albedo(wi)
    bins0 = pane.bin_energies(wi, MU_EDGES, PHI_EDGES)
    print(f"R {R:.6f} / {R0:.6f}, T {T:.6f} / {T0:.6f} +- {se_albedo:.1e}")
    assert abs(R - R0) <= 4 * se_albedo + 2e-5 and abs(T - T0) <= 4 * se_albedo + 2e-5
    for side in bins:
        assert np.all(np.abs(bins[side] - bins0[side]) <= 4 * se[side][..., 0] + 1e-6), side


@pytest.mark.slow
@pytest.mark.parametrize("theta", [70.0, 75.0, 80.0])
def test_a_lossless_pane_keeps_the_walks_energy_at_grazing_incidence(pane, theta, monkeypatch):
    """R + T of the pane (its faces lose only the single-scattering share of light that stays
    trapped for hundreds of grazing bounces: 2e-4 at 75 degrees, 9e-4 at 80) equals the
    2e6-path walk's within 4 standard errors of both (plus 2e-5, the tracing's quadrature),
    while the traced paths alone (the walked
    branches' light dropped) fall short by over 10 of the continuation's."""
    wi = _wi(theta)
    ex = continue_frontier(pane.model.models[0], True, pane.model.models[0].p_in(wi[None])[0])
    se = math.sqrt(float(np.sum(ex.w ** 2)))
    R, T = pane.albedo(wi)
    res = mc.simulate(layersim.Scene.from_dict({"layer": PANE}), wi, 2_000_000,
                      backend="warp-cpu", seed=7)
    # the walk's lost share and its own standard error (R and T are anticorrelated)
    lost, se_walk = float(res.absorbed), float(res.absorbed_stderr)
    print(f"{theta} deg: 1 - R - T = {1 - R - T:.2e} +- {se:.1e}, walk {lost:.2e} +- "
          f"{se_walk:.1e}, continuation {ex.w.sum():.2e}")
    assert abs(1.0 - R - T - lost) <= 4 * math.hypot(se, se_walk) + 2e-5
    _without_continuation(monkeypatch, pane)
    R0, T0 = pane.albedo(wi)
    assert 1.0 - (R0 + T0) > 10 * se


@pytest.mark.slow
def test_the_glass_pane_bins_agree_with_the_walk_at_70_degrees(pane, monkeypatch):
    """Glass pane at 70 degrees against a 1e6-path walk (warp-cpu), sigma the walk's and the
    continuation's standard errors together: without the walked branches' light the grazing
    bins (``|cos| < 0.1``, the mirror azimuth) are beyond 3 sigma; with it every bin of both
    sides is within 3 sigma (the top grazing bin stayed 5.5 sigma short while the trapped light
    of kept paths was traced instead, docs/method.md)."""
    wi = _wi(70.0)
    scene = layersim.Scene.from_dict({"layer": PANE})
    res = mc.simulate(scene, wi, 1_000_000, mu_edges=MU_EDGES, phi_edges=PHI_EDGES,
                      backend="warp-cpu", seed=5)
    model = pane.model.models[0]            # one group of channels: no dispersion
    ex = continue_frontier(model, True, model.p_in(wi[None])[0])
    se = standard_error(model, ex, MU_EDGES, PHI_EDGES)

    def z(bins, own):
        out = {}
        for side in ("top", "bottom"):
            ref, got = np.asarray(res.bins[side], float), np.asarray(bins[side], float)
            sig = np.sqrt(np.asarray(res.bins_stderr[side], float) ** 2
                          + np.maximum(got, 0.0) / res.particles + own[side][..., 0] ** 2)
            out[side] = np.where((ref > 0) | (got > 1e-12),
                                 np.abs(got - ref) / np.maximum(sig, 1e-15), 0.0)
        return out

    after = z(pane.bin_energies(wi, MU_EDGES, PHI_EDGES), se)
    _without_continuation(monkeypatch, pane)
    zero = {k: np.zeros_like(v) for k, v in se.items()}
    before = z(pane.bin_energies(wi, MU_EDGES, PHI_EDGES), zero)
    print(f"grazing bins z: top {before['top'][0, 6]:.1f} -> {after['top'][0, 6]:.1f}, "
          f"bottom {before['bottom'][0, 6]:.1f} -> {after['bottom'][0, 6]:.1f}; largest "
          f"{max(after['top'].max(), after['bottom'].max()):.1f}")
    assert before["top"][0, 6] > 3.0 and before["bottom"][0, 6] > 3.0
    assert after["top"].max() <= 3.0 and after["bottom"].max() <= 3.0


def test_albedo_and_bins_at_one_incidence_share_one_walk(monkeypatch):
    """The walked branches' light is walked once per incidence for ``albedo`` and
    ``bin_energies`` together (deterministic: the same seed), and both equal those of a fresh
    model that walks for each."""
    scene = layersim.Scene.from_dict({"layer": [{"kind": "dielectric", "ior": 1.5,
                                                 "roughness": 0.02}]})
    wi = _wi(60.0)
    fresh = SpecularPathsBSDF(scene)
    R0, T0 = fresh.albedo(wi)
    bins0 = SpecularPathsBSDF(scene).bin_energies(wi, MU_EDGES, PHI_EDGES)
    calls = []
    real = path_model.continue_frontier
    monkeypatch.setattr(path_model, "continue_frontier",
                        lambda *a, **k: calls.append(1) or real(*a, **k))
    shared = SpecularPathsBSDF(scene)
    R, T = shared.albedo(wi)
    bins = shared.bin_energies(wi, MU_EDGES, PHI_EDGES)
    assert len(calls) == 1
    assert (R, T) == (R0, T0)
    for side in bins:
        np.testing.assert_array_equal(bins[side], bins0[side])
    shared.albedo(_wi(30.0))
    assert len(calls) == 2
