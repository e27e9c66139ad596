"""Tabulated NDFs (Wang et al. 2008): a table sampled from an analytic anisotropic Beckmann or GGX
NDF must reproduce the analytic interface: its shadowing (eq. (5)) is Smith's G1, its kernel
BSDF the analytic one, the solver's operators and the Monte Carlo walk (which samples the
table) the analytic layer's."""

import numpy as np
import pytest
import warp as wp
from scipy.special import erf

import layersim
import layersim.montecarlo as mc
from layersim.errors import SceneError
from layersim.kernels import projection as kproj
from layersim.kernels import tabulated as ktab
from layersim.ndf import from_arrays, load_ndf, sampled_table
from layersim.ndf.table import shadow_grid

from conftest import random_directions, unit

AU, AV = 0.3, 0.15
GOLD = [0.143552, 3.98397]


def beckmann(t, p, au=AU, av=AV):
    c = np.cos(t)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        q = np.tan(t) ** 2 * (np.cos(p) ** 2 / au ** 2 + np.sin(p) ** 2 / av ** 2)
        d = np.exp(-q) / (np.pi * au * av * c ** 4)
    return np.where(c > 1e-12, d, 0.0)


def ggx(t, p, au=AU, av=AV):
    c = np.cos(t)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        q = np.tan(t) ** 2 * (np.cos(p) ** 2 / au ** 2 + np.sin(p) ** 2 / av ** 2)
        d = 1.0 / (np.pi * au * av * c ** 4 * (1 + q) ** 2)
    return np.where(c > 1e-12, d, 0.0)


def smith_g1(theta, phi, dist):
    a_proj = np.sqrt(np.cos(phi) ** 2 * AU ** 2 + np.sin(phi) ** 2 * AV ** 2)
    with np.errstate(divide="ignore"):
        x = a_proj * np.tan(theta)
        if dist == "ggx":
            lam = 0.5 * (np.sqrt(1 + x * x) - 1)
        else:
            a = 1 / x
            lam = np.where(np.isinf(a), 0.0, 0.5 * (erf(a) - 1)
                           + np.exp(-a * a) / (2 * a * np.sqrt(np.pi)))
    return np.where(theta < 0.5 * np.pi - 1e-12, 1 / (1 + lam), 0.0)


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    """91 x 180 tables (1 x 2 degrees) of the two analytic NDFs, and their files."""
    out = {}
    d = tmp_path_factory.mktemp("ndf")
    for name, fn in (("beckmann", beckmann), ("ggx", ggx)):
        tab = sampled_table(fn, 91, 180)
        path = d / f"{name}.npz"
        np.savez(path, theta=tab.theta, phi=tab.phi, D=fn(tab.theta[:, None], tab.phi[None, :]))
        out[name] = (tab, str(path))
    return out


def layer(kind, ior, dist, tables=None, **extra):
    if tables is None:
        return {"kind": kind, "ior": ior, "roughness": [AU, AV], "distribution": dist, **extra}
    return {"kind": kind, "ior": ior, "distribution": "tabulated", "ndf": tables[dist][1],
            **extra}


# ------------------------------------------------------------------------------------------
# the table itself
# ------------------------------------------------------------------------------------------

def test_shadowing_of_the_beckmann_table_is_smith_g1(tables):
    tab = tables["beckmann"][0]
    tg, pg = shadow_grid()
    ref = smith_g1(tg[:, None], pg[None, :], "beckmann")
    assert np.abs(tab.shadow - ref).max() < 1e-3
    # interpolated between the nodes, up to 89.5 degrees
    rng = np.random.default_rng(3)
    th, ph = rng.uniform(0, np.radians(89.5), 4000), rng.uniform(0, 2 * np.pi, 4000)
    k = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1)
    assert np.abs(tab.shadowing(k) - smith_g1(th, ph, "beckmann")).max() < 1e-3
    # the derivation is not tied to Beckmann: the GGX table gives GGX's Smith term
    assert np.abs(tables["ggx"][0].shadow - smith_g1(tg[:, None], pg[None, :], "ggx")).max() \
        < 2e-3


