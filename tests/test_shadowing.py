"""The Smith shadowing-masking choice of microfacet interfaces (``shadowing``): closed forms and
orderings of ``physics.smith_g2`` (Heitz 2014, sec. 6, eq. 99-100), reciprocity of the BSDF built
on it, refusals, the solver against the random walk, and the acceptance of issue 35: pbrt-v4's
layered BSDFs (``pbrt4_layered.json`` of the shared reference data) reproduced with the
height-correlated term."""

import functools
import json
import math
from pathlib import Path

import numpy as np
import pytest

import layersim
from layersim import montecarlo as mc
from layersim.errors import SceneError
from layersim.kernels import physics, pointwise, sampling
from layersim.statistical import lobes

from probes import ProbeSet

V, T, I = "double3", "double", "int"
CASES = [
    (sampling.sample_microfacet_shadowed, [V, T, T, T, T, T, T, I, I, T, T, T, T]),   # 0
    (sampling.microfacet_pdf_film, [V, V, T, T, T, T, T, T, I]),                     # 1
    (physics.microfacet_eval_shadowed, [V, V, T, T, T, T, T, T, I, I]),              # 2
]

REFDATA = [Path(__file__).resolve().parents[1] / ".." / "shared" / "refdata" / "pbrt4_layered.json",
           Path("/work/shared/refdata/pbrt4_layered.json")]


def _directions(rng, n, lower=False):
    w = rng.normal(size=(n, 3))
    w[:, 2] = np.abs(w[:, 2]) + 0.05
    w /= np.linalg.norm(w, axis=1)[:, None]
    if lower:
        w[:, 2] = -w[:, 2]
    return w


@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
def test_g2_closed_forms_and_order(dist):
    rng = np.random.default_rng(3)
    wi, wo_r, wo_t = _directions(rng, 200), _directions(rng, 200), _directions(rng, 200, True)
    n = np.array([0.0, 0.0, 1.0])
    a = 0.4
    g1i = pointwise.smith_g1(wi, a, a, dist)
    g = {(s, side): pointwise.smith_g2(wi, wo, n, a, a, dist, s)
         for s in ("separable", "height-correlated", "height-correlated-beta")
         for side, wo in (("R", wo_r), ("T", wo_t))}
    for side, wo in (("R", wo_r), ("T", wo_t)):
        g1o = pointwise.smith_g1(wo, a, a, dist)
        li, lo = 1.0 / g1i - 1.0, 1.0 / g1o - 1.0
        np.testing.assert_allclose(g["separable", side], g1i * g1o, rtol=1e-14)
        np.testing.assert_allclose(g["height-correlated", side], 1.0 / (1.0 + li + lo),
                                   rtol=1e-13)
        assert np.all(g["height-correlated", side] <= np.minimum(g1i, g1o) * (1 + 1e-14))
        assert np.all(g["height-correlated", side] >= g["separable", side] * (1 - 1e-14))
    beta = np.exp([math.lgamma(1 + x) + math.lgamma(1 + y) - math.lgamma(2 + x + y)
                   for x, y in zip(1.0 / g1i - 1.0,
                                   1.0 / pointwise.smith_g1(wo_t, a, a, dist) - 1.0)])
    np.testing.assert_allclose(g["height-correlated-beta", "T"], beta, rtol=1e-11)
    assert np.all(g["height-correlated-beta", "T"] <= g["separable", "T"] * (1 + 1e-14))
    np.testing.assert_array_equal(g["height-correlated-beta", "R"], g["height-correlated", "R"])
    assert np.all(g["height-correlated", "T"] > g["height-correlated-beta", "T"])


