"""Single-view NDF fitting and completion (Wang et al. 2008 sec. 5.1-5.2, eq. 5, 10-17),
tested against analytic GGX / Beckmann surfaces and their closed-form Smith shadowing."""

import numpy as np
import pytest

from layersim.cli import main
from layersim.errors import FileFormatError, InfeasibleError
from layersim.kernels import pointwise as pw
from layersim.kernels.fresnel import fresnel
from layersim.ndf import complete as cp
from layersim.ndf import microfacet as mf
from layersim.ndf import synthetic as sy
from layersim.ndf.fit import PartialNDF, fit_partial_ndf
from layersim.ndf.halfgrid import HalfGrid
from layersim.ndf.measurements import Measurements
from layersim.ndf.ndffile import save_ndf

ALPHA = (0.2, 0.4)


def _rel_l2(grid, d, ref, mask=None):
    wts = grid.weights * (1.0 if mask is None else mask)
    return float(np.sqrt(np.sum(wts * np.nan_to_num(d - ref) ** 2) / np.sum(wts * ref ** 2)))


def _truth(grid, rot, alpha=ALPHA):
    return sy.analytic_ndf("ggx", *alpha, rot)[0](grid.directions())


@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
def test_shadowing_from_the_tabulated_ndf_is_the_smith_term(dist):
    g = HalfGrid(91, 180)
    d = pw.ndf(g.directions(), 0.2, 0.45, dist)
    assert g.projected_area(d) == pytest.approx(1.0, abs=1e-3)
    t, p = np.meshgrid(np.radians([5, 30, 60, 75, 85]), np.radians([0, 35, 90, 160, 250]))
    k = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    exact = pw.smith_g1(k, 0.2, 0.45, dist)
    assert np.abs(mf.shadowing_table(g, d, k) - exact).max() < 1e-3
    assert np.abs(mf.shadowing_table(g, 7.0 * d, k) - exact).max() < 1e-3    # scale-free
    assert exact.min() < 0.8                                   # the test reaches real shadowing


def test_shadowing_on_rings_equals_the_direct_integral():
    g = HalfGrid(31, 60)
    d = np.roll(pw.ndf(g.directions(), 0.3, 0.1, "ggx"), 5, axis=1)
    tk = np.radians([0.0, 20.0, 70.0, 88.0])
    t, p = np.meshgrid(tk, g.phi, indexing="ij")
    k = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    np.testing.assert_allclose(mf.shadowing_rings(g, d, tk).ravel(),
                               mf.shadowing_table(g, d, k), atol=1e-12)


def test_fresnel_of_eq3_limits():
    eta = 1.5
    assert fresnel(1.0, eta) == pytest.approx(((eta - 1) / (eta + 1)) ** 2)
    assert fresnel(1e-9, eta) == pytest.approx(1.0, abs=1e-6)


def test_measurement_files_round_trip_and_reject_bad_fields(tmp_path):
    m = sy.measure(sy.direction(35, 20), sy.fibonacci_lights(50), channel_scale=(1, 0.5))
    for name in ("m.npz", "m.csv"):
        m.save(tmp_path / name)
        back = Measurements.load(tmp_path / name)
        np.testing.assert_allclose(back.values, m.values, rtol=1e-9)
        np.testing.assert_allclose(back.view, m.view, rtol=1e-9)
    with pytest.raises(FileFormatError, match="field 'view'"):
        Measurements.from_arrays([0.5, 0, -0.8], m.lights, m.values)
    with pytest.raises(FileFormatError, match="field 'values'"):
        Measurements.from_arrays(m.view, m.lights, m.values[:-1])
    text = (tmp_path / "m.csv").read_text().splitlines()
    text[2] = ",".join(text[2].split(",")[:3] + ["0", "0", "1"] + text[2].split(",")[6:])
    (tmp_path / "bad.csv").write_text("\n".join(text))
    with pytest.raises(FileFormatError, match="view_x/y/z"):
        Measurements.load(tmp_path / "bad.csv")