def test_table_is_normalised_and_interpolates_the_ndf(tables):
    tab = tables["beckmann"][0]
    scaled = from_arrays(tab.theta, tab.phi, 3.7 * beckmann(tab.theta[:, None],
                                                            tab.phi[None, :]))
    assert np.allclose(scaled.D, tab.D, rtol=1e-12)
    assert scaled.scale == pytest.approx(tab.scale / 3.7, rel=1e-12)
    # the analytic NDF is normalised: the table's projected area is 1 to its resolution
    assert tab.scale == pytest.approx(1.0, abs=2e-3)
    assert tab.cell_probabilities().sum() == pytest.approx(1.0, abs=1e-12)
    rng = np.random.default_rng(4)
    th, ph = rng.uniform(0, np.radians(70), 5000), rng.uniform(0, 2 * np.pi, 5000)
    ref = beckmann(th, ph)
    big = ref > 0.01 * ref.max()
    assert np.linalg.norm((tab.eval(th, ph) - ref)[big]) / np.linalg.norm(ref[big]) < 0.01
    au, av = tab.equivalent_alpha()
    assert au == pytest.approx(AU, rel=0.02) and av == pytest.approx(AV, rel=0.02)


@pytest.mark.parametrize("dist", ["beckmann", "ggx"])
@pytest.mark.parametrize("eta", [1.5, 1 / 1.5, complex(*GOLD)])
def test_kernel_bsdf_matches_the_analytic_interface(tables, dist, eta):
    rng = np.random.default_rng(5)
    P = 60
    mu_i = rng.uniform(0.05, 1.0, P)
    sign = -1.0 if isinstance(eta, complex) else rng.choice([-1.0, 1.0], P)
    mu_o = rng.uniform(0.05, 1.0, P) * sign
    f = kproj.tabulated_ds_samples(mu_i, mu_o, eta, tables[dist][0].packed(np.float64), 64, 16)
    pd = np.repeat(2 * np.pi * np.arange(64) / 64, 16)
    ps = np.tile(2 * np.pi * np.arange(16) / 16, 64)
    ref = kproj.microfacet_values_ds(mu_i, mu_o, np.tile(pd, (P, 1)), np.tile(ps, (P, 1)), eta,
                                     AU, AV, dist).reshape(P, 64, 16)
    big = ref > 0.01 * ref.max()
    assert np.linalg.norm((f - ref)[big]) / np.linalg.norm(ref[big]) < 0.01


@wp.kernel
def _sample_kernel(tab: wp.array(dtype=wp.float64), wi: wp.array(dtype=wp.vec3d),
                   u: wp.array2d(dtype=wp.float64), eta: wp.float64, k: wp.float64,
                   wo: wp.array(dtype=wp.vec3d), weight: wp.array(dtype=wp.float64),
                   f: wp.array(dtype=wp.float64), pdf: wp.array(dtype=wp.float64)):
    t = wp.tid()
    w, g = ktab.sample_microfacet_tabulated(wi[t], eta, k, tab, 0, u[t, 0], u[t, 1], u[t, 2])
    wo[t] = w
    weight[t] = g
    f[t] = ktab.microfacet_eval_tabulated(wi[t], w, eta, k, tab, 0)
    pdf[t] = ktab.microfacet_pdf_tabulated(wi[t], w, eta, k, tab, 0)


@wp.kernel
def _normal_pdf_kernel(tab: wp.array(dtype=wp.float64), m: wp.array(dtype=wp.vec3d),
                       pdf: wp.array(dtype=wp.float64)):
    t = wp.tid()
    pdf[t] = ktab.normal_pdf(tab, 0, m[t])


