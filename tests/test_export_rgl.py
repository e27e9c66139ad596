"""RGL tensor export (layersim.bsdffile.rgl): the container, the warp against Mitsuba 3's own,
files loaded unchanged by Mitsuba 3's ``measured`` plug-in whose ``eval`` matches the solved
BSDF within the error the export reports, ``sample``/``pdf`` consistency, colour round trips,
reading our own files back, and the refusals."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import layersim
from layersim.bsdffile import cie, rgl, rgl_color, rgl_error, tensorfile
from layersim.bsdffile.marginal2d import Marginal2D
from layersim.errors import FileFormatError, InfeasibleError

try:
    import mitsuba as mi
except ImportError:                                     # pragma: no cover
    mi = None

ROOT = Path(__file__).resolve().parent.parent
needs_mitsuba = pytest.mark.skipif(mi is None, reason="mitsuba (Mitsuba 3) is not importable")

CONDUCTOR = {"layer": [{"kind": "conductor", "ior": [0.2, 3.9], "roughness": 0.2}]}
ANISO = {"layer": [{"kind": "conductor", "ior": [0.2, 3.9], "roughness": [0.15, 0.35],
                    "rotation": 30}]}
GOLD_RGB = {"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.15},
                      {"kind": "conductor", "roughness": 0.2,
                       "ior": [[0.143552, 3.98397], [0.374, 2.38], [1.442, 1.846]]}]}


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """Solved BSDFs and their RGL exports, built once: name -> (bsdf, RGLExport)."""
    folder = tmp_path_factory.mktemp("rgl")
    out = {}

    def get(name):
        if name not in out:
            scene, kw = {"conductor": (CONDUCTOR, {}),
                         "coated_gold": (ROOT / "examples/coated_gold.toml", {}),
                         "aniso": (ANISO, {"resolution": 12}),
                         "gold_rgb": (GOLD_RGB, {"resolution": 16}),
                         "gold_rgb_field": (GOLD_RGB, {"resolution": 16, "color": "rgb"})}[name]
            bsdf = layersim.solve(scene)
            out[name] = (bsdf, rgl.export(bsdf, folder / f"{name}.bsdf", **kw))
        return out[name]
    return get


def _mitsuba_evaluator(path, variant, lam):
    """``evaluate(wi, wo)`` -> (n, len(lam)) by Mitsuba 3's ``measured`` plug-in, loading
    ``path`` unchanged (``lam``: wavelengths, or channel indices in an RGB variant)."""
    mi.set_variant(variant)
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    ctx = mi.BSDFContext()

    def evaluate(wi, wo):
        out = np.zeros((len(wi), len(lam)))
        for k in range(len(wi)):
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*wi[k])
            if variant.endswith("spectral"):
                for a in range(0, len(lam), 4):
                    chunk = list(lam[a:a + 4]) + [lam[0]] * (4 - len(lam[a:a + 4]))
                    si.wavelengths = mi.Spectrum(chunk)
                    val = np.array(bsdf.eval(ctx, si, mi.Vector3f(*wo[k])))
                    out[k, a:a + 4] = val[:len(lam[a:a + 4])]
            else:
                out[k] = np.array(bsdf.eval(ctx, si, mi.Vector3f(*wo[k])))[lam]
        return out
    return bsdf, evaluate


# ---- container, warp, colour tables (fast) -----------------------------------------------

def test_tensorfile_round_trip_and_bad_files(tmp_path):
    fields = {"a": np.arange(6, dtype=np.float32).reshape(2, 3),
              "flag": np.array([1], np.uint8), "b": np.linspace(0, 1, 5)}
    path = tensorfile.write(tmp_path / "x.tensor", fields)
    data = path.read_bytes()
    assert data[:12] == b"tensor_file\0" and data[12:14] == bytes([1, 0])
    back = tensorfile.read(path)
    assert list(back) == list(fields)
    for k in fields:
        assert back[k].dtype == fields[k].dtype and np.array_equal(back[k], fields[k])
    with pytest.raises(FileFormatError, match="header"):
        tensorfile.from_bytes(b"not a tensor file at all")
    with pytest.raises(FileFormatError, match="past the end"):
        tensorfile.from_bytes(data[:-4])
    with pytest.raises(FileFormatError, match="missing.tensor: cannot read"):
        tensorfile.read(tmp_path / "missing.tensor")


@needs_mitsuba
def test_marginal2d_matches_mitsuba():
    """sample, invert and eval of the numpy warp against Mitsuba 3's MarginalContinuous2D2."""
    mi.set_variant("scalar_rgb")
    rng = np.random.default_rng(1)
    data = (rng.random((3, 4, 7, 9)) + 0.1).astype(np.float32)
    p0, p1 = np.array([0.0, 1.0, 2.5], np.float32), np.array([0, 0.3, 0.5, 1.2], np.float32)
    ours = Marginal2D(data, [p0, p1])
    theirs = mi.MarginalContinuous2D2(data, [p0.tolist(), p1.tolist()])
    u = rng.random((40, 2))
    par = (rng.random(40) * 2.7 - 0.1, rng.random(40) * 1.4 - 0.1)     # incl. clamped ends
    pts, pdf = ours.sample(u, par)
    back, _ = ours.invert(pts, par)
    assert np.max(np.abs(back - u)) < 1e-12
    for k in range(40):
        q, d = theirs.sample(mi.Point2f(u[k]), [par[0][k], par[1][k]])
        assert np.allclose(np.array(q), pts[k], atol=2e-5) and d == pytest.approx(pdf[k], 1e-4)
        e = theirs.eval(mi.Point2f(pts[k]), [par[0][k], par[1][k]])
        assert e == pytest.approx(ours.eval(pts[k:k + 1], (par[0][k:k + 1],
                                                          par[1][k:k + 1]))[0], rel=1e-5)