def _fit(view_deg, rot, grid, constrained=True, alpha=ALPHA, seed=1, n=800):
    m = sy.measure(sy.direction(view_deg, 10.0), sy.fibonacci_lights(n, 85.0), "ggx", *alpha,
                   rot, noise=0.01, seed=seed)
    return fit_partial_ndf(m, grid, constrained=constrained), m


@pytest.mark.slow
@pytest.mark.parametrize("view_deg", [30.0, 45.0])
def test_single_view_fit_recovers_anisotropic_ggx_over_omega(view_deg):
    g = HalfGrid(91, 180)
    part, m = _fit(view_deg, 20.0, g)
    # eq. (10)/(12): W = sqrt(reflect(o, h) . n) inside Omega, 0 outside
    i_h = mf.reflect(m.view, g.directions())
    assert np.all(part.w[i_h[..., 2] <= 0] == 0)
    det = part.w > 0
    np.testing.assert_allclose(part.w[det], np.sqrt(i_h[..., 2][det]))
    assert 0.2 < part.coverage < 0.3
    err = _rel_l2(g, part.d, _truth(g, 20.0), det)
    assert err < 0.05, err
    assert part.residual < 0.02                         # the model fits its data (1 % noise)


@pytest.mark.slow
def test_constrained_shadowing_has_lower_bias_than_unconstrained():
    g = HalfGrid(61, 120)
    for view_deg, alpha in ((40.0, ALPHA), (45.0, (0.3, 0.15))):
        truth = _truth(g, 20.0, alpha)
        bias = []
        for constrained in (True, False):
            part, _ = _fit(view_deg, 20.0, g, constrained, alpha)
            wts = g.weights * (part.w > 0)
            bias.append(np.sum(wts * np.nan_to_num(part.d - truth)) / np.sum(wts * truth))
        assert abs(bias[0]) < abs(bias[1]), (view_deg, bias)


@pytest.mark.slow
def test_completion_from_four_rotated_partial_ndfs_recovers_the_full_ndf():
    g = HalfGrid(46, 90)
    rots = [15.0, 95.0, 170.0, 260.0]
    parts = [_fit(40.0, r, g, seed=k)[0] for k, r in enumerate(rots)]
    done = cp.complete_ndf(parts[0], parts[1:])
    merged = [n for n in done.notes if n.startswith("merged")]
    assert len(merged) >= 2
    for note in merged:                 # the rotation found is a true one (GGX: mod 180 deg)
        j, ang = int(note.split()[3]), float(note.split()[6])
        off = (ang - (rots[j] - rots[0])) % 180.0
        assert min(off, 180.0 - off) < 2.5, note
    assert done.coverage > 1.5 * parts[0].coverage      # GGX is point-symmetric: some merges
                                                        # land on covered ground
    d, filled = cp.fill_uncovered(done)
    d /= g.projected_area(d)
    truth = _truth(g, rots[0])
    assert _rel_l2(g, d, truth) < 0.10
    assert _rel_l2(g, d, truth, done.w > 0) < 0.05


def test_merge_is_the_confidence_weighted_mean_of_eq16_17():
    g = HalfGrid(5, 8)
    d1, d2 = np.full((5, 8), 2.0), np.full((5, 8), 8.0)
    w1, w2 = np.full((5, 8), 0.25), np.full((5, 8), 0.75)
    w1[0] = 0.0
    d, w = cp.merge(g, d1, w1, d2, w2, s1=1.0, s2=2.0)           # D2 scaled by s1/s2 = 1/2
    np.testing.assert_allclose(d[1:], (0.25 * 2 + 0.75 * 4) / 1.0)
    np.testing.assert_allclose(d[0], 4.0)
    np.testing.assert_allclose(w, np.maximum(w1, w2))


