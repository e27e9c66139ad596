"""Energy-loss compensation (layersim.compensation): tables against closed forms, conservation,
reciprocity, layerlab's defining property, bad input, and the solver against the walk."""
import os

import numpy as np
import pytest

import layersim
from layersim import config
from layersim.compensation import lobes_for, tables
from layersim.errors import InfeasibleError, SceneError
from layersim.scene import Conductor, Scene

ANGLES = np.radians(np.arange(0, 86, 5))


def directions(side=1.0):
    return np.stack([np.sin(ANGLES), 0 * ANGLES, side * np.cos(ANGLES)], -1)


def fresnel(mu, eta):
    st2 = (1 - mu ** 2) / eta ** 2
    ct = np.sqrt(np.maximum(1 - st2, 0))
    rs = (mu - eta * ct) / (mu + eta * ct)
    rp = (eta * mu - ct) / (eta * mu + ct)
    return np.where(st2 >= 1, 1.0, 0.5 * (rs ** 2 + rp ** 2))


def test_tables_reach_fresnel_in_the_smooth_limit():
    a = tables.albedos(1.5, 0.0, 0.005, "beckmann")
    mu = tables.nodes()[:161]                          # 0-80 degrees
    assert np.abs(a.r_top[:161] + a.t_top[:161] - 1).max() < 1e-9
    assert np.abs(a.r_top[:161] - fresnel(mu, 1.5)).max() < 2e-4
    # from inside: Fresnel with the inverted index, total internal reflection beyond 41.8 deg
    # (the roughness blurs the steep rise just below it)
    away = np.abs(np.degrees(np.arccos(mu)) - np.degrees(np.arcsin(1 / 1.5))) > 2
    assert np.abs(a.r_bottom[:161] - fresnel(mu, 1 / 1.5))[away].max() < 1e-3


def test_tables_match_the_solvers_projection():
    scene = layersim.Scene.from_dict({"layer": [{"kind": "conductor", "ior": [1.0, 100.0],
                                                 "roughness": 0.5}]})
    op = layersim.solve(scene).operators[0]
    a = tables.albedos(1.0, 100.0, 0.5, "beckmann")
    mu = op.grid.mu[op.grid.mu > 0.1]
    alb = op.albedo()["Rt"][op.grid.mu > 0.1]
    assert np.abs(tables.interpolate(a.r_top, mu) - alb).max() < 1e-3


@pytest.mark.parametrize("dist, alpha", [("beckmann", 0.1), ("ggx", 0.6), ("beckmann", 1.0)])
def test_perfect_mirror_conserves_energy(dist, alpha):
    # k = 1e6 (beyond the scene file's guard rail): Fresnel 1 - O(1e-6), F_avg = 1 - 4e-12
    layer = Conductor(ior=complex(1.0, 1e6), alpha_u=alpha, alpha_v=alpha, distribution=dist,
                      energy_compensation="multiple-scattering")
    r, _ = layersim.solve(Scene(stacks=((layer,),))).albedo(directions())
    assert np.abs(r - 1).max() < 1e-9, r
    plain = Conductor(ior=complex(1.0, 1e6), alpha_u=alpha, alpha_v=alpha, distribution=dist)
    r, _ = layersim.solve(Scene(stacks=((plain,),))).albedo(directions())
    assert np.abs(r - 1).max() > 0.02                                  # the loss it fills


@pytest.mark.parametrize("dist, alpha, eta", [("beckmann", 0.5, 1.5), ("ggx", 0.3, 2.2),
                                              ("beckmann", 0.1, 3.0), ("ggx", 1.0, 1.1)])
def test_rough_dielectric_conserves_energy_from_both_sides(dist, alpha, eta):
    scene = layersim.Scene.from_dict({"stack": {"energy_compensation": "multiple-scattering"},
                                      "layer": [{"kind": "dielectric", "ior": eta,
                                                 "roughness": alpha, "distribution": dist}]})
    bsdf = layersim.solve(scene)
    for side in (1.0, -1.0):
        r, t = bsdf.albedo(directions(side))
        assert np.abs(r + t - 1).max() < 1e-9, (side, r + t)


