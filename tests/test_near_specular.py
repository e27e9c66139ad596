"""Near-specular rough coats (layersim.solved.lobe): the split against the physics and Monte Carlo."""

import numpy as np
import pytest

import layersim
from layersim.kernels.fresnel import fresnel
from layersim.kernels.projection import microfacet_values
from layersim.solved.lobe import NEAR_SPECULAR_ALPHA, NearSpecularLobe
from layersim.plan import make_plan

GOLD = [0.143552, 3.98397]


def _scene(rough):
    return layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": rough},
        {"kind": "conductor", "ior": GOLD, "roughness": 0.2}]})


def _dir(theta_deg, phi=0.35):
    t = np.radians(theta_deg)
    return np.array([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi), np.cos(t)])


def test_lobe_is_the_projection_physics_and_its_energies_sum_to_its_integral():
    """eval equals the projection kernels' microfacet BSDF; the reflected energy equals the
    integral of eval * cos over a fine grid around the mirror direction, and tends to F."""
    lobe = NearSpecularLobe(1.5, 0.02, 0.02, "beckmann")
    mu_i, mu_o = np.array([0.8, 0.8]), np.array([-0.8, -0.75])
    phi = np.array([[0.0, 0.01], [0.0, 0.02]])
    ref = microfacet_values(mu_i, mu_o, phi, 1.5, 0.02, 0.02)
    wi = np.array([[-0.6, 0.0, 0.8]] * 2)
    so = np.sqrt(1 - mu_o**2)
    for j in range(2):
        wo = np.stack([so * np.cos(phi[:, j]), so * np.sin(phi[:, j]), -mu_o], axis=1)
        assert np.allclose(lobe.eval(wi, wo), ref[:, j], rtol=1e-12)
    # reflected energy at 40 degrees: integral of the lobe in a 0.3 rad patch (slopes to 7 sigma)
    w = _dir(40.0, 0.0)
    u = np.linspace(-0.3, 0.3, 601)
    du = u[1] - u[0]
    ux, uy = np.meshgrid(u, u)
    mirror = np.array([-w[0], -w[1], w[2]])
    e1 = np.array([mirror[2], 0.0, -mirror[0]])
    d = mirror[None] + ux.reshape(-1, 1) * e1 + uy.reshape(-1, 1) * np.array([0.0, 1.0, 0.0])
    wo = d / np.linalg.norm(d, axis=1)[:, None]
    jac = 1.0 / np.linalg.norm(d, axis=1) ** 3           # solid angle of the tangent-plane cell
    f = lobe.eval(np.repeat(w[None], wo.shape[0], 0), wo)
    integral = np.sum(f * wo[:, 2] * jac) * du * du
    R, T = lobe.energies(w[None])
    assert abs(integral - R[0]) < 1e-4 * R[0]
    assert abs(R[0] - fresnel(w[2], 1.5)) < 1e-4 and abs(R[0] + T[0] - 1) < 1e-4


def test_plan_splits_near_specular_coats_and_projects_rougher_ones():
    plan = make_plan(_scene([0.001, 0.01]))
    assert plan.near_specular == (0,) and plan.lobes["top"]["alpha_v"] == 0.01
    assert "near-specular split" in plan.report() and "Monte Carlo" in plan.report()
    assert plan.memory_bytes < 2**31
    rough = make_plan(_scene(2 * NEAR_SPECULAR_ALPHA))
    assert rough.near_specular == () and rough.layers[0].action == "project"
    # over a smooth base the refraction blur would be seen: no split (exact, or refused)
    mirror = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.005},
        {"kind": "conductor", "ior": GOLD, "roughness": 0}]})
    assert make_plan(mirror, refuse=False).near_specular == ()