def test_symmetry_images_map_h_as_stated():
    g = HalfGrid(7, 12)
    h = g.directions()
    d = 1.0 + h[..., 0] + 2.0 * h[..., 1]                        # no symmetry of its own
    part = PartialNDF(g, d, np.ones_like(d))
    expect = {"point": 1 - h[..., 0] - 2 * h[..., 1], "mirror-x": 1 + h[..., 0] - 2 * h[..., 1],
              "mirror-y": 1 - h[..., 0] + 2 * h[..., 1]}
    for name, ref in expect.items():
        np.testing.assert_allclose(cp.symmetry_images(part, name)[0].d, ref, atol=1e-12)
    with pytest.raises(ValueError, match="choose one of"):
        cp.symmetry_images(part, "cubic")


def test_fill_reproduces_a_constant_and_a_full_table_is_normalised(tmp_path):
    g = HalfGrid(19, 36)
    d = np.full((19, 36), 3.0)
    w = np.ones_like(d)
    w[10:] = 0.0
    part = PartialNDF(g, np.where(w > 0, d, np.nan), w, channel_scale=np.array([1.0, 0.5]),
                      channels=("r", "g"))
    filled, frac = cp.fill_uncovered(part)
    np.testing.assert_allclose(filled, 3.0)
    zero = cp.fill_uncovered(part, "zero")[0]
    np.testing.assert_allclose(zero[-1], 0.0)
    assert np.all(np.diff(zero[9:, 0]) < 0)              # falls from the data to the horizon
    with pytest.raises(ValueError, match="horizon"):
        cp.fill_uncovered(part, "cubic")
    assert frac == pytest.approx(np.sum(g.weights[10:]) / np.sum(g.weights))
    with pytest.raises(InfeasibleError, match="--fill"):
        save_ndf(tmp_path / "x.npz", part)
    out = save_ndf(tmp_path / "x.npz", part, fill=True)
    z = np.load(tmp_path / "x.npz")
    assert g.projected_area(z["D"]) == pytest.approx(1.0)
    np.testing.assert_allclose(z["ks"], 3.0 * g.projected_area(np.ones((19, 36))) * np.array(
        [1.0, 0.5]))
    assert out["filled"] == pytest.approx(frac)
    assert np.all(np.diff(z["theta"]) > 0) and z["theta"][-1] == pytest.approx(np.pi / 2)
    assert z["phi"][0] == 0.0 and z["phi"][-1] < 2 * np.pi


