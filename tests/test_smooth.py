"""Exact smooth interfaces (roughness 0): deltas in the adding equations, smooth conductors,
smooth dielectric boundaries on the Snell-matched grid (layersim.operators.deltas,
layersim.solved.boundary)."""

import numpy as np
import pytest

import layersim
from layersim.errors import InfeasibleError
from layersim.kernels.fresnel import fresnel


def _fext(eta):
    x, v = np.polynomial.legendre.leggauss(400)
    x, v = 0.5 * (x + 1), 0.5 * v
    return float(np.sum(2 * x * fresnel(x, eta) * v))


def _coated_lambert(rho, eta=1.5):
    return layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": eta, "roughness": 0},
        {"kind": "diffuse", "albedo": rho}]})


def _dirs(deg, phi=0.0):
    th = np.radians(np.asarray(deg, float))
    return np.stack([np.sin(th) * np.cos(phi), np.sin(th) * np.sin(phi), np.cos(th)], -1)


@pytest.mark.parametrize("rho", [0.5, 1.0])
def test_smooth_coating_over_lambert_closed_form(rho):
    """R(mu) = F + (1 - F) rho (1 - F_int) / (1 - rho F_int), F_int = 1 - (1 - F_ext) / eta^2,
    to 1e-4 for incidence 0..85 deg; eval matches (1 - F_i)(1 - F_o)/eta^2 rho / (pi (1 - rho
    F_int)); the specular part is F."""
    eta = 1.5
    bsdf = layersim.solve(_coated_lambert(rho, eta))
    deg = np.linspace(0, 85, 35)
    wi = _dirs(deg)
    F = fresnel(np.cos(np.radians(deg)), eta)
    fint = 1 - (1 - _fext(eta)) / eta**2
    R, T = bsdf.albedo(wi)
    assert np.abs(R - (F + (1 - F) * rho * (1 - fint) / (1 - rho * fint))).max() < 1e-4
    assert np.all(T == 0)
    spec = bsdf.specular(wi)
    assert np.allclose(spec["top"][0], F, atol=1e-12)
    assert np.allclose(spec["top"][1], wi * [-1, -1, 1])
    wo = _dirs(deg[::-1] * 0.9, phi=1.0)
    Fo = fresnel(wo[:, 2], eta)
    f_ref = (1 - F) * (1 - Fo) / eta**2 * rho / (np.pi * (1 - rho * fint))
    assert np.allclose(bsdf.eval(wi, wo), f_ref, rtol=1e-4, atol=1e-7)


def test_smooth_coating_bins_sum_to_albedo():
    bsdf = layersim.solve(_coated_lambert(0.7))
    wi = _dirs(30.0)
    E = bsdf.bin_energies(wi, np.linspace(0, 1, 9), np.linspace(0, 2 * np.pi, 13))
    R, _ = bsdf.albedo(wi)
    assert abs(E["top"].sum() - R) < 1e-9
    spec = bsdf.specular(wi)["top"][0]
    # the mirror direction (mu = cos 30 deg, phi = pi) holds the specular energy on top of the
    # smooth part
    k = np.searchsorted(np.linspace(0, 1, 9), np.cos(np.radians(30))) - 1
    assert E["top"][k, 6] > spec


def test_smooth_conductor_is_its_fresnel_delta():
    eta, k = 0.2, 3.0
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "conductor", "ior": [eta, k], "roughness": 0}]})
    bsdf = layersim.solve(scene)
    wi = _dirs([0, 40, 80])
    R, _ = bsdf.albedo(wi)
    F = fresnel(wi[:, 2], eta, k)
    # linear interpolation between the ordinates of the exact node values
    assert np.allclose(R, F, atol=2e-4)
    assert np.allclose(bsdf.specular(wi)["top"][0], R)
    assert np.all(bsdf.eval(wi, wi * [-1, -1, 1]) == 0)     # no lobe: the delta is not smeared
    with pytest.raises(InfeasibleError, match="delta"):
        layersim.export(bsdf, "/tmp/never-written.bsdf")


