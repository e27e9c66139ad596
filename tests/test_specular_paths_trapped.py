"""The light of the branches that path enumeration cuts (layersim.specular_paths.continuation):
its walk's face events against the faces' directional energies, no change where nothing is
trapped, conservation in a lossless pane at grazing incidence, and the grazing bins of the
glass pane at 70 degrees against the Monte Carlo walk."""

import math

import numpy as np
import pytest

import layersim
import layersim.montecarlo as mc
from layersim.specular_paths import SpecularPathsBSDF
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


def _without_continuation(monkeypatch):
    """Make the model carry nothing of the cut branches (the solver before continuation)."""
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
def test_nothing_changes_where_nothing_is_trapped(pane, monkeypatch):
    """At 30 degrees the cut branches carry below 1e-6 of the power: bins and albedos stay
    those of the kept paths alone within 1e-6."""
    wi = _wi(30.0)
    R, T = pane.albedo(wi)
    bins = pane.bin_energies(wi, MU_EDGES, PHI_EDGES)
    _without_continuation(monkeypatch)
    R0, T0 = pane.albedo(wi)
    bins0 = pane.bin_energies(wi, MU_EDGES, PHI_EDGES)
    assert abs(R - R0) < 1e-6 and abs(T - T0) < 1e-6
    for side in bins:
        assert np.max(np.abs(bins[side] - bins0[side])) < 1e-6


@pytest.mark.slow
@pytest.mark.parametrize("theta", [70.0, 75.0, 80.0])
def test_a_lossless_pane_conserves_energy_at_grazing_incidence(pane, theta, monkeypatch):
    """R + T = 1 within 4 standard errors of the continuation (and the single-scattering
    loss, below 2e-5 here), while the kept paths alone lose over 10 of them."""
    wi = _wi(theta)
    ex = continue_frontier(pane.model.models[0], True, pane.model.models[0].p_in(wi[None])[0])
    se = math.sqrt(float(np.sum(ex.w ** 2)))
    R, T = pane.albedo(wi)
    print(f"{theta} deg: R + T - 1 = {R + T - 1:.2e}, continuation {ex.w.sum():.2e} "
          f"+- {se:.1e}")
    assert abs(R + T - 1.0) <= 4 * se + 2e-5
    _without_continuation(monkeypatch)
    R0, T0 = pane.albedo(wi)
    assert 1.0 - (R0 + T0) > 10 * se


@pytest.mark.slow
def test_the_glass_pane_grazing_bins_agree_with_the_walk(pane, monkeypatch):
    """Glass pane at 70 degrees against a 1e6-path walk (warp-cpu), sigma the walk's and the
    continuation's standard errors together: the grazing bins (``|cos| < 0.1``, the mirror
    azimuth) were beyond 3 sigma without the continuation; now the bottom one and every
    other bin is within 3 sigma and the top one is nearer. The top one stays short
    (measured 5.5 sigma): :func:`layersim.specular_paths.binning.path_bins` gives a sparse
    bin of a kept path the integral of its linearised lobe, which holds none of the light
    that leaves there after being trapped for a few bounces (docs/method.md)."""
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
    _without_continuation(monkeypatch)
    zero = {k: np.zeros_like(v) for k, v in se.items()}
    before = z(pane.bin_energies(wi, MU_EDGES, PHI_EDGES), zero)
    print(f"grazing bins z: top {before['top'][0, 6]:.1f} -> {after['top'][0, 6]:.1f}, "
          f"bottom {before['bottom'][0, 6]:.1f} -> {after['bottom'][0, 6]:.1f}")
    assert before["top"][0, 6] > 3.0 and before["bottom"][0, 6] > 3.0
    assert after["bottom"][0, 6] <= 3.0
    assert after["top"][0, 6] < before["top"][0, 6] - 1.0
    others = after["top"].copy()
    others[0, 6] = 0.0
    assert others.max() <= 3.0 and after["bottom"].max() <= 3.0