def test_g2_at_normal_incidence_and_side_conditions():
    n = np.array([0.0, 0.0, 1.0])
    for s in ("separable", "height-correlated", "height-correlated-beta"):
        assert pointwise.smith_g2(n, n, n, 0.5, 0.5, "ggx", s) == 1.0
        assert pointwise.smith_g2(n, -n, n, 0.5, 0.5, "ggx", s) == pytest.approx(1.0, abs=1e-10)
        # a normal facing away from wo: masked whatever the term
        m = np.array([0.9, 0.0, 0.1]) / np.linalg.norm([0.9, 0.0, 0.1])
        wo = np.array([-0.8, 0.0, 0.6])
        assert pointwise.smith_g2(n, wo, m, 0.5, 0.5, "ggx", s) == 0.0


@pytest.mark.parametrize("shadowing", ["height-correlated", "height-correlated-beta"])
@pytest.mark.parametrize("eta", [1.5, complex(0.2, 3.6)])
def test_bsdf_reciprocity(shadowing, eta):
    rng = np.random.default_rng(5)
    wi, wo = _directions(rng, 300), _directions(rng, 300)
    f = pointwise.microfacet_bsdf(wi, wo, eta, 0.3, "ggx", shadowing)
    np.testing.assert_allclose(f, pointwise.microfacet_bsdf(wo, wi, eta, 0.3, "ggx", shadowing),
                               rtol=1e-12)
    assert np.all(f >= pointwise.microfacet_bsdf(wi, wo, eta, 0.3, "ggx", "separable"))
    if eta.imag == 0:               # transmission: f(wi, wo) / eta_o^2 = f(wo, wi) / eta_i^2
        wt = _directions(rng, 300, lower=True)
        ft = pointwise.microfacet_bsdf(wi, wt, eta, 0.3, "ggx", shadowing)
        back = pointwise.microfacet_bsdf(wt, wi, eta, 0.3, "ggx", shadowing)
        assert np.count_nonzero(ft) > 30
        np.testing.assert_allclose(ft / eta ** 2, back, rtol=1e-10)


@pytest.fixture(scope="module")
def probes(tmp_path_factory):
    return ProbeSet(CASES, tmp_path_factory.mktemp("shadowing"),
                    name="layersim_test_shadowing_probes")


@pytest.mark.parametrize("shadow", [1, 2])
@pytest.mark.parametrize("conductor", [False, True])
def test_walk_weight_is_eval_cos_over_pdf(probes, shadow, conductor):
    """The walk's sampler weights by G2 / G1(wi): weight == f |wo.z| / pdf pointwise for the
    height-correlated terms (codes of physics.SHADOWING_CODES), reflection and refraction from
    both sides, both distributions, anisotropic slopes; films off (phase 0)."""
    r = np.random.default_rng(11 + shadow + 2 * conductor)
    n = 3000
    wi = _directions(r, n)
    if not conductor:
        wi[r.random(n) < 0.5, 2] *= -1
    eta = np.where(r.random(n) < 0.5, r.uniform(1.1, 2.0, n), r.uniform(0.5, 0.9, n))
    k = r.uniform(1, 4, n) if conductor else np.zeros(n)
    zero = np.zeros(n)
    au, av = r.uniform(0.05, 0.8, n), r.uniform(0.05, 0.8, n)
    d, sh = r.integers(0, 2, n), np.full(n, shadow)
    us = [r.uniform(1e-9, 1 - 1e-9, n) for _ in range(4)]
    wo, weight = probes.warp(0, wi, eta, k, zero, zero, au, av, d, sh, *us)
    pdf = probes.warp(1, wi, wo, eta, k, zero, zero, au, av, d)[0]
    f = probes.warp(2, wi, wo, eta, k, zero, zero, au, av, d, sh)[0]
    live = weight > 0
    assert live.mean() > 0.8 and np.all(pdf[live] > 0)
    np.testing.assert_allclose(weight[live], f[live] * np.abs(wo[live, 2]) / pdf[live],
                               rtol=1e-7)
    assert np.all(weight <= 1 + 1e-12)


def _coat(stack_shadowing=None, **interface):
    layer = {"kind": "dielectric", "ior": 1.5, "roughness": 0.2, "distribution": "ggx",
             **interface}
    layer = {k: v for k, v in layer.items() if v is not None}
    stack = {} if stack_shadowing is None else {"shadowing": stack_shadowing}
    return {"stack": stack, "layer": [layer, {"kind": "conductor", "ior": [0.2, 3.6],
                                              "roughness": 0.2, "distribution": "ggx"}]}


