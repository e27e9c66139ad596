"""The solved BSDF object: eval against the physics, energy bookkeeping, bins, persistence and
input checking."""

import numpy as np
import pytest

import layersim
from layersim import FileFormatError

from conftest import random_directions, unit
from test_physics import _eval_pairs


def test_eval_matches_the_microfacet_physics_in_reflection(rough_glass):
    rng = np.random.default_rng(0)
    wi = random_directions(rng, 5000, min_z=0.2)
    wo = random_directions(rng, 5000, min_z=0.2)
    ref = _eval_pairs(wi, wo, 1.5, 0.0, 0.3, 0.3, "beckmann")
    ours = rough_glass.eval(wi, wo)
    lobe = ref > 0.05 * ref.max()
    err = np.abs(ours[lobe] / ref[lobe] - 1)
    assert lobe.sum() > 50
    assert np.median(err) < 3e-4 and err.max() < 3e-3


def _transmission_error(n):
    bsdf = layersim.solve(layersim.Scene.from_dict({
        "layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.3}],
        "discretization": {"n": n}}))
    rng = np.random.default_rng(1)
    wi = random_directions(rng, 3000, min_z=0.2)
    wo = random_directions(rng, 3000, lower=True, min_z=0.2)
    ref = _eval_pairs(wi, wo, 1.5, 0.0, 0.3, 0.3, "beckmann")
    lobe = ref > 0.05 * ref.max()
    return np.percentile(np.abs(bsdf.eval(wi, wo)[lobe] / ref[lobe] - 1), 90)


def test_eval_in_transmission_converges_with_the_ordinates(rough_glass):
    coarse, fine = _transmission_error(66), _transmission_error(132)
    assert coarse < 0.05
    assert fine < coarse / 4   # cubic interpolation of a resolved lobe


def test_eval_broadcasts_and_handles_the_horizon(coated_gold):
    wi = unit(30.0)
    wo = unit(np.array([[10.0, 20.0, 40.0], [50.0, 60.0, 70.0]]), 180.0)
    f = coated_gold.eval(wi, wo)
    assert f.shape == (2, 3) and np.all(f > 0)
    assert coated_gold.eval(wi, np.array([1.0, 0.0, 0.0])) == 0.0
    # opaque stack: transmission and bottom reflection are left out -> zero
    assert coated_gold.eval(wi, unit(30.0, 180.0, below=True)) == 0.0


def test_albedo_and_bins_agree_and_cover_the_hemisphere(coated_gold, rough_glass):
    for bsdf, theta in ((coated_gold, 30.0), (rough_glass, 50.0), (rough_glass, 140.0)):
        wi = unit(theta, 25.0)
        R, T = bsdf.albedo(wi)
        bins = bsdf.bin_energies(wi, np.linspace(0, 1, 9), np.linspace(0, 2 * np.pi, 17))
        top, bottom = (R, T) if wi[2] > 0 else (T, R)
        assert bins["top"].shape == (8, 16)
        assert bins["top"].sum() == pytest.approx(float(top), rel=1e-12)
        assert bins["bottom"].sum() == pytest.approx(float(bottom), rel=1e-12)
        # cubic interpolation in the outgoing elevation may undershoot at a lobe's edge, by
        # far less than the discretisation error
        for side in ("top", "bottom"):
            assert bins[side].min() >= -1e-5 * bins[side].max()


def test_bins_follow_the_specular_direction(coated_gold):
    wi = unit(40.0, 30.0)
    bins = coated_gold.bin_energies(wi, np.linspace(0, 1, 21), np.linspace(0, 2 * np.pi, 37))
    k_mu, k_phi = np.unravel_index(np.argmax(bins["top"]), bins["top"].shape)
    assert 0.75 <= k_mu / 20 <= np.cos(np.radians(40.0)) <= (k_mu + 1) / 20
    assert k_phi * 10 <= 210 < (k_phi + 1) * 10   # mirror azimuth: 30 + 180 degrees