@pytest.mark.parametrize("eta", [1.5, complex(*GOLD)])
def test_sampling_weight_is_bsdf_cosine_over_pdf(tables, eta):
    tab = wp.array(tables["ggx"][0].packed(np.float64), dtype=wp.float64, device="cpu")
    rng = np.random.default_rng(6)
    n = 4000
    wi = random_directions(rng, n, lower=not isinstance(eta, complex))
    if isinstance(eta, complex):
        wi[:, 2] = np.abs(wi[:, 2])
    outs = [wp.empty(n, dtype=wp.vec3d, device="cpu")] + \
        [wp.empty(n, dtype=wp.float64, device="cpu") for _ in range(3)]
    e = complex(eta)
    wp.launch(_sample_kernel, dim=n, device="cpu",
              inputs=[tab, wp.array(wi, dtype=wp.vec3d, device="cpu"),
                      wp.array(rng.uniform(1e-6, 1 - 1e-6, (n, 3)), dtype=wp.float64,
                               device="cpu"), e.real, e.imag], outputs=outs)
    wo, weight, f, pdf = (o.numpy() for o in outs)
    ok = (weight > 0) & (pdf > 0)
    assert ok.mean() > 0.5
    assert np.allclose(weight[ok], f[ok] * np.abs(wo[ok, 2]) / pdf[ok], rtol=1e-6)
    # the normal density integrates to one over the hemisphere (midpoint rule, fine grid)
    th = (np.arange(900) + 0.5) * (0.5 * np.pi / 900)
    ph = (np.arange(720) + 0.5) * (2 * np.pi / 720)
    T, Ph = np.meshgrid(th, ph, indexing="ij")
    m = np.stack([np.sin(T) * np.cos(Ph), np.sin(T) * np.sin(Ph), np.cos(T)], -1).reshape(-1, 3)
    p = wp.empty(m.shape[0], dtype=wp.float64, device="cpu")
    wp.launch(_normal_pdf_kernel, dim=m.shape[0], device="cpu",
              inputs=[tab, wp.array(m, dtype=wp.vec3d, device="cpu")], outputs=[p])
    total = np.sum(p.numpy().reshape(T.shape) * np.sin(T)) * (0.5 * np.pi / 900) * (
        2 * np.pi / 720)
    assert total == pytest.approx(1.0, abs=2e-3)


# ------------------------------------------------------------------------------------------
# solver and Monte Carlo against the analytic interface
# ------------------------------------------------------------------------------------------

DISC = {"n": 40, "md": 48}


def _eval_error(a, b, upper_only):
    rng = np.random.default_rng(7)
    wi = random_directions(rng, 3000, lower=not upper_only)
    wo = random_directions(rng, 3000, lower=not upper_only)
    if upper_only:
        wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]), np.abs(wo[:, 2])
    fa, fb = a.eval(wi, wo), b.eval(wi, wo)
    big = np.abs(fa) > 0.01 * np.abs(fa).max()
    return np.linalg.norm((fa - fb)[big]) / np.linalg.norm(fa[big])


@pytest.mark.slow
@pytest.mark.parametrize("dist", ["beckmann", "ggx"])
def test_solver_matches_the_analytic_conductor(tables, dist):
    analytic = layersim.solve({"layer": [layer("conductor", GOLD, dist)],
                               "discretization": DISC})
    tab = layersim.solve({"layer": [layer("conductor", GOLD, dist, tables)],
                          "discretization": DISC})
    assert _eval_error(analytic, tab, upper_only=True) < 0.01
    wi = unit(40.0, 20.0)
    assert float(tab.albedo(wi)[0]) == pytest.approx(float(analytic.albedo(wi)[0]), abs=2e-3)


@pytest.mark.slow
def test_solver_matches_the_analytic_dielectric_alone_and_under_a_coating(tables):
    for stack in ([("dielectric", 1.5)], [("coat", None), ("conductor", GOLD)]):
        def build(tabs):
            out = []
            for kind, ior in stack:
                if kind == "coat":
                    out.append({"kind": "dielectric", "ior": 1.5, "roughness": 0.2})
                else:
                    out.append(layer(kind, ior, "beckmann", tabs, rotation=30.0))
            return {"layer": out, "discretization": {"n": 60, "md": 64}}
        analytic = layersim.solve(build(None))
        tab = layersim.solve(build(tables))
        assert _eval_error(analytic, tab, upper_only=stack[-1][0] == "conductor") < 0.01


def _albedos(scene, wi, particles, seed):
    r = mc.simulate(scene, wi, particles, backend="warp-cpu", seed=seed)
    return np.array([r.reflectance, r.transmittance]), np.array(
        [r.reflectance_stderr, r.transmittance_stderr])