@pytest.mark.parametrize("interface, field", [
    ({"shadowing": "height"}, "shadowing"),
    ({"shadowing": "height-correlated", "roughness": 0.02}, "shadowing"),
])
def test_refusals_name_the_layer_and_field(interface, field):
    with pytest.raises(SceneError) as e:
        layersim.Scene.from_dict(_coat(**interface))
    assert e.value.field == field and e.value.layer == 0
    assert "\n" not in str(e.value)


def test_stack_default_and_refusals():
    scene = layersim.Scene.from_dict(_coat("height-correlated"))
    assert [x.shadowing for x in scene.layers] == ["height-correlated"] * 2
    assert layersim.Scene.from_dict(_coat()).layers[0].shadowing == "separable"
    with pytest.raises(SceneError, match="shadowing"):
        layersim.Scene.from_dict(_coat("pbrt"))
    with pytest.raises(Exception, match="shadowing"):
        lobes(scene, 0.3)


@pytest.mark.slow
@pytest.mark.parametrize("shadowing", ["height-correlated", "height-correlated-beta"])
def test_compensation_tables_of_the_height_correlated_term(shadowing):
    """The albedo tables are keyed by the term (the height-correlated interface keeps more
    energy in reflection, eq. 99 >= the product; the Beta form less in transmission), and the
    compensated rough dielectric conserves energy from both sides with it."""
    from layersim.compensation import tables
    sep = tables.albedos(1.5, 0.0, 0.5, "ggx")
    hc = tables.albedos(1.5, 0.0, 0.5, "ggx", shadowing=shadowing)
    assert np.all(hc.r_top >= sep.r_top - 1e-15) and np.any(hc.r_top > sep.r_top + 1e-3)
    if shadowing == "height-correlated-beta":
        assert np.all(hc.t_top <= sep.t_top + 1e-15)
    scene = layersim.Scene.from_dict({
        "stack": {"energy_compensation": "multiple-scattering", "shadowing": shadowing},
        "layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.5, "distribution": "ggx"}]})
    bsdf = layersim.solve(scene)
    angles = np.radians(np.arange(0, 86, 5))
    for side in (1.0, -1.0):
        wi = np.stack([np.sin(angles), 0 * angles, side * np.cos(angles)], -1)
        r, t = bsdf.albedo(wi)
        assert np.abs(r + t - 1).max() < 1e-9, (side, r + t)


@functools.lru_cache(maxsize=None)
def _ggx_table(au=0.3, av=0.15):
    """A 91 x 180 table of the anisotropic GGX NDF (as tests/test_tabulated_ndf.py's)."""
    from layersim.ndf import sampled_table

    def ggx(t, p):
        c = np.cos(t)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            q = np.tan(t) ** 2 * (np.cos(p) ** 2 / au ** 2 + np.sin(p) ** 2 / av ** 2)
            d = 1.0 / (np.pi * au * av * c ** 4 * (1 + q) ** 2)
        return np.where(c > 1e-12, d, 0.0)
    return sampled_table(ggx, 91, 180)


@pytest.mark.parametrize("shadowing", ["height-correlated", "height-correlated-beta"])
@pytest.mark.parametrize("eta", [1.5, 1 / 1.5, complex(0.2, 3.6)])
def test_tabulated_ndf_extends_the_height_correlated_term(shadowing, eta):
    """G2 from the table's S (Smith's G1 of its D; physics.g2_from_masking) reproduces the
    analytic interface's height-correlated BSDF as closely as the table's separable BSDF
    reproduces the analytic separable one (the table's resolution: 0.2-1.3 % L2 here)."""
    from layersim.kernels import projection as kproj
    rng = np.random.default_rng(8)
    P = 60
    mu_i = rng.uniform(0.05, 1.0, P)
    sign = -1.0 if isinstance(eta, complex) else rng.choice([-1.0, 1.0], P)
    mu_o = rng.uniform(0.05, 1.0, P) * sign
    packed = _ggx_table().packed(np.float64)
    pd = np.tile(np.repeat(2 * np.pi * np.arange(64) / 64, 16), (P, 1))
    ps = np.tile(np.tile(2 * np.pi * np.arange(16) / 16, 64), (P, 1))

    def rel(a, b):
        big = b > 0.01 * b.max()
        return np.linalg.norm((a - b)[big]) / np.linalg.norm(b[big])
    f = kproj.tabulated_ds_samples(mu_i, mu_o, eta, packed, 64, 16, shadowing=shadowing)
    ref = kproj.microfacet_values_ds(mu_i, mu_o, pd, ps, eta, 0.3, 0.15, "ggx",
                                     shadowing=shadowing).reshape(P, 64, 16)
    sep = kproj.tabulated_ds_samples(mu_i, mu_o, eta, packed, 64, 16)
    sep_ref = kproj.microfacet_values_ds(mu_i, mu_o, pd, ps, eta, 0.3, 0.15,
                                         "ggx").reshape(P, 64, 16)
    assert rel(f, ref) < 1.1 * rel(sep, sep_ref) + 1e-3
    assert rel(sep, ref) > rel(f, ref)          # the term is not the separable one


def _pbrt_sets():
    for path in REFDATA:
        if path.exists():
            return json.loads(path.read_text())["sets"]
    pytest.skip("the shared reference data (pbrt4_layered.json) are not on this machine")


def _pbrt_scene(p, shadowing="height-correlated", n=None):
    """The stack of a pbrt-v4 parameter set (the file's conventions: GGX alpha given directly,
    the conductor's material index absolute, thickness as optical depth)."""
    layers = [{"kind": "dielectric", "ior": p["interface_eta"], "roughness": p["interface_alpha"],
               "distribution": "ggx"},
              {"kind": "medium", "tau": p["thickness"], "albedo": p["albedo"], "g": p["g"]}]
    if "reflectance" in p:
        layers.append({"kind": "diffuse", "albedo": p["reflectance"]})
    else:
        layers.append({"kind": "conductor", "ior": [p["conductor_eta"], p["conductor_k"]],
                       "roughness": p["conductor_alpha"], "distribution": "ggx"})
    scene = {"stack": {"shadowing": shadowing}, "layer": layers}
    if n is not None:
        scene["discretization"] = {"n": n, "md": n}
    return layersim.Scene.from_dict(scene)


@pytest.mark.slow
def test_solver_matches_walk_height_correlated():
    p = _pbrt_sets()["b"]["material_params"]
    scene = _pbrt_scene(p, n=160)
    bsdf = layersim.solve(scene)
    for theta in (60.0, 75.0):
        wi = np.array([math.sin(math.radians(theta)), 0.0, math.cos(math.radians(theta))])
        r = mc.simulate(scene, wi, 200_000, backend="warp-cpu", seed=2)
        assert abs(float(bsdf.albedo(wi)[0]) - r.reflectance) < 3.5 * r.reflectance_stderr


@pytest.mark.slow
def test_pbrt_v4_layered_acceptance():
    """Issue 35: every albedo of pbrt-v4's ``Sample_f`` within max(3 standard errors, 1e-3),
    and ``f_patched`` (``f`` with the MIS fix of pbrt-v4 issue 187) of sets a and c within
    1.5 % relative L2 over their pairs."""
    for key, data in _pbrt_sets().items():
        # the planner's default discretisation, but for set b (alpha 0.3 coat, grazing
        # albedos), which needs finer ordinates for 1e-3 (benchmarks/accuracy/
        # pbrt_v4_layered.py solves every set to tol = 1e-3 instead)
        bsdf = layersim.solve(_pbrt_scene(data["material_params"], n=200 if key == "b" else None))
        for a in data["albedo_Sample_f_1e7"]:
            got = float(bsdf.albedo(np.array(a["wo"]))[0])
            assert abs(got - a["albedo"]) <= max(3 * a["albedo_stderr"], 1e-3), (key, a)
        if "pairs" in data:
            wo = np.array([q["wo"] for q in data["pairs"]])
            wi = np.array([q["wi"] for q in data["pairs"]])
            ref = np.array([q["f_patched"] for q in data["pairs"]])
            err = np.linalg.norm(bsdf.eval(wi, wo) - ref) / np.linalg.norm(ref)
            assert err < 0.015, (key, err)


@pytest.mark.slow
def test_solver_matches_walk_height_correlated_compensated():
    """Compensation lobes from the height-correlated albedo tables, in the solver and the walk
    (a GGX coat over a scattering medium and a rough GGX exit)."""
    scene = layersim.Scene.from_dict({
        "stack": {"energy_compensation": "multiple-scattering",
                  "shadowing": "height-correlated"},
        "layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.5, "distribution": "ggx"},
                  {"kind": "medium", "tau": 0.5, "albedo": 0.9, "g": 0.3},
                  {"kind": "dielectric", "ior": 1.0, "roughness": 0.3, "distribution": "ggx"}]})
    bsdf = layersim.solve(scene)
    wi = np.array([np.sin(0.6), 0.0, np.cos(0.6)])
    res = mc.simulate(scene, wi, 400_000, backend="warp-cpu", seed=7)
    r, t = (float(x) for x in bsdf.albedo(wi))
    assert abs(r - res.reflectance) < 4 * res.reflectance_stderr
    assert abs(t - res.transmittance) < 4 * res.transmittance_stderr


@pytest.mark.slow
def test_tabulated_height_correlated_solver_matches_walk():
    """A tabulated GGX conductor with the height-correlated term: solver and walk (which
    samples the table) agree, and the table follows the analytic layer."""
    table = _ggx_table()
    inline = {"theta": np.degrees(table.theta).tolist(), "phi": np.degrees(table.phi).tolist(),
              "D": table.D.tolist()}
    def scene(base):
        return layersim.Scene.from_dict({"stack": {"shadowing": "height-correlated"}, "layer": [
            {"kind": "conductor", "ior": [0.2, 3.6], **base}]})
    tab = scene({"distribution": "tabulated", "ndf": inline})
    ana = scene({"distribution": "ggx", "roughness": [0.3, 0.15]})
    wi = np.array([math.sin(1.1), 0.0, math.cos(1.1)])
    r_tab = float(layersim.solve(tab).albedo(wi)[0])
    r = mc.simulate(tab, wi, 300_000, backend="warp-cpu", seed=5)
    assert abs(r_tab - r.reflectance) < 4 * r.reflectance_stderr
    assert abs(r_tab - float(layersim.solve(ana).albedo(wi)[0])) < 3e-3


@pytest.mark.slow
def test_anisotropic_height_correlated_solver_matches_walk():
    """The coupled-mode projection carries the term too: an anisotropic GGX conductor, lit
    obliquely off its axes, against the walk; the separable term is measurably apart."""
    def scene(shadowing):
        return layersim.Scene.from_dict({"stack": {"shadowing": shadowing}, "layer": [
            {"kind": "conductor", "ior": [0.2, 3.6], "roughness": [0.25, 0.5],
             "distribution": "ggx", "rotation": 30.0}]})
    t = math.radians(75.0)
    wi = np.array([math.sin(t) * math.cos(0.4), math.sin(t) * math.sin(0.4), math.cos(t)])
    hc = float(layersim.solve(scene("height-correlated")).albedo(wi)[0])
    sep = float(layersim.solve(scene("separable")).albedo(wi)[0])
    r = mc.simulate(scene("height-correlated"), wi, 400_000, backend="warp-cpu", seed=4)
    assert abs(hc - r.reflectance) < 4 * r.reflectance_stderr
    assert hc - sep > 10 * r.reflectance_stderr