@pytest.mark.parametrize("mode", ["multiple-scattering", "layerlab"])
def test_lobes_are_reciprocal_and_nonnegative(mode):
    eta = 1.7
    lobes = lobes_for(mode, eta, 0.6, "ggx")
    mu = np.linspace(0.02, 1, 40)
    a, b = np.meshgrid(mu, mu, indexing="ij")
    for name in ("Rt", "Rb"):
        f = lobes.eval(name, a, b)
        assert f.min() >= 0 and np.allclose(f, f.T, rtol=1e-12, atol=0)
    # generalized reciprocity, radiance convention: f_Tbt(b, a) = f_Ttb(a, b) / eta^2
    assert np.allclose(lobes.eval("Tbt", b, a), lobes.eval("Ttb", a, b) / eta ** 2, rtol=1e-12)
    assert lobes.eval("Ttb", a, b).max() > 0


@pytest.mark.slow
def test_solver_operator_keeps_reciprocity():
    scene = {"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.4}],
             "discretization": {"n": 64}}
    plain = layersim.solve(layersim.Scene.from_dict(scene)).operators[0]
    scene["stack"] = {"energy_compensation": "multiple-scattering"}
    comp = layersim.solve(layersim.Scene.from_dict(scene)).operators[0]
    assert comp.reciprocity_error() < max(10 * plain.reciprocity_error(), 1e-10)


@pytest.mark.slow
def test_layerlab_compensated_albedo():
    """layerlab's defining property: a dielectric's compensated albedo is 1 from both sides; a
    conductor's is E(mu) + (1 - E1(mu)) F E1_avg / (1 - F (1 - E1_avg))."""
    eta, alpha = 1.5, 0.8
    a = tables.albedos(eta, 0.0, alpha, "beckmann")
    lobes = lobes_for("layerlab", eta, alpha, "beckmann")
    mu = tables.nodes()
    top = a.r_top + a.t_top + lobes.albedo("Rt", mu) + lobes.albedo("Ttb", mu)
    bottom = a.r_bottom + a.t_bottom + lobes.albedo("Rb", mu) + lobes.albedo("Tbt", mu)
    assert np.abs(top - 1).max() < 1e-12 and np.abs(bottom - 1).max() < 1e-12
    assert lobes.albedo("Ttb", mu).max() > 1e-3            # part of the loss is transmitted
    gold = complex(0.143552, 3.98397)
    e = tables.albedos(gold.real, gold.imag, alpha, "beckmann").r_top
    e1 = tables.albedos(gold.real, gold.imag, alpha, "beckmann", unit_fresnel=True).r_top
    cond = lobes_for("layerlab", gold, alpha, "beckmann")
    f_avg = tables.fresnel_average(gold.real, gold.imag)
    e_avg = 2 * np.trapezoid((e1 * mu)[::-1], mu[::-1])
    expected = e + (1 - e1) * f_avg * e_avg / (1 - f_avg * (1 - e_avg))
    assert np.abs(e + cond.albedo("Rt", mu) - expected).max() < 2e-4


def test_cache_directory(tmp_path):
    tables.albedos.cache_clear()
    with config.configure(cache_dir=str(tmp_path)):
        first = tables.albedos(1.0, 2.0, 0.7, "ggx")
        files = os.listdir(tmp_path / "compensation")
        assert len(files) == 1 and files[0].endswith(".npz")
        tables.albedos.cache_clear()
        again = tables.albedos(1.0, 2.0, 0.7, "ggx")
    assert np.array_equal(first.r_top, again.r_top) and first.r_top.max() > 0.3


def test_cache_dir_setting():
    assert config.Settings.from_env({"LAYERSIM_CACHE_DIR": "off"}).cache_dir is None
    assert config.Settings.from_env({"LAYERSIM_CACHE_DIR": "/x/y"}).cache_dir == "/x/y"
    assert config.Settings.from_env({}).cache_dir.endswith("layersim")