@pytest.mark.slow
@pytest.mark.parametrize("dist", ["beckmann", "ggx"])
def test_monte_carlo_matches_the_analytic_interface(tables, dist):
    """Albedos within 4 standard errors at 1e6 paths: the walk samples the table (its own
    proposal) and the analytic lobe (visible normals); the two must agree, alone and under a
    rough coating, lit from above and (glass) from below."""
    cases = [
        ([layer("conductor", GOLD, dist)], [layer("conductor", GOLD, dist, tables)],
         unit(50.0, 30.0)),
        ([layer("dielectric", 1.5, dist)], [layer("dielectric", 1.5, dist, tables)],
         unit(30.0, 100.0)),
        ([layer("dielectric", 1.5, dist)], [layer("dielectric", 1.5, dist, tables)],
         unit(160.0, 10.0)),
        ([{"kind": "dielectric", "ior": 1.5, "roughness": 0.2}, layer("conductor", GOLD, dist)],
         [{"kind": "dielectric", "ior": 1.5, "roughness": 0.2},
          layer("conductor", GOLD, dist, tables)], unit(20.0, 45.0)),
    ]
    for k, (a, t, wi) in enumerate(cases):
        ea, sa = _albedos(layersim.Scene.from_dict({"layer": a}), wi, 1_000_000, 10 + k)
        et, st = _albedos(layersim.Scene.from_dict({"layer": t}), wi, 1_000_000, 20 + k)
        assert np.all(np.abs(ea - et) <= 4 * np.hypot(sa, st) + 1e-12), (k, ea, et, sa, st)


@pytest.mark.slow
def test_solver_and_monte_carlo_agree_on_a_coated_tabulated_conductor(tables):
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.2},
        layer("conductor", GOLD, "ggx", tables, rotation=20.0)]})
    wi = unit(35.0, 70.0)
    est, se = _albedos(scene, wi, 1_000_000, 31)
    R = float(layersim.solve(scene).albedo(wi)[0])
    assert abs(R - est[0]) <= 4 * se[0] + 1e-3     # 1e-3: the discretisation's energy error


@pytest.mark.slow
def test_opencl_walk_samples_the_table_as_warp_does(tables, cl_device):
    scene = layersim.Scene.from_dict({"layer": [layer("conductor", GOLD, "beckmann", tables)]})
    wi = unit(40.0, 10.0)
    a = mc.simulate(scene, wi, 20_000, backend="opencl", seed=4)
    b = mc.simulate(scene, wi, 20_000, backend="warp-cpu", seed=4)
    assert a.reflectance == pytest.approx(b.reflectance, abs=1e-5)


# ------------------------------------------------------------------------------------------
# scene, plan, errors
# ------------------------------------------------------------------------------------------

def test_scene_paths_inline_tables_and_plan_report(tables, tmp_path):
    path = tmp_path / "s.toml"
    np.savez(tmp_path / "t.npz", theta=tables["ggx"][0].theta, phi=tables["ggx"][0].phi,
             D=tables["ggx"][0].D)
    path.write_text('[[layer]]\nkind = "conductor"\nior = [0.2, 3.0]\n'
                    'distribution = "tabulated"\nndf = "t.npz"\n')
    scene = layersim.Scene.from_toml(path)
    assert scene.layers[0].ndf.D.shape == (91, 180)
    assert "tabulated NDF 91 x 180" in scene.describe()
    report = layersim.make_plan(scene).report()
    assert "grid spacing 1 x 2 deg" in report and "equivalent Beckmann alpha" in report
    # inline, in degrees: an isotropic table of four elevations
    th = np.linspace(0.0, 90.0, 4)
    inline = {"theta": th.tolist(), "phi": [0.0, 90.0, 180.0, 270.0],
              "D": [[float(v)] * 4 for v in beckmann(np.radians(th), 0.0, 0.5, 0.5)]}
    s = layersim.Scene.from_dict({"layer": [{"kind": "conductor", "ior": [0.2, 3.0],
                                             "distribution": "tabulated", "ndf": inline}]})
    assert s.layers[0].ndf.theta[-1] == pytest.approx(np.pi / 2)


@pytest.mark.parametrize("entry, message", [
    ({"distribution": "tabulated"}, "field 'ndf': is required"),
    ({"distribution": "tabulated", "ndf": "missing.npz"}, "cannot read NDF file"),
    ({"distribution": "tabulated", "ndf": "t.npz", "roughness": 0.2},
     "field 'roughness': a tabulated NDF takes no roughness"),
    ({"ndf": "t.npz"}, 'field \'ndf\': is only used with distribution = "tabulated"'),
    ({"distribution": "tabulated", "ndf": {"theta": [0, 90], "phi": [0, 180],
                                           "D": [[1, 1], [1]]}}, "field 'ndf'"),
    ({"distribution": "tabulated", "ndf": {"theta": [0, 45], "phi": [0, 180],
                                           "D": [[1, 1], [1, 1]]}}, "from 0 to pi/2"),
    ({"distribution": "tabulated", "ndf": {"theta": [0, 90], "phi": [0, 180],
                                           "D": [[0, 0], [0, 0]]}}, "cannot be normalised"),
    ({"distribution": "tabulated", "ndf": {"theta": [0, 90], "phi": [0, 180],
                                           "D": [[1, 1], [2, 1]]}}, "rotation by pi"),
    ({"distribution": "tabulated", "ndf": {"theta": [0, 90], "phi": [0, 100],
                                           "D": [[1, 1], [1, 1]]}}, "phi[j] + pi"),
])
def test_bad_tables_name_layer_field_and_file(tmp_path, monkeypatch, entry, message):
    monkeypatch.chdir(tmp_path)
    np.savez("t.npz", theta=[0.0, np.pi / 2], phi=[0.0, np.pi], D=[[1.0, 1.0], [1.0, 1.0]])
    with pytest.raises(SceneError) as err:
        layersim.Scene.from_dict({"layer": [{"kind": "dielectric", "ior": 1.5}, {
            "kind": "conductor", "ior": [0.2, 3.0], **entry}]})
    assert message in str(err.value) and "layer 1 (conductor)" in str(err.value)


