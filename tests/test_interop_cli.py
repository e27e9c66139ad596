"""The export / eval / plot commands and the pictures behind them: the same f from a scene, a
saved BSDF and an exported .bsdf file; PNGs that show what they claim (slices integrate to the
albedo on the projected disk, lobes where reflection and Snell's law put them); bad input gives
one line and exit status 2."""

import re

import matplotlib.image
import numpy as np
import pytest

import layersim
from layersim.solved import plot
from layersim.cli import main as cli_main

from conftest import unit

GLASS_TOML = """
[stack]
name = "glass"

[[layer]]
kind = "dielectric"
ior = 1.5
roughness = 0.3

[discretization]
n = 48
md = 64
"""

RGB_TOML = """
[[layer]]
kind = "dielectric"
ior = 1.5
roughness = 0.3

[[layer]]
kind = "conductor"
ior = [[0.143552, 3.98397], [0.377438, 2.38495], [1.43825, 1.60434]]
roughness = 0.3

[discretization]
n = 48
md = 64
"""


BRUSHED_TOML = """
[stack]
name = "brushed"

[[layer]]
kind = "conductor"
ior = [0.2, 3.0]
roughness = [0.4, 0.2]
rotation = 30

[discretization]
n = 24
md = 10
"""


@pytest.fixture(scope="module")
def glass_files(tmp_path_factory):
    """Scene files, and the glass and RGB stacks solved once and saved (.lsim)."""
    d = tmp_path_factory.mktemp("cli")
    (d / "glass.toml").write_text(GLASS_TOML)
    (d / "rgb.toml").write_text(RGB_TOML)
    layersim.solve(layersim.Scene.from_toml(d / "rgb.toml")).save(d / "rgb.lsim")
    layersim.solve(layersim.Scene.from_toml(d / "glass.toml")).save(d / "glass.lsim")
    return d


@pytest.fixture(scope="module")
def glass(glass_files):
    return layersim.BSDF.load(glass_files / "glass.lsim")


def _f(out: str) -> np.ndarray:
    line = [l for l in out.splitlines() if l.startswith("f")][-1]
    return np.array([float(x) for x in re.findall(r"[-+0-9.eE]+(?= )", line.split("=")[1])])


def test_eval_is_the_same_from_a_scene_a_saved_bsdf_and_a_bsdf_file(glass_files, glass,
                                                                    capsys):
    d = glass_files
    assert cli_main(["export", str(d / "glass.toml"), "-o", str(d / "glass.bsdf")]) == 0
    out = capsys.readouterr().out
    assert "SCATFUN v1, 50 nodes" in out and f"{(d / 'glass.bsdf').stat().st_size} bytes" in out
    values = []
    for src in ("glass.toml", "glass.lsim", "glass.bsdf"):
        # a negative first component right after --wo must not be taken for an option
        assert cli_main(["eval", str(d / src), "--wi", "0.3,0.2,0.933", "--wo",
                         "-0.2,-0.13,-0.97"]) == 0
        values.append(_f(capsys.readouterr().out))
    assert values[0].size == 1 and values[0][0] > 0
    np.testing.assert_allclose(values, values[0][0], rtol=1e-5)
    wi, wo = np.array([0.3, 0.2, 0.933]), np.array([-0.2, -0.13, -0.97])
    expected = glass.eval(wi / np.linalg.norm(wi), wo / np.linalg.norm(wo))
    assert values[0][0] == pytest.approx(float(expected), rel=1e-5)


def test_eval_prints_one_value_per_channel(glass_files, capsys):
    assert cli_main(["eval", str(glass_files / "rgb.lsim"), "--wi", "0,0,1", "--wo",
                     "0.1,0,0.99"]) == 0
    out = capsys.readouterr().out
    assert "f (R G B)" in out
    f = _f(out)
    assert f.size == 3 and f[0] > f[2] > 0          # gold: red above blue