def test_cli_fit_ndf_refuses_an_incomplete_table_and_writes_a_partial_one(tmp_path, capsys):
    m = sy.measure(sy.direction(40, 0), sy.fibonacci_lights(300, 85), "ggx", 0.3, 0.5)
    m.save(tmp_path / "view.npz")
    out = tmp_path / "ndf.npz"
    assert main(["fit-ndf", str(tmp_path / "view.npz"), "-o", str(out), "--grid", "19x36"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "% of the hemisphere only" in err and not out.exists()
    assert main(["fit-ndf", str(tmp_path / "view.npz"), "-o", str(out), "--grid", "19x36",
                 "--partial", "--symmetry", "point"]) == 0
    z = np.load(out)
    assert z["D"].shape == (19, 36) and bool(z["partial"])
    assert np.all(np.isnan(z["D"]) == (z["W"] == 0)) and np.isnan(z["D"]).any()
    assert main(["fit-ndf", str(tmp_path / "view.npz"), "-o", str(out), "--grid", "19"]) == 2


def test_fit_plot_panels_have_labelled_axes_and_ticks(tmp_path, capsys):
    """fit-ndf --plot: each panel (D, W) is the projected hemisphere of normals with labelled
    h_x, h_y axes and ticks from -1 to 1, and the PNG is written."""
    from layersim.ndf.fitplot import fit_figure
    g = HalfGrid(19, 36)
    d = np.ones((19, 36))
    w = np.where(np.arange(19)[:, None] < 10, 1.0, 0.0) * np.ones((1, 36))
    fig = fit_figure(g, d, w, title="t")
    panels = [ax for ax in fig.axes if ax.get_title()]
    assert [ax.get_title() for ax in panels] == ["D [1/sr]", "confidence W"]
    for ax in panels:
        assert "h_x" in ax.get_xlabel() and "h_y" in ax.get_ylabel()
        assert list(ax.get_xticks()) == [-1.0, -0.5, 0.0, 0.5, 1.0] == list(ax.get_yticks())
    m = sy.measure(sy.direction(40, 0), sy.fibonacci_lights(300, 85), "ggx", 0.3, 0.5)
    m.save(tmp_path / "view.npz")
    assert main(["fit-ndf", str(tmp_path / "view.npz"), "-o", str(tmp_path / "n.npz"),
                 "--grid", "19x36", "--partial", "--plot", str(tmp_path / "n.png")]) == 0
    assert (tmp_path / "n.png").stat().st_size > 0


@pytest.mark.slow
def test_cli_fit_ndf_completes_from_rotated_samples_and_plots(tmp_path, capsys):
    g = HalfGrid(31, 60)
    view, lights = sy.direction(40, 0), sy.fibonacci_lights(600, 85)
    files = []
    for k, rot in enumerate([15.0, 100.0, 190.0, 280.0]):
        files.append(tmp_path / f"m{k}.csv")
        sy.measure(view, lights, "beckmann", 0.2, 0.4, rot, noise=0.01, seed=k,
                   channel_scale=(0.8, 0.4)).save(files[-1])
    out, png = tmp_path / "ndf.npz", tmp_path / "ndf.png"
    assert main(["fit-ndf", str(files[0]), "-o", str(out), "--complete", *map(str, files[1:]),
                 "--fill", "zero", "--grid", "31x60", "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert text.count("merged partial NDF") >= 2 and "projected area" in text
    z = np.load(out)
    assert g.projected_area(z["D"]) == pytest.approx(1.0)
    assert _rel_l2(g, z["D"], sy.analytic_ndf("beckmann", 0.2, 0.4, 15.0)[0](
        g.directions())) < 0.03
    np.testing.assert_allclose(z["ks"], [0.8, 0.4], rtol=0.03)   # Beckmann: nothing beyond
    assert png.stat().st_size > 10_000                           # the reach of the views


@pytest.mark.slow
def test_fitted_table_is_a_layer_the_planner_takes(tmp_path, capsys):
    """The measured-microstructure workflow end to end: four rotated single-view samples ->
    fit-ndf (point symmetry stated, uncovered normals filled) -> a tabulated conductor under a
    coat that the scene reader validates and the planner sizes like the analytic lobe."""
    view, lights = sy.direction(40, 0), sy.fibonacci_lights(600, 85)
    files = []
    for k, rot in enumerate([15.0, 100.0, 190.0, 280.0]):
        files.append(tmp_path / f"m{k}.csv")
        sy.measure(view, lights, "beckmann", 0.2, 0.4, rot, noise=0.01, seed=k).save(files[-1])
    out = tmp_path / "ndf.npz"
    assert main(["fit-ndf", str(files[0]), "-o", str(out), "--complete", *map(str, files[1:]),
                 "--fill", "zero", "--symmetry", "point"]) == 0
    capsys.readouterr()
    import layersim
    from layersim.plan import make_plan
    coat = {"kind": "dielectric", "ior": 1.5, "roughness": 0.1}
    gold = {"kind": "conductor", "ior": [0.143552, 3.98397]}
    fitted = make_plan({"layer": [coat, {**gold, "distribution": "tabulated", "ndf": str(out)}]})
    analytic = make_plan({"layer": [coat, {**gold, "roughness": [0.2, 0.4],
                                           "rotation": 15.0}]})
    assert fitted.representation == "anisotropic" and fitted.ms >= 1
    assert abs(fitted.n - analytic.n) <= 0.25 * analytic.n
    with pytest.raises(layersim.SceneError, match="ndf"):
        make_plan({"layer": [coat, {**gold, "distribution": "tabulated",
                                    "ndf": str(tmp_path / "missing.npz")}]})