def test_lambertian_bins_follow_the_cosine_law():
    bsdf = layersim.solve(layersim.Scene.from_dict({"layer": [{"kind": "diffuse",
                                                                "albedo": 0.6}]}))
    mu_edges, phi_edges = np.linspace(0, 1, 6), np.linspace(0, 2 * np.pi, 5)
    bins = bsdf.bin_energies(unit(20.0), mu_edges, phi_edges)["top"]
    exact = 0.6 * np.outer(np.diff(mu_edges ** 2), np.diff(phi_edges) / (2 * np.pi))
    np.testing.assert_allclose(bins, exact, rtol=1e-12)


@pytest.mark.parametrize("theta, phi, forward", [(35.0, 60.0, (8, 8)), (0.0, 0.0, (9, 6))])
def test_unscattered_light_lands_in_the_forward_bin(theta, phi, forward):
    scene = layersim.Scene.from_dict({"layer": [{"kind": "medium", "albedo": 0.5,
                                                 "tau": 0.3}]})
    bsdf = layersim.solve(scene)
    wi = unit(theta, phi)
    R, T = bsdf.albedo(wi)
    direct = np.exp(-0.3 / np.cos(np.radians(theta)))
    assert T > direct
    bins = bsdf.bin_energies(wi, np.linspace(0, 1, 11), np.linspace(0, 2 * np.pi, 13))
    assert bins["bottom"].sum() == pytest.approx(float(T), rel=1e-12)
    # the forward bin holds the delta: mu = cos 35 in [0.8, 0.9), phi = 240 deg in [240, 270);
    # at normal incidence mu = 1 (the closed top edge), phi = 180 deg in [180, 210)
    assert bins["bottom"][forward] > direct
    assert bins["bottom"][forward] - direct < 0.05


def test_rgb_scenes_carry_a_channel_axis():
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "medium", "albedo": [0.6, 0.8, 0.95], "g": 0.2, "tau": 1.0},
        {"kind": "diffuse", "albedo": [0.2, 0.5, 0.9]}]})
    bsdf = layersim.solve(scene)
    assert bsdf.channels == 3
    R, T = bsdf.albedo(unit([0.0, 60.0]))
    assert R.shape == (2, 3) and np.all(np.diff(R, axis=-1) > 0)   # bluer is brighter
    assert bsdf.eval(unit(10.0), unit(20.0, 180.0)).shape == (3,)
    mono = layersim.solve(scene.channel(1))
    np.testing.assert_allclose(mono.albedo(unit(60.0))[0], R[1, 1], rtol=1e-12)


def test_save_and_load_round_trip(tmp_path, coated_gold):
    path = coated_gold.save(tmp_path / "gold.lsim")
    again = layersim.BSDF.load(path)
    rng = np.random.default_rng(2)
    wi, wo = random_directions(rng, 100), random_directions(rng, 100)
    np.testing.assert_array_equal(again.eval(wi, wo), coated_gold.eval(wi, wo))
    assert again.info["n"] == coated_gold.info["n"]
    (tmp_path / "junk.lsim").write_bytes(b"not a bsdf")
    with pytest.raises(FileFormatError):
        layersim.BSDF.load(tmp_path / "junk.lsim")


@pytest.mark.parametrize("wi,wo,match", [
    (np.array([0.0, 0.0, 2.0]), np.array([0.0, 0.0, 1.0]), "unit vectors"),
    (np.array([0.0, 1.0]), np.array([0.0, 0.0, 1.0]), "shape"),
    (np.array([0.0, 0.0, np.nan]), np.array([0.0, 0.0, 1.0]), "non-finite"),
])
def test_eval_rejects_bad_directions(coated_gold, wi, wo, match):
    with pytest.raises(ValueError, match=match):
        coated_gold.eval(wi, wo)


def test_energy_queries_reject_impossible_light(coated_gold):
    with pytest.raises(ValueError, match="opaque"):
        coated_gold.albedo(unit(20.0, below=True))
    with pytest.raises(ValueError, match="horizon"):
        coated_gold.albedo(np.array([1.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="increasing"):
        coated_gold.bin_energies(unit(20.0), [0.0, 0.5, 0.4], [0, 1])
    with pytest.raises(ValueError, match="within"):
        coated_gold.bin_energies(unit(20.0), [0.0, 1.5], [0, 1])