@pytest.mark.parametrize("data, field", [
    ({"stack": {"energy_compensation": "kulla"}}, "energy_compensation"),
    ({"layer_extra": {"energy_compensation": "full"}}, "energy_compensation"),
    ({"layer_extra": {"roughness": [0.1, 0.3], "energy_compensation": "layerlab"}},
     "energy_compensation"),
])
def test_bad_input_names_the_field(data, field):
    layer = {"kind": "conductor", "ior": [0.2, 3.0], "roughness": 0.3}
    layer.update(data.get("layer_extra", {}))
    scene = {"layer": [layer]}
    if "stack" in data:
        scene["stack"] = data["stack"]
    with pytest.raises(SceneError, match=field):
        layersim.Scene.from_dict(scene)


def test_near_specular_coat_is_refused():
    scene = layersim.Scene.from_dict({"stack": {"energy_compensation": "layerlab"}, "layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.02},
        {"kind": "diffuse", "albedo": 0.5}]})
    with pytest.raises(InfeasibleError, match="layer 0 .*energy_compensation"):
        layersim.make_plan(scene)


def test_plan_and_info_say_what_was_used(tmp_path):
    scene = layersim.Scene.from_dict({"stack": {"energy_compensation": "layerlab"}, "layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
        {"kind": "conductor", "ior": [0.2, 3.0], "roughness": 0.3,
         "energy_compensation": "multiple-scattering"}]})
    report = layersim.make_plan(scene).report()
    assert "energy compensation 'layerlab'" in report
    assert "energy compensation 'multiple-scattering'" in report
    gold = layersim.Scene.from_dict({"layer": [{"kind": "conductor", "ior": [0.2, 3.0],
                                                "roughness": 0.3,
                                                "energy_compensation": "layerlab"}]})
    bsdf = layersim.solve(gold)
    expected = [{"layer": 0, "kind": "conductor", "mode": "layerlab"}]
    assert bsdf.info["energy_compensation"] == expected
    bsdf.save(tmp_path / "gold.lsim")
    assert layersim.BSDF.load(tmp_path / "gold.lsim").info["energy_compensation"] == expected
    assert any("energy compensation (layerlab)" in n for n in bsdf.info["notes"])


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["multiple-scattering", "layerlab"])
def test_solver_matches_monte_carlo(mode):
    import layersim.montecarlo as mc
    scene = layersim.Scene.from_dict({"stack": {"energy_compensation": mode}, "layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.5},
        {"kind": "medium", "tau": 0.5, "albedo": 0.9, "g": 0.3},
        {"kind": "dielectric", "ior": 1.0, "roughness": 0.3, "distribution": "ggx"}]})
    bsdf = layersim.solve(scene)
    wi = np.array([np.sin(0.6), 0.0, np.cos(0.6)])
    res = mc.simulate(scene, wi=wi, particles=1_000_000, mu_edges=np.linspace(0, 1, 2),
                      phi_edges=np.linspace(0, 2 * np.pi, 2), backend="warp-cpu", seed=7)
    r, t = (float(x) for x in bsdf.albedo(wi))
    assert abs(r - res.reflectance) < 4 * res.reflectance_stderr
    assert abs(t - res.transmittance) < 4 * res.transmittance_stderr


@pytest.mark.slow
def test_opencl_walk_draws_the_same_compensation(cl_device):
    """The OpenCL kernel is generated from the same Warp functions (kernels/compensation.py):
    with the same random numbers it follows the same paths."""
    import layersim.montecarlo as mc
    scene = layersim.Scene.from_dict({"stack": {"energy_compensation": "multiple-scattering"},
                                      "layer": [{"kind": "dielectric", "ior": 1.5,
                                                 "roughness": 0.5},
                                                {"kind": "conductor", "ior": [1.0, 50.0],
                                                 "roughness": 0.5, "distribution": "ggx"}]})
    wi = np.array([np.sin(0.7), 0.0, np.cos(0.7)])
    kw = dict(wi=wi, particles=50_000, mu_edges=np.linspace(0, 1, 3),
              phi_edges=np.linspace(0, 2 * np.pi, 3), seed=4)
    w = mc.simulate(scene, backend="warp-cpu", **kw)
    o = mc.simulate(scene, backend="opencl", **kw)
    assert abs(w.reflectance - o.reflectance) < 0.1 * w.reflectance_stderr
    assert abs(w.events - o.events) <= 1e-3 * w.events