def test_npz_without_the_arrays_is_refused(tmp_path):
    np.savez(tmp_path / "x.npz", theta=[0.0, 1.0])
    with pytest.raises(SceneError, match=r"x.npz: missing array\(s\) phi, D"):
        load_ndf(tmp_path / "x.npz")


def test_plot_of_a_table_is_written(tables, tmp_path):
    from layersim.ndf.plot import plot_ndf
    path = plot_ndf(tables["beckmann"][0], tmp_path / "ndf.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 10_000


@pytest.mark.slow
def test_cli_plans_a_tabulated_scene_and_refuses_a_bad_table(tables, tmp_path, capsys):
    from layersim.cli import main as cli_main
    scene = tmp_path / "s.toml"
    scene.write_text('[[layer]]\nkind = "conductor"\nior = [0.2, 3.0]\n'
                     f'distribution = "tabulated"\nndf = "{tables["beckmann"][1]}"\n')
    assert cli_main(["plan", str(scene)]) == 0
    assert "tabulated NDF 91 x 180" in capsys.readouterr().out
    np.savez(tmp_path / "bad.npz", theta=[0.0, 1.0], phi=[0.0, np.pi], D=[[1.0, 1.0]] * 2)
    scene.write_text('[[layer]]\nkind = "conductor"\nior = [0.2, 3.0]\n'
                     'distribution = "tabulated"\nndf = "bad.npz"\n')
    assert cli_main(["plan", str(scene)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.npz" in err[0] and "from 0 to pi/2" in err[0]


@pytest.fixture(scope="module")
def rotated(tmp_path_factory):
    """The Beckmann (0.3, 0.15) table turned by 30 deg in azimuth: not mirror symmetric about
    its axes (complex coefficients f_{d,s}), only under a rotation by pi."""
    tab = sampled_table(lambda t, p: beckmann(t, p - np.radians(30.0)), 91, 180)
    path = tmp_path_factory.mktemp("rot") / "rotated.npz"
    np.savez(path, theta=tab.theta, phi=tab.phi, D=tab.D)
    return str(path)


def test_a_turned_table_is_planned_as_the_rotated_lobe(rotated):
    analytic = layersim.make_plan({"layer": [layer("conductor", GOLD, "beckmann",
                                                   rotation=30.0)]})
    tab = layersim.make_plan({"layer": [{"kind": "conductor", "ior": GOLD,
                                         "distribution": "tabulated", "ndf": rotated}]})
    assert (tab.n, tab.md, tab.ms) == (analytic.n, analytic.md, analytic.ms)
    assert "alpha=(0.302, 0.15) along 30 deg" in tab.report()


@pytest.mark.slow
@pytest.mark.parametrize("kind, ior", [("conductor", GOLD), ("dielectric", 1.5)])
def test_a_turned_table_matches_the_rotated_analytic_layer(rotated, kind, ior):
    disc = {"n": 64, "md": 48}
    analytic = layersim.solve({"layer": [layer(kind, ior, "beckmann", rotation=30.0)],
                               "discretization": disc})
    tab = layersim.solve({"layer": [{"kind": kind, "ior": ior, "distribution": "tabulated",
                                     "ndf": rotated}], "discretization": disc})
    assert _eval_error(analytic, tab, upper_only=kind == "conductor") < 0.01
    if kind == "dielectric":
        assert _eval_error(analytic, tab, upper_only=True) < 0.01