def _agrees_with_monte_carlo(scene, bsdf, wi, seed: int, slack: float,
                             paths: int = 1_000_000) -> float:
    """Albedo within 4 standard errors of ``paths`` walks plus ``slack`` (the split's measured
    error), bins within 3 sigma in >= 97 % of the populated 9 x 12 bins, bins summing to the
    albedo; returns the albedo."""
    import layersim.montecarlo as mc
    mu_edges, phi_edges = np.linspace(0, 1, 10), np.linspace(0, 2 * np.pi, 13)
    res = mc.simulate(scene, wi, paths, mu_edges=mu_edges, phi_edges=phi_edges,
                      backend="warp-cpu", seed=seed)
    R = float(bsdf.albedo(wi)[0])
    assert abs(R - res.reflectance) <= 4 * res.reflectance_stderr + slack
    bins = bsdf.bin_energies(wi, mu_edges, phi_edges)["top"]
    assert abs(bins.sum() - R) < 2e-3
    z = res.z_scores("top", bins)
    assert z.size > 50 and np.mean(z <= 3.0) >= 0.97, np.sort(z)[-5:]
    return R


@pytest.mark.slow
def test_near_specular_coat_agrees_with_monte_carlo_and_survives_save(tmp_path):
    """alpha 0.005 over rough gold at 40 degrees: albedo within 4 standard errors of 1e6
    paths plus the split's measured error at this roughness (benchmarks/features/near_specular.txt:
    5e-5), bins within 3 sigma in >= 97 % of the populated 9 x 12 bins."""
    scene = _scene(0.005)
    bsdf = layersim.solve(scene)
    wi = _dir(40.0)
    R = _agrees_with_monte_carlo(scene, bsdf, wi, seed=7, slack=1e-4)
    back = layersim.BSDF.load(bsdf.save(tmp_path / "ns.npz"))
    assert back.lobes == bsdf.lobes and back.lobes[0]
    assert np.allclose(back.albedo(wi)[0], R, atol=1e-14)
    _check_sampling(bsdf, wi)


def _check_sampling(bsdf, wi, count=10000):
    """Sampling a near-specular BSDF (layersim.solved.sampling.LobeSampler): pdf(wi, wo) is the
    density returned with each sample, the weight is eval |wo.z| / pdf, and the mean weight
    estimates the energy outside the deltas within 4 standard errors."""
    u = np.random.default_rng(5).random((count, 2))
    wo, weight, pdf = bsdf.sample(wi, u)
    ok = pdf > 0       # inside a smooth boundary, directions under TIR leave nowhere
    assert ok.mean() > 0.5
    assert np.allclose(bsdf.pdf(wi, wo[ok]), pdf[ok], rtol=1e-9)
    f = bsdf.eval(np.broadcast_to(wi, wo[ok].shape), wo[ok])
    assert np.allclose(weight[ok], f * np.abs(wo[ok, 2]) / pdf[ok], rtol=1e-9)
    R, T = bsdf.albedo(wi)
    deltas = sum(float(e) for e, _ in bsdf.specular(wi).values())
    target = float(R) + float(T) - deltas
    mean, se = weight.mean(), weight.std() / np.sqrt(count)
    assert abs(mean - target) <= 4 * se + 1e-6, (mean, se, target)


def _gold(rough, coat=None):
    layers = [] if coat is None else [{"kind": "dielectric", "ior": 1.5, "roughness": coat}]
    return layersim.Scene.from_dict({"layer": [
        *layers, {"kind": "conductor", "ior": GOLD, "roughness": rough}]})