@needs_mitsuba
def test_cie_tables_and_rgb_basis_round_trip():
    """The CIE tables are Mitsuba's, and the spectrum written for an RGB value has that sRGB
    value by Mitsuba's own conversion (spectrum_list_to_srgb with D65)."""
    mi.set_variant("scalar_rgb")
    for k, lam in enumerate(cie.NODES):
        assert np.allclose(list(mi.cie1931_xyz(float(lam))),
                           [cie.XBAR[k], cie.YBAR[k], cie.ZBAR[k]], rtol=1e-6, atol=1e-9)
        assert mi.cie_d65(float(lam)) == pytest.approx(cie.D65[k], rel=1e-6)
    for rgb in ([0.9, 0.6, 0.3], [0.2, 0.5, 0.8], [1.0, 1.0, 1.0], [0.05, 0.04, 0.03]):
        spec = rgl_color.to_spectra(np.array(rgb))
        back = mi.spectrum_list_to_srgb(rgl_color.WAVELENGTHS.tolist(), spec.tolist(),
                                        bounded=False, d65=True)
        assert np.allclose(np.array(back), rgb, rtol=2e-4, atol=1e-6)
        assert np.allclose(rgl_color.to_rgb(spec), rgb, rtol=1e-10)


# ---- exports loaded by Mitsuba 3 (slow: each solves and tabulates) ------------------------

@pytest.mark.slow
@needs_mitsuba
@pytest.mark.parametrize("name", ["conductor", "coated_gold", "aniso"])
def test_mitsuba_measured_matches_layersim(exported, name):
    """Mitsuba 3 loads the file unchanged; its eval equals the numpy reconstruction (to
    float32) and matches layersim's eval times cos(theta_o) within the reported error."""
    bsdf, res = exported(name)
    assert 0.0 < res.error < 0.25 and 0.0 < res.error_to_80 < 0.25
    _, evaluate = _mitsuba_evaluator(res.path, "scalar_spectral", [550.0])
    rng = np.random.default_rng(7)
    wi = rgl_error.cosine_directions(rng, 300)
    wo = rgl_error.uniform_directions(rng, 300)
    theirs = evaluate(wi, wo)[:, 0]
    ours = rgl.channel_values(res.table, wi, wo, 1)[:, 0]
    assert np.linalg.norm(theirs - ours) <= 2e-4 * np.linalg.norm(ours)
    # the same estimator as the export's, with Mitsuba's eval and other direction pairs
    err = rgl.reconstruction_error(bsdf, res.table, samples=1024, seed=3, evaluate=evaluate)
    assert err <= 2.0 * res.error + 0.02
    t = res.table
    if name == "aniso":                 # pbrt-v4 reads only reduction 1 (phi_i over 2 pi)
        assert not t.isotropic and t.reduction == 1
        assert t.phi_i[0] == pytest.approx(-np.pi) and t.phi_i[-1] == pytest.approx(np.pi)
    else:
        assert t.isotropic and len(t.phi_i) == 1