def test_interior_smooth_dielectric_refused():
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.2},
        {"kind": "dielectric", "ior": 1.3, "roughness": 0},
        {"kind": "diffuse", "albedo": 0.5}]})
    with pytest.raises(InfeasibleError, match="layer 1 .*inside the stack"):
        layersim.solve(scene)


def test_smooth_slab_closed_form():
    """A non-scattering absorbing slab between two smooth interfaces in air against its closed
    form (incoherent multiple reflections), 0..89 deg: T is all straight-through delta."""
    tau, eta = 0.5, 1.5
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": eta, "roughness": 0},
        {"kind": "medium", "albedo": 0.0, "g": 0.0, "tau": tau},
        {"kind": "dielectric", "ior": 1.0, "roughness": 0}]})
    bsdf = layersim.solve(scene)
    deg = np.linspace(0.0, 89.0, 90)
    wi = _dirs(deg)
    F = fresnel(wi[:, 2], eta)
    mu_in = np.sqrt(1 - (1 - wi[:, 2] ** 2) / eta**2)
    a = np.exp(-tau / mu_in)
    T_ref = (1 - F) ** 2 * a / (1 - F**2 * a**2)
    R_ref = F + (1 - F) ** 2 * F * a**2 / (1 - F**2 * a**2)
    R, T = bsdf.albedo(wi)
    spec = bsdf.specular(wi)
    assert np.allclose(spec["bottom"][0], T_ref, atol=1e-4, rtol=0)
    assert np.allclose(T, spec["bottom"][0], atol=1e-12)
    assert np.allclose(R, R_ref, atol=1e-4, rtol=0)
    assert np.allclose(spec["bottom"][1], -wi, atol=1e-9)


MU_EDGES = np.linspace(0.0, 1.0, 9)
PHI_EDGES = np.linspace(0.0, 2 * np.pi, 13)
GOLD = [0.143552, 3.98397]
MC_SCENES = {
    "coated_gold": [{"kind": "dielectric", "ior": 1.5, "roughness": 0},
                    {"kind": "conductor", "ior": GOLD, "roughness": 0.2}],
    "coated_hg_diffuse": [{"kind": "dielectric", "ior": 1.5, "roughness": 0},
                          {"kind": "medium", "albedo": 0.9, "g": 0.5, "tau": 1.0},
                          {"kind": "diffuse", "albedo": 0.6}],
    "smooth_slab": [{"kind": "dielectric", "ior": 1.5, "roughness": 0},
                    {"kind": "medium", "albedo": 0.95, "g": 0.3, "tau": 1.0},
                    {"kind": "dielectric", "ior": 1.0, "roughness": 0}],
}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(MC_SCENES))
def test_smooth_stacks_agree_with_monte_carlo(name):
    """Albedos within 4 standard errors, bin energies (specular deltas in their bins) within 3
    sigma in >= 99 % of the populated bins, at 5e5 paths
    (benchmarks/features/smooth_vs_mc.py: 1e7)."""
    import layersim.montecarlo as mc
    scene = layersim.Scene.from_dict({"layer": MC_SCENES[name]})
    bsdf = layersim.solve(scene)
    paths = 500_000
    for theta in (25.0, 70.0):
        wi = _dirs(theta, phi=0.3)
        res = mc.simulate(scene, wi, paths, mu_edges=MU_EDGES, phi_edges=PHI_EDGES,
                          backend="warp-cpu", seed=3)
        R, T = (float(x) for x in bsdf.albedo(wi))
        assert abs(R - res.reflectance) <= 4 * res.reflectance_stderr + 1e-12
        assert abs(T - res.transmittance) <= 4 * res.transmittance_stderr + 1e-12
        bins = bsdf.bin_energies(wi, MU_EDGES, PHI_EDGES)
        z = np.concatenate([res.z_scores(side, bins[side]) for side in ("top", "bottom")])
        assert z.size > 50
        assert np.mean(z <= 3.0) >= 0.99, (theta, np.sort(z)[-5:])