def test_energy_notes_go_into_the_bsdf_info_and_info_prints_them(glass_files, glass, tmp_path,
                                                                  capsys):
    from layersim.operators.energy import check_operator_energy
    scene = layersim.Scene.from_toml(glass_files / "glass.toml")
    plan = layersim.make_plan(scene)
    before = list(plan.notes)
    over = glass.operators[0].map_blocks(lambda mat: mat * 1.002)   # 0.2 % too much energy
    notes = check_operator_energy(over, 0, scene.layers[0], plan.n)
    assert len(notes) == 1 and "over-counted energy" in notes[0]
    assert plan.notes == before                                      # the plan is not touched
    alb = over.albedo()
    assert np.max(alb["Rt"] + alb["Ttb"]) <= 1.0 + 1e-12            # and the excess is removed
    saved = layersim.BSDF(glass.operators, None, {**glass.info, "notes": notes})
    saved.save(tmp_path / "noted.lsim")
    assert cli_main(["info", str(tmp_path / "noted.lsim")]) == 0
    assert f"note: {notes[0]}" in capsys.readouterr().out


def test_export_version_2(glass_files, capsys):
    out_file = glass_files / "glass_v2.bsdf"
    assert cli_main(["export", str(glass_files / "glass.lsim"), "-o", str(out_file),
                     "--version", "2", "--alpha", "0.3,0.3"]) == 0
    assert "SCATFUN v2" in capsys.readouterr().out
    table = layersim.bsdffile.read(out_file)
    assert table.version == 2 and table.alpha == pytest.approx((0.3, 0.3))