@pytest.mark.slow
@needs_mitsuba
@pytest.mark.parametrize("name", ["conductor", "aniso"])
def test_mitsuba_sample_pdf_consistent(exported, name):
    """Mitsuba's sample returns the pdf that its pdf() gives (and our numpy pdf), weight =
    eval / pdf, and the mean weight (a furnace test) is the solved albedo within Monte Carlo
    error plus the reconstruction error."""
    bsdf, res = exported(name)
    plugin, _ = _mitsuba_evaluator(res.path, "scalar_spectral", [550.0])
    ctx = mi.BSDFContext()
    rng = np.random.default_rng(11)
    for theta in (0.3, 1.0):
        wi = np.array([np.sin(theta) * np.cos(0.4), np.sin(theta) * np.sin(0.4),
                       np.cos(theta)])
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*wi)
        si.wavelengths = mi.Spectrum([550.0] * 4)
        weights = []
        for k in range(4000):
            bs, w = plugin.sample(ctx, si, 0.5, mi.Point2f(*rng.random(2)))
            weights.append(float(np.array(w)[0]))
            if k < 40 and weights[-1] > 0:
                wo = np.array(bs.wo)
                assert plugin.pdf(ctx, si, bs.wo) == pytest.approx(bs.pdf, rel=2e-3)
                assert res.table.pdf(wi[None], wo[None])[0] == pytest.approx(bs.pdf, rel=2e-3)
                f = np.array(plugin.eval(ctx, si, bs.wo))[0]
                assert weights[-1] == pytest.approx(f / bs.pdf, rel=2e-3)
        weights = np.array(weights)
        albedo = float(np.ravel(bsdf.albedo(wi)[0])[0])
        stderr = weights.std() / np.sqrt(len(weights))
        assert abs(weights.mean() - albedo) <= 4 * stderr + 0.03 * albedo


@pytest.mark.slow
@needs_mitsuba
def test_rgb_stack_spectral_round_trip(exported):
    """An RGB stack written as spectra: Mitsuba's spectral eval at the file's wavelengths,
    converted to sRGB as Mitsuba converts reflectance spectra, gives layersim's channels
    within the reported error; the rgb field gives them in Mitsuba's RGB variant."""
    bsdf, res = exported("gold_rgb")
    _, evaluate = _mitsuba_evaluator(res.path, "scalar_spectral", rgl_color.WAVELENGTHS.tolist())
    err = rgl.reconstruction_error(bsdf, res.table, samples=512, seed=5,
                                   evaluate=lambda a, b: rgl_color.to_rgb(evaluate(a, b)))
    assert 0.0 < res.error < 0.25 and err <= 2.0 * res.error + 0.02
    bsdf2, res2 = exported("gold_rgb_field")
    assert res2.table.wavelengths is None and "rgb" in tensorfile.read(res2.path)
    _, evaluate_rgb = _mitsuba_evaluator(res2.path, "scalar_rgb", [0, 1, 2])
    rng = np.random.default_rng(2)
    wi, wo = rgl_error.cosine_directions(rng, 200), rgl_error.uniform_directions(rng, 200)
    theirs = evaluate_rgb(wi, wo)
    ours = rgl.channel_values(res2.table, wi, wo, 3)
    assert np.linalg.norm(theirs - ours) <= 2e-4 * np.linalg.norm(ours)
    # both flavours tabulate the same channels: spectra -> sRGB equals the rgb field
    assert np.allclose(rgl.channel_values(res.table, wi, wo, 3), ours, rtol=1e-4, atol=1e-6)


@pytest.mark.slow
def test_read_back_own_file(exported):
    bsdf, res = exported("conductor")
    back = rgl.read(res.path)
    written = res.table.fields()
    for name, arr in back.fields().items():
        assert np.array_equal(arr, written[name]), name
    rng = np.random.default_rng(4)
    wi, wo = rgl_error.cosine_directions(rng, 100), rgl_error.uniform_directions(rng, 100)
    assert np.array_equal(back.eval(wi, wo, [550.0]), res.table.eval(wi, wo, [550.0]))
    assert "top-side reflection only" in back.description


@pytest.mark.slow
def test_retro_ndf_is_a_fixed_point(exported, monkeypatch):
    """The NDF written is normalised (unit projected area toward the normal), ``sigma`` is
    its projected area, and one more power-iteration step leaves it unchanged."""
    from layersim.bsdffile import rgl_ndf
    bsdf, res = exported("conductor")
    t = res.table
    ndf = np.asarray(t.ndf, np.float64)
    assert rgl_ndf.projected_area(ndf, np.array([0.0, 0.0, 1.0])) == pytest.approx(1.0, 1e-5)
    sigma = rgl_ndf.projected_area(ndf, rgl_ndf.table_directions(ndf.shape[1], ndf.shape[0]))
    assert np.allclose(sigma, t.sigma, rtol=1e-4)

    def retro(w):
        return np.asarray(bsdf.eval(w, w)).reshape(w.shape[:-1])

    base, _ = rgl_ndf.retro_ndf(retro, *ndf.shape[::-1])
    assert np.allclose(base, ndf, rtol=1e-5)               # the file holds this NDF
    monkeypatch.setattr(rgl_ndf, "ITERATIONS", rgl_ndf.ITERATIONS + 1)
    more, _ = rgl_ndf.retro_ndf(retro, *ndf.shape[::-1])
    assert np.linalg.norm(more - base) < 1e-6 * np.linalg.norm(base)
    monkeypatch.setattr(rgl_ndf, "ITERATIONS", 1)
    one, _ = rgl_ndf.retro_ndf(retro, *ndf.shape[::-1])
    assert np.linalg.norm(one - base) > 1e-3 * np.linalg.norm(base)    # iterating matters


