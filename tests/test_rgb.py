"""RGB scenes: every output carries the same three channels, each channel is the monochromatic
solve of that channel (gold's complex index per channel; the blue Henyey-Greenstein medium of
Zeltner & Jakob 2018, Fig. 7d), and per-channel physics oracles (Fresnel of gold at normal incidence; a
higher single-scattering albedo reflects and transmits more)."""

import numpy as np
import pytest

import layersim
from layersim import bsdffile
from layersim.solved import plot

from conftest import random_directions, unit

#: Gold (eta, k) per RGB channel (layerlab tutorial sec. 6.4).
GOLD = [[0.143552, 3.98397], [0.377438, 2.38495], [1.43825, 1.60434]]
#: Seed 000 Fig. 7d: blue HG medium (albedo [0.6, 0.8, 0.95], g = 0.2) under a dielectric
#: coating, on gold. The figure's base is anisotropic and its coating alpha = 0.05; isotropic
#: alpha = 0.3 for both here (coarse, fast discretisation), tau = 1 (not given in the paper).
FIG7D = {"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
                   {"kind": "medium", "albedo": [0.6, 0.8, 0.95], "g": 0.2, "tau": 1.0},
                   {"kind": "conductor", "ior": GOLD, "roughness": 0.3}],
         "discretization": {"n": 48, "md": 48}}


@pytest.fixture(scope="module")
def fig7d():
    scene = layersim.Scene.from_dict(FIG7D)
    return scene, layersim.solve(scene)


def test_every_output_carries_three_channels(tmp_path, fig7d):
    _, bsdf = fig7d
    wi = unit(np.array([0.0, 30.0, 60.0]), 20.0)
    wo = unit(np.array([10.0, 40.0, 70.0]), 200.0)
    assert bsdf.eval(wi, wo).shape == (3, 3)
    R, T = bsdf.albedo(wi)
    assert R.shape == T.shape == (3, 3)
    bins = bsdf.bin_energies(wi[1], np.linspace(0, 1, 5), np.linspace(0, 2 * np.pi, 9))
    assert bins["top"].shape == bins["bottom"].shape == (4, 8, 3)
    np.testing.assert_allclose(bins["top"].sum(axis=(0, 1)), R[1], rtol=1e-12)
    wo_s, weight, pdf = bsdf.sample(wi[1], np.random.default_rng(0).random((100, 2)))
    assert weight.shape == (100, 3) and pdf.shape == (100,)
    assert bsdf.pdf(wi[1], wo_s).shape == (100,)
    table = layersim.export(bsdf, tmp_path / "fig7d.bsdf")
    assert table.channels == 3 and table.eval(wi, wo).shape == (3, 3)
    assert bsdffile.read(tmp_path / "fig7d.bsdf").to_bsdf().eval(wi, wo).shape == (3, 3)
    img = plot.slice_images(bsdf, wi[1], resolution=16)["reflection"]
    assert img.shape == (16, 16, 3)


def test_each_channel_is_the_monochromatic_solve(fig7d):
    scene, bsdf = fig7d
    rng = np.random.default_rng(1)
    wi, wo = random_directions(rng, 200), random_directions(rng, 200)
    f = bsdf.eval(wi, wo)
    R, _ = bsdf.albedo(wi)
    bins = bsdf.bin_energies(wi[0], np.linspace(0, 1, 5), np.linspace(0, 2 * np.pi, 9))
    for c in range(3):
        mono = layersim.solve(scene.channel(c))
        np.testing.assert_allclose(f[:, c], mono.eval(wi, wo), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(R[:, c], mono.albedo(wi)[0], rtol=1e-12)
        np.testing.assert_allclose(bins["top"][..., c],
                                   mono.bin_energies(wi[0], np.linspace(0, 1, 5),
                                                     np.linspace(0, 2 * np.pi, 9))["top"],
                                   rtol=1e-12, atol=1e-15)


def test_gold_reflects_its_normal_incidence_fresnel_per_channel():
    """A bare rough gold conductor at normal incidence reflects F0 = ((n-1)^2 + k^2) /
    ((n+1)^2 + k^2) of each channel (single-scattering shadowing loses < 1e-3 at alpha 0.2)."""
    bsdf = layersim.solve(layersim.Scene.from_dict({"layer": [
        {"kind": "conductor", "ior": GOLD, "roughness": 0.2}]}))
    R, T = bsdf.albedo(unit(0.0))
    F0 = np.array([((n - 1) ** 2 + k ** 2) / ((n + 1) ** 2 + k ** 2) for n, k in GOLD])
    np.testing.assert_allclose(R, F0, atol=1e-3)
    assert R[0] > R[1] > R[2] and np.all(T == 0)


def test_blue_medium_reflects_and_transmits_more_where_it_absorbs_less():
    """Fig. 7d's medium alone: R and T grow with the single-scattering albedo, the absorbed
    fraction 1 - R - T shrinks; per channel as the monochromatic solve."""
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "medium", "albedo": [0.6, 0.8, 0.95], "g": 0.2, "tau": 1.0}]})
    bsdf = layersim.solve(scene)
    mono = layersim.solve(scene.channel(2))
    for theta in (0.0, 45.0, 135.0):
        R, T = bsdf.albedo(unit(theta))
        assert np.all(np.diff(R) > 0) and np.all(np.diff(T) > 0)
        assert np.all(np.diff(1 - R - T) < 0) and np.all(1 - R - T > 0)
        np.testing.assert_allclose(R[2], mono.albedo(unit(theta))[0], rtol=1e-12)