@pytest.mark.parametrize("rough", [0.005, [0.001, 0.01]])
def test_bare_near_specular_conductor_is_its_exact_lobe(tmp_path, rough):
    """Alone, a near-specular conductor (refused for memory by the exact projection: n ~ 1 /
    alpha) is a mirror of the rough reflectance in the solve, and eval / albedo / bins are
    its microfacet lobe: eval equals the physics at and beside the peak, the albedo equals
    the lobe's reflected energy (close to the smooth Fresnel reflectance), nothing is
    left as a delta, and the bins hold the albedo; saving keeps the lobe."""
    scene = _gold(rough)
    plan = make_plan(scene)
    assert plan.near_specular == (0,) and "near-specular conductor" in plan.report()
    assert plan.memory_bytes < 2**28
    bsdf = layersim.solve(scene)
    au, av = (rough, rough) if np.isscalar(rough) else rough
    lobe = NearSpecularLobe(GOLD[0], au, av, "beckmann", k=GOLD[1])
    for theta in (0.0, 30.0, 75.0):
        wi = _dir(theta)
        mirror = wi * np.array([-1.0, -1.0, 1.0])
        beside = mirror + np.array([0.3 * au, 0.2 * av, 0.0])
        wo = np.stack([mirror, beside / np.linalg.norm(beside)])
        f = bsdf.eval(np.stack([wi, wi]), wo)
        assert np.allclose(f, lobe.eval(np.stack([wi, wi]), wo), rtol=1e-12) and f[0] > 1e3
        R, T = bsdf.albedo(wi)
        assert abs(float(R) - lobe.energies(wi[None])[0][0]) < 1e-12 and float(T) == 0.0
        assert abs(float(R) - fresnel(wi[2], GOLD[0], GOLD[1])) < 1e-3
        assert float(bsdf.specular(wi)["top"][0]) == 0.0
        bins = bsdf.bin_energies(wi, np.linspace(0, 1, 10), np.linspace(0, 2 * np.pi, 13))
        assert abs(bins["top"].sum() - float(R)) < 1e-9
    assert abs(float(bsdf.albedo(_dir(0.0))[0]) - fresnel(1.0, GOLD[0], GOLD[1])) < 1e-4
    _check_sampling(bsdf, _dir(30.0))
    back = layersim.BSDF.load(bsdf.save(tmp_path / "gold.npz"))
    assert back.lobes == bsdf.lobes and back.lobes[0]
    assert np.allclose(back.eval(_dir(30.0), _dir(30.0) * [-1, -1, 1]),
                       bsdf.eval(_dir(30.0), _dir(30.0) * [-1, -1, 1]), rtol=1e-12)


def test_near_specular_conductor_behind_a_smooth_coat_is_not_a_mirror():
    """Behind a smooth coat nothing blurs the conductor's lobe (and near the coat's critical
    angle part of it is trapped): the mirror is not used. With clear media only, the stack is
    solved as specular paths (layersim.specular_paths); with a scattering medium the exact
    projection's refusal says why and what to use."""
    from layersim.specular_paths import SpecularPathsBSDF
    assert isinstance(layersim.solve(_gold(0.005, coat=0.0)), SpecularPathsBSDF)
    milky = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.0},
        {"kind": "medium", "albedo": 0.5, "tau": 0.1},
        {"kind": "conductor", "ior": GOLD, "roughness": 0.005}]})
    with pytest.raises(layersim.InfeasibleError, match="no rough interface above it"):
        layersim.solve(milky)


@pytest.mark.slow
def test_near_specular_conductor_under_a_rough_coat_agrees_with_monte_carlo():
    """Gold of alpha 0.005 under a coat of alpha 0.1 at 30 degrees: albedo within 4 standard
    errors of 1e6 paths (plus 2e-4: the mirror's measured error,
    benchmarks/features/near_specular.txt), bins within 3 sigma in >= 97 % of the populated
    9 x 12 bins."""
    scene = _gold(0.005, coat=0.1)
    assert make_plan(scene).near_specular == (1,)
    _agrees_with_monte_carlo(scene, layersim.solve(scene), _dir(30.0), seed=11, slack=2e-4)


def test_near_specular_conductor_with_energy_compensation_is_refused():
    """The mirror and its lobe have no compensation term: asking for one is an error naming
    the layer and the field, not a silent omission."""
    scene = {"stack": {"energy_compensation": "multiple-scattering"},
             "layer": [{"kind": "conductor", "ior": GOLD, "roughness": 0.005}]}
    with pytest.raises(layersim.InfeasibleError, match="layer 0.*energy_compensation"):
        layersim.solve(scene)