def test_boundary_survives_save_and_load_and_refuses_stack_algebra(tmp_path):
    from layersim.errors import OperatorError
    bsdf = layersim.solve(_coated_lambert(0.5))
    path = bsdf.save(tmp_path / "coated.npz")
    back = layersim.BSDF.load(path)
    wi = _dirs([10.0, 70.0])
    assert np.allclose(back.albedo(wi)[0], bsdf.albedo(wi)[0], atol=1e-15)
    assert back.boundary == bsdf.boundary == {"top": 1.0}
    glass = layersim.solve(layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.3}]}), like=bsdf)
    with pytest.raises(OperatorError, match="smooth dielectric boundary"):
        layersim.add(glass, bsdf)


def test_mirror_delta_through_both_adding_functions():
    """A non-scattering slab over a smooth conductor: the stack's mirror delta is
    F(mu) exp(-2 tau / mu) in the isotropic and in the coupled adding (layersim.operators.deltas), and
    albedo and specular agree with it."""
    from layersim.ingredients import medium_operator
    from layersim.ingredients.smooth import smooth_conductor_operator
    from layersim.operators.operator import Grid
    tau = 0.3
    grid = Grid.make("gauss-lobatto", 32)
    slab = medium_operator(grid, 4, 0.0, 0.0, tau, 1.0)
    metal = smooth_conductor_operator(grid, 4, complex(*GOLD), 1.0)
    expect = fresnel(grid.mu, *GOLD) * np.exp(-2 * tau / grid.mu)
    from layersim.errors import OperatorError
    with pytest.raises(OperatorError, match="mirror"):
        layersim.subtract(layersim.add(slab, metal), metal, side="bottom")
    for stack in (layersim.add(slab, metal),
                  layersim.add(slab.as_coupled(), metal.as_coupled())):
        assert np.allclose(stack.delta["Rt"], expect, rtol=1e-12)
        assert np.allclose(stack.albedo()["Rt"], expect, rtol=1e-12)
        bsdf = layersim.BSDF([stack])
        wi = _dirs([0.0, 30.0])
        assert np.allclose(bsdf.specular(wi)["top"][0], bsdf.albedo(wi)[0], rtol=1e-12)
        assert np.allclose(bsdf.eval(wi, wi * [-1, -1, 1]), 0.0, atol=1e-9)


@pytest.mark.slow
def test_smooth_coating_over_anisotropic_gold_albedo_agrees_with_monte_carlo():
    """The coupled representation under a smooth boundary: the boundary's transmittance is
    applied per incident azimuth (AnisoEvaluator.node_energy). Albedos within 4 standard errors
    at 3e5 paths; the bins are as accurate as the coupled operator's own (not tested here)."""
    import layersim.montecarlo as mc
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0},
        {"kind": "conductor", "ior": GOLD, "roughness": [0.1, 0.3]}]})
    bsdf = layersim.solve(scene)
    assert bsdf.anisotropic
    for theta, phi in ((25.0, 0.0), (60.0, 1.2)):
        wi = _dirs(theta, phi)
        res = mc.simulate(scene, wi, 300_000, backend="warp-cpu", seed=5)
        R, T = bsdf.albedo(wi)
        assert abs(float(R) - res.reflectance) <= 4 * res.reflectance_stderr
        E = bsdf.bin_energies(wi, np.linspace(0, 1, 5), np.linspace(0, 2 * np.pi, 7))
        assert abs(E["top"].sum() - float(R)) < 1e-9