@pytest.mark.slow
def test_anisotropic_scene_exports_evaluates_and_plots(tmp_path, capsys):
    """A rotated brushed metal: export writes version 2 with complex coefficients by default
    (version 1 is refused), eval of the file equals eval of the scene (and of the solved BSDF;
    the mirrored direction gives another value, so the comparison sees the rotation), and the
    slices drawn from the file are those drawn from the scene."""
    scene, out = tmp_path / "brushed.toml", tmp_path / "brushed.bsdf"
    scene.write_text(BRUSHED_TOML)
    assert cli_main(["export", str(scene), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "SCATFUN v2" in text and "(complex)" in text and f"{out.stat().st_size} bytes" in text
    table = layersim.bsdffile.read(out)
    assert table.version == 2 and table.is_complex and table.max_order[0] > 1
    wi, wo = np.array([0.5, 0.1, 0.86]), np.array([-0.3, 0.4, 0.866])
    values = []
    for src, w in ((scene, wo), (out, wo), (out, wo * [1, -1, 1])):
        assert cli_main(["eval", str(src), "--wi", ",".join(map(str, wi)), "--wo",
                         ",".join(map(str, w))]) == 0
        values.append(_f(capsys.readouterr().out)[0])
    bsdf = layersim.solve(layersim.Scene.from_toml(scene))
    expected = float(bsdf.eval(wi / np.linalg.norm(wi), wo / np.linalg.norm(wo)))
    assert values[0] == pytest.approx(expected, rel=1e-5)
    assert values[1] == pytest.approx(expected, rel=1e-5)
    assert abs(values[2] / values[1] - 1) > 0.05
    for src in (scene, out):
        assert cli_main(["plot", str(src), "--wi", "30,20", "-o",
                         str(tmp_path / f"{src.suffix[1:]}.png")]) == 0
    a, b = (matplotlib.image.imread(tmp_path / f"{x}.png") for x in ("toml", "bsdf"))
    assert a[..., :3].std() > 0.05 and np.abs(a - b).max() < 2 / 255
    assert cli_main(["plot", str(out), "--blocks", "--order", "1", "-o",
                     str(tmp_path / "blocks.png")]) == 0
    assert matplotlib.image.imread(tmp_path / "blocks.png")[..., :3].std() > 0.05
    assert cli_main(["export", str(scene), "--version", "1", "-o", str(tmp_path / "v1.bsdf")]) \
        == 2
    assert "isotropic BSDFs only" in capsys.readouterr().err


def test_plot_writes_slices_and_blocks(glass_files, capsys):
    d = glass_files
    assert cli_main(["plot", str(d / "glass.lsim"), "--wi", "40,30", "-o",
                     str(d / "slices.png")]) == 0
    assert cli_main(["plot", str(d / "glass.lsim"), "--blocks", "--order", "1", "-o",
                     str(d / "blocks.png")]) == 0
    assert cli_main(["plot", str(d / "rgb.lsim"), "--wi", "20,0", "--log", "-o",
                     str(d / "rgb.png")]) == 0
    for name in ("slices.png", "blocks.png", "rgb.png"):
        img = matplotlib.image.imread(d / name)
        assert img.ndim == 3 and img.shape[0] > 300 and img.shape[1] > 300
        assert img[..., :3].std() > 0.05                    # not a blank canvas
    assert "wrote" in capsys.readouterr().out


@pytest.mark.parametrize("argv,words", [
    (["eval", "{d}/glass.toml", "--wi", "0.3,0.2", "--wo", "0,0,1"], "3 comma-separated"),
    (["eval", "{d}/glass.toml", "--wi", "0,0,0", "--wo", "0,0,1"], "nonzero"),
    (["eval", "{d}/missing.toml", "--wi", "0,0,1", "--wo", "0,0,1"], "No such file"),
    (["export", "{d}/junk.txt"], "not a scene"),
    (["export", "{d}/junk.bsdf"], "flag 0x01"),
    (["plot", "{d}/glass.toml", "--wi", "90,0"], "horizon"),
    (["plot", "{d}/glass.toml"], "exactly one of"),
    (["plot", "{d}/glass.toml", "--blocks", "--order", "-1"], "order"),
    (["export", "{d}/glass.toml", "--relerr", "1.5"], "[0, 1)"),
])
def test_bad_input_prints_one_line_and_exits_2(glass_files, capsys, argv, words):
    d = glass_files
    (d / "junk.txt").write_text("hello")
    (d / "junk.bsdf").write_bytes(b"SCATFUN\x01" + bytes(80))
    assert cli_main([a.format(d=d) for a in argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("layersim: error:") and words in err[0]


# ---- what the pictures show --------------------------------------------------------------------

def test_slices_integrate_to_the_albedo_and_peak_where_physics_says(glass):
    wi = unit(40.0, 30.0)
    res = 200
    imgs = plot.slice_images(glass, wi, resolution=res)
    R, T = glass.albedo(wi)
    pixel = (2.0 / res) ** 2                  # on the projected disk, dA = |cos| d omega
    assert np.nansum(imgs["reflection"]) * pixel == pytest.approx(float(R), rel=0.02)
    assert np.nansum(imgs["transmission"]) * pixel == pytest.approx(float(T), rel=0.02)
    # the transmitted lobe peaks near the refracted direction (Snell: sin = sin 40 / 1.5),
    # opposite to the incident azimuth; rows are wo.y, columns wo.x
    t = np.nan_to_num(imgs["transmission"])
    r_, c_ = np.unravel_index(np.argmax(t), t.shape)
    x, y = (c_ + 0.5) / res * 2 - 1, (r_ + 0.5) / res * 2 - 1
    s = np.sin(np.radians(40.0)) / 1.5
    assert np.hypot(x + s * np.cos(np.radians(30)), y + s * np.sin(np.radians(30))) < 0.06


def test_log_slices_of_an_rgb_bsdf_are_logarithmic(glass_files, tmp_path):
    """--log draws RGB slices on a log scale too: the picture differs from the linear one,
    and each pixel keeps its colour with its luminance mapped to log10 over LOG_DECADES
    decades below the largest (0 at the floor, 1 at the top)."""
    rgb = layersim.BSDF.load(glass_files / "rgb.lsim")
    wi = unit(20.0)
    lin = matplotlib.image.imread(plot.plot_slices(rgb, wi, tmp_path / "lin.png"))
    log = matplotlib.image.imread(plot.plot_slices(rgb, wi, tmp_path / "log.png", log=True))
    assert lin.shape == log.shape and np.abs(lin - log).max() > 0.2
    img = np.nan_to_num(plot.slice_images(rgb, wi, resolution=64)["reflection"])
    lum = img @ layersim.solved.channels.LUMINANCE
    top = lum.max()
    toned, norm = plot._log_tone(img, lum, top)
    level = toned @ layersim.solved.channels.LUMINANCE
    expect = np.clip(np.log10(np.maximum(lum, 1e-300) / top) / plot.LOG_DECADES + 1, 0, 1)
    np.testing.assert_allclose(level, expect, atol=1e-12)
    lit = lum > top * 1e-3
    np.testing.assert_allclose(toned[lit] / level[lit, None], img[lit] / lum[lit, None],
                               rtol=1e-10)                      # the same chromaticity
    assert norm.vmin == pytest.approx(top * 10.0 ** -plot.LOG_DECADES) and norm.vmax == top


def test_block_plots_say_where_their_colour_scale_clips(glass, glass_files, tmp_path,
                                                        capsys):
    """Each panel's scale ends at the 99th percentile (layerlab's choice): where brighter
    values saturate the colour bar has an arrow on that side and its label names the
    percentile and the largest value; --percentile 100 shows the full range, unlabelled."""
    imgs = plot.block_images(glass, samples=50)
    vmax, extend, note = plot.colour_scale(imgs["Ttb"], False, 99.0)
    assert vmax == pytest.approx(np.percentile(imgs["Ttb"], 99)) and vmax < imgs["Ttb"].max()
    assert extend == "max" and note == f"clipped at 99th percentile, max {imgs['Ttb'].max():.3g}"
    assert plot.colour_scale(imgs["Ttb"], False, 100.0) == (imgs["Ttb"].max(), "neither", "")
    signed = plot.block_images(glass, order=1, samples=50)["Ttb"]
    vmax, extend, note = plot.colour_scale(signed, True, 99.0)
    assert vmax == pytest.approx(np.percentile(np.abs(signed), 99))
    assert extend == {(True, True): "both", (True, False): "max", (False, True): "min"}[
        (signed.max() > vmax, signed.min() < -vmax)] and "|value|" in note
    d = glass_files
    for pct in ("99", "100"):
        assert cli_main(["plot", str(d / "glass.lsim"), "--blocks", "--percentile", pct, "-o",
                         str(tmp_path / f"{pct}.png")]) == 0
    a, b = (matplotlib.image.imread(tmp_path / f"{p}.png") for p in ("99", "100"))
    assert a.shape != b.shape or np.abs(a - b).max() > 0.1
    assert cli_main(["plot", str(d / "glass.lsim"), "--blocks", "--percentile", "0"]) == 2
    assert "--percentile must be in (0, 100]" in capsys.readouterr().err


def test_block_images_of_a_lambertian_layer():
    """f = albedo / (2 pi sum w mu) in Rt only, in order 0 and at every azimuth; order 1 is 0."""
    bsdf = layersim.solve(layersim.Scene.from_dict({"layer": [{"kind": "diffuse",
                                                                "albedo": 0.5}]}))
    f = 0.5 / (2 * np.pi * bsdf.grid.flux_weight.sum())
    for kwargs in ({"order": 0}, {"phi_d": 1.0}):
        imgs = plot.block_images(bsdf, samples=20, **kwargs)
        mu = (np.arange(20) + 0.5) / 20
        np.testing.assert_allclose(imgs["Rt"], f * np.outer(mu[::-1], mu), rtol=1e-9)
        for name in ("Rb", "Ttb", "Tbt"):
            assert np.all(imgs[name] == 0)
    assert np.all(plot.block_images(bsdf, order=1, samples=10)["Rt"] == 0)


def test_block_images_follow_snells_law(glass):
    """T^tb at phi_d = 0 peaks, for incident mu_i, near the refracted mu_o (for alpha = 0.3 the
    peak moves toward the normal as the incidence grazes: within 0.04 down to mu_i = 0.6)."""
    img = plot.block_images(glass, samples=100)["Ttb"]       # [mu_o, mu_i]
    mu = (np.arange(100) + 0.5) / 100
    for k in (60, 80, 95):
        mu_t = np.sqrt(1 - (1 - mu[k] ** 2) / 1.5 ** 2)
        assert abs(mu[np.argmax(img[:, k])] - mu_t) < 0.04