# ---- refusals -----------------------------------------------------------------------------

def test_refusals_before_work():
    smooth = layersim.solve({"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.0},
                                       {"kind": "diffuse", "albedo": 0.5}]})
    with pytest.raises(InfeasibleError, match="mirror"):
        rgl.check_exportable(smooth)
    with pytest.raises(TypeError, match="solved BSDF"):
        rgl.check_exportable("x.toml")
    with pytest.raises(ValueError, match="color"):
        rgl.colour_mode(1, None, "xyz")
    with pytest.raises(ValueError, match="wavelengths"):
        rgl.colour_mode(3, [650.0, 550.0], "spectral")
    with pytest.raises(ValueError, match="resolution"):
        rgl.resolution_grid(2, False)


@pytest.mark.slow
def test_transmitting_stack_warns(tmp_path):
    glass = layersim.solve({"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.3}]})
    with pytest.warns(UserWarning, match="reflection only"):
        res = rgl.export(glass, tmp_path / "glass.bsdf", resolution=8, samples=256)
    assert res.notes and res.path.exists()


@pytest.mark.slow
def test_cli_export_rgl(tmp_path):
    out = tmp_path / "g.bsdf"
    run = subprocess.run([sys.executable, "-m", "layersim.cli", "export",
                          "examples/coated_gold.toml", "--format", "rgl", "--resolution", "8",
                          "-o", str(out)], capture_output=True, text=True, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    assert "reconstruction error" in run.stdout and "within 80 deg" in run.stdout
    assert out.exists()
    assert rgl.read(out).spectra.shape[-1] == 8
    bad = subprocess.run([sys.executable, "-m", "layersim.cli", "export",
                          "examples/coated_gold.toml", "--format", "rgl", "--resolution", "2",
                          "-o", str(out)], capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1
    assert "--resolution" in bad.stderr and "Traceback" not in bad.stderr
    bad = subprocess.run([sys.executable, "-m", "layersim.cli", "export",
                          "examples/coated_gold.toml", "--format", "rgl", "--wavelengths",
                          "500,600", "-o", str(out)], capture_output=True, text=True, cwd=ROOT)
    assert bad.returncode == 2 and "wavelengths 500, 600" in bad.stderr


def test_fit_recovers_a_bilinear_remainder():
    """When F is exactly J times a bilinear interpolant of node values, the weighted least
    squares of rgl_fit returns those values (points below the horizon, omega = 0, are left
    out; the regularisation toward other values, here zero, moves a determined fit by less
    than 1e-3)."""
    from layersim.bsdffile import rgl_fit
    rng = np.random.default_rng(3)
    n = 9
    truth = rng.random((n * n, 2)) + 0.5
    pts = rgl_fit.cell_points(n)
    A = rgl_fit.bilinear_matrix(pts, n)
    assert np.allclose(A.sum(axis=1), 1.0)
    jac = rng.random(len(pts)) * 3 + 0.1
    f = jac[:, None] * (A @ truth)
    omega = rng.random(len(pts)) + 0.1
    omega[:10] = 0.0
    f[:10] = 1e6                                   # garbage where omega = 0: ignored
    fit = rgl_fit.fit_slice(A, jac, f, omega, np.zeros_like(truth))
    assert np.allclose(fit, truth, rtol=1e-3)
    assert not np.allclose(rgl_fit.fit_slice(A, jac, f, np.ones(len(pts)),
                                             np.zeros_like(truth)), truth, rtol=1e-2)


def test_rgl_file_as_source_is_refused_by_name(tmp_path):
    """An RGL file given where layersim expects a BSDF is named as what it is."""
    path = tensorfile.write(tmp_path / "m.bsdf", {"x": np.zeros(2, np.float32)})
    with pytest.raises(ValueError, match="RGL material"):
        layersim.BSDF.load(path)