def test_smooth_coating_over_smooth_gold_closed_form():
    """All deltas: R = F + (1 - F)^2 R_g / (1 - F R_g) with R_g the gold Fresnel reflectance
    at the refracted angle (layersim.operators.deltas with the boundary), 3e-5 to 80 deg, 2e-4 to
    89."""
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0},
        {"kind": "conductor", "ior": GOLD, "roughness": 0}]})
    bsdf = layersim.solve(scene)
    deg = np.linspace(0, 89, 90)
    wi = _dirs(deg)
    F = fresnel(wi[:, 2], 1.5)
    mu = np.sqrt(1 - (1 - wi[:, 2] ** 2) / 1.5**2)
    Rg = fresnel(mu, GOLD[0] / 1.5, GOLD[1] / 1.5)
    ref = F + (1 - F) ** 2 * Rg / (1 - F * Rg)
    R, _ = bsdf.albedo(wi)
    err = np.abs(R - ref)
    assert err[deg <= 80].max() < 3e-5 and err.max() < 2e-4
    assert np.allclose(bsdf.specular(wi)["top"][0], R, atol=1e-14)


def test_sampling_through_a_smooth_boundary_is_unbiased():
    """BoundarySampler: the mean weight estimates the smooth part of the albedo (R minus the
    specular part) within 4 standard errors, and pdf() agrees with the density of sample()."""
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0},
        {"kind": "medium", "albedo": 0.95, "g": 0.3, "tau": 1.0},
        {"kind": "dielectric", "ior": 1.0, "roughness": 0}]})
    bsdf = layersim.solve(scene)
    u = np.random.default_rng(4).random((100_000, 2))
    for theta in (20.0, 70.0):
        wi = _dirs(theta, 0.4)
        wo, weight, pdf = bsdf.sample(wi, u)
        R, T = bsdf.albedo(wi)
        spec = bsdf.specular(wi)
        for sel, ref in ((wo[:, 2] > 0, R - spec["top"][0]), (wo[:, 2] < 0, T - spec["bottom"][0])):
            w = np.where(sel, weight, 0.0)
            assert abs(w.mean() - ref) <= 4 * w.std() / np.sqrt(w.size)
        ok = np.flatnonzero(pdf > 0)[:500]
        assert np.allclose(bsdf.pdf(wi, wo[ok]), pdf[ok], rtol=1e-10)


def test_bad_smooth_boundaries_are_refused_with_the_layer_and_field():
    lam = {"kind": "diffuse", "albedo": 0.5}
    with pytest.raises(InfeasibleError, match=r"\[discretization\] n = 8"):
        layersim.make_plan(layersim.Scene.from_dict({
            "layer": [{"kind": "dielectric", "ior": 1.5}, lam], "discretization": {"n": 8}}))
    with pytest.raises(InfeasibleError, match="layer 0 .*denser medium inside"):
        layersim.make_plan(layersim.Scene.from_dict({
            "stack": {"top_ior": 1.6}, "layer": [{"kind": "dielectric", "ior": 1.5}, lam]}))
    with pytest.raises(InfeasibleError, match="layer 0 .*same index in every channel"):
        layersim.make_plan(layersim.Scene.from_dict({
            "layer": [{"kind": "dielectric", "ior": [1.5, 1.52, 1.55]}, lam]}))


def test_rotational_average_keeps_the_smooth_boundary():
    """The rotational average of a coupled stack under a smooth coating is evaluated outside
    the boundary too: its albedo is the incident-azimuth average of the stack's (the average
    keeps the order-0 coupling exactly and the boundary's transmittance does not depend on
    the azimuth; 64 azimuths integrate the stack's modes exactly)."""
    bsdf = layersim.solve(layersim.Scene.from_dict({
        "discretization": {"n": 24, "md": 9},
        "layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0},
                  {"kind": "conductor", "ior": GOLD, "roughness": [0.2, 0.4]}]}))
    avg = bsdf.rotational_average()
    assert bsdf.anisotropic and not avg.anisotropic and avg.boundary == bsdf.boundary
    for theta in (0.0, 40.0, 70.0):
        wi = _dirs(np.full(64, theta), phi=np.linspace(0.0, 2 * np.pi, 64, endpoint=False))
        R, T = bsdf.albedo(wi)
        R_avg, T_avg = avg.albedo(_dirs(theta))
        assert abs(R_avg - R.mean()) < 1e-12 and T_avg == 0.0 == T.max(), theta
