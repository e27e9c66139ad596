"""The Fourier solver against the Monte Carlo reference: same per-layer physics, so differences
measure discretisation error, which must stay within the Monte Carlo standard errors."""

import numpy as np
import pytest

import layersim
import layersim.montecarlo as mc

from conftest import unit

MU_EDGES = np.linspace(0.0, 1.0, 9)
PHI_EDGES = np.linspace(0.0, 2 * np.pi, 13)
GOLD = [0.143552, 3.98397]


def compare(scene, wi, particles, seed=11, min_fraction=0.99):
    bsdf = layersim.solve(scene)
    res = mc.simulate(scene, wi, particles, mu_edges=MU_EDGES, phi_edges=PHI_EDGES,
                      backend="warp-cpu", seed=seed)
    R, T = bsdf.albedo(wi)
    bins = bsdf.bin_energies(wi, MU_EDGES, PHI_EDGES)
    top, bottom = (float(R), float(T)) if wi[2] > 0 else (float(T), float(R))
    mc_top, mc_bot = ((res.reflectance, res.transmittance) if wi[2] > 0
                      else (res.transmittance, res.reflectance))
    err_top, err_bot = ((res.reflectance_stderr, res.transmittance_stderr) if wi[2] > 0
                        else (res.transmittance_stderr, res.reflectance_stderr))
    assert abs(top - mc_top) <= 4 * err_top + 1e-12
    assert abs(bottom - mc_bot) <= 4 * err_bot + 1e-12
    # with the Poisson floor of nearly empty bins (MCResult.z_scores)
    z = np.concatenate([res.z_scores(side, bins[side]) for side in ("top", "bottom")])
    assert z.size > 20
    assert np.mean(z <= 4.0) >= min_fraction, (np.sort(z)[-5:], z.size)
    return z


@pytest.mark.slow
def test_single_rough_interface_bins_agree_within_4_sigma():
    # The transmitted lobe is a ridge mu_o = T(mu_i) that moves quickly with the incident
    # elevation (slope eta^2 mu_i / mu_t leaving the glass): interpolating between incident
    # ordinates needs n ~ 200 for Monte Carlo accuracy at 1e6 paths (the planner's n = 66 for
    # alpha = 0.3 is within ~2 % in the main bins; benchmarks/ reports error against n).
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.3}],
        "discretization": {"n": 200}})
    compare(scene, unit(30.0, 40.0), 1_000_000, min_fraction=1.0)
    compare(scene, unit(150.0, 10.0), 1_000_000, min_fraction=1.0)   # lit from inside


def test_rough_conductor_bins_agree_within_4_sigma():
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "conductor", "ior": GOLD, "roughness": 0.2, "distribution": "ggx"}]})
    compare(scene, unit(50.0), 500_000, min_fraction=1.0)


def test_hg_slab_against_the_solver():
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "medium", "albedo": 0.95, "g": 0.5, "tau": 2.0}]})
    compare(scene, unit(35.0, 60.0), 500_000)


def test_coated_diffuse_in_99_percent_of_bins():
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.2},
        {"kind": "medium", "albedo": 0.9, "g": 0.3, "tau": 0.5},
        {"kind": "diffuse", "albedo": 0.6}]})
    compare(scene, unit(20.0), 500_000)


def test_coated_rough_conductor_in_99_percent_of_bins(coated_gold):
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.1},
        {"kind": "conductor", "ior": GOLD, "roughness": 0.1}]})
    compare(scene, unit(45.0, 100.0), 500_000)
