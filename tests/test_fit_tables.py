"""Fit targets from tabulated files: a Fourier ``.bsdf`` and an RGL ``.bsdf`` written by
``layersim export`` from a known stack, and a MERL binary written from a known stack at the
MERL sample positions, are fit back to that stack's parameters (within what each format's
resolution allows); the samples a careful user leaves out are left out; wrong channels and
unreadable files are refused in one line."""

import time

import numpy as np
import pytest

import layersim
from layersim.bsdffile import rgl_table
from layersim.cli import main
from layersim.errors import FileFormatError
from layersim.fit import as_target, direction_pairs
from layersim.fit.plot import plot_fit
from layersim.fit.tables import MERL_THETA_MAX, TableTarget, read_table
from layersim.layers.merl import half_diff, read_merl, write_merl

#: The hidden opaque stack (one channel) of the .bsdf files, and its free values.
TRUTH = {"layer[0].roughness": 0.3, "layer[1].ior[1]": 3.0, "layer[1].roughness": 0.4}
#: The hidden RGB stack of the MERL file: a rough coat over a coloured Lambertian base.
MERL_TRUTH = {"layer[0].roughness": 0.3, "layer[1].albedo[0]": 0.8,
              "layer[1].albedo[1]": 0.5, "layer[1].albedo[2]": 0.2}


def _scene(coat=0.3, k=3.0, base=0.4) -> dict:
    return {"stack": {"name": "hidden"},
            "layer": [{"kind": "dielectric", "ior": 1.5, "roughness": coat},
                      {"kind": "conductor", "ior": [0.2, k], "roughness": base}]}


def _template() -> dict:
    return {"stack": {"name": "hidden"},
            "layer": [{"kind": "dielectric", "ior": 1.5, "roughness": {"fit": [0.2, 0.5]}},
                      {"kind": "conductor", "ior": [0.2, {"fit": [1.0, 5.0], "start": 2.0}],
                       "roughness": {"fit": [0.25, 0.6], "start": 0.5}}]}


def _merl_scene(albedo=(0.8, 0.5, 0.2)) -> dict:
    return {"stack": {"name": "painted"},
            "layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
                      {"kind": "diffuse", "albedo": list(albedo)}]}


def _merl_template() -> dict:
    free = {"fit": [0.05, 0.95], "start": 0.5}
    return {"stack": {"name": "painted"},
            "layer": [{"kind": "dielectric", "ior": 1.5, "roughness": {"fit": [0.15, 0.6]}},
                      {"kind": "diffuse", "albedo": [free, free, free]}]}


@pytest.fixture(scope="module")
def hidden():
    return layersim.solve(layersim.Scene.from_dict(_scene()))


def from_half_diff(th, td, pd):
    """Directions ``(wi, wo)`` (..., 3) of Rusinkiewicz angles with ``phi_h = 0``: the inverse
    of :func:`layersim.layers.merl.half_diff` (``wo`` is ``wi`` mirrored about the half
    vector)."""
    th, td, pd = np.broadcast_arrays(th, td, pd)
    d = np.stack([np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)], axis=-1)
    ct, st = np.cos(th)[..., None], np.sin(th)[..., None]

    def tilt(v):                            # rotate by theta_h about y: the half vector to z'
        x, y, z = v[..., :1], v[..., 1:2], v[..., 2:]
        return np.concatenate([x * ct + z * st, y, z * ct - x * st], axis=-1)

    return tilt(d), tilt(d * [-1.0, -1.0, 1.0])


def write_merl_of(path, f, unmeasured=None) -> None:
    """A MERL file of ``f(wi, wo)`` (pairs (N, 3) -> RGB BRDF (N, 3), 1/sr) at the MERL sample
    positions; samples with a direction below the surface, and those where
    ``unmeasured(th, td, pd)`` is True, are stored as unmeasured (negative), as MERL does."""
    def brdf(th, td, pd):
        wi, wo = from_half_diff(th, td, pd)
        ok = (wi[..., 2] > 0) & (wo[..., 2] > 0)
        if unmeasured is not None:
            ok &= ~np.broadcast_to(unmeasured(th, td, pd), ok.shape)
        values = np.full(ok.shape + (3,), -1.0)
        values[ok] = np.asarray(f(wi[ok], wo[ok])).reshape(-1, 3)
        return np.moveaxis(values, -1, 0)

    write_merl(path, brdf)


def _unmeasured(th, td, pd):
    """A patch the gantry missed: theta_h 20-30 deg, theta_d 20-40 deg, every phi_d."""
    return ((th > np.radians(20)) & (th < np.radians(30)) & (td > np.radians(20))
            & (td < np.radians(40)))


#: The RGB BRDF (1/sr) of the Lambertian MERL file: distinct channels, to see their order.
LAMBERT = np.array([0.6, 0.3, 0.1]) / np.pi


@pytest.fixture(scope="module")
def merl_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("merl") / "lambert.binary"
    write_merl_of(path, lambda wi, wo: np.tile(LAMBERT, (len(wi), 1)), _unmeasured)
    return path


def test_from_half_diff_inverts_half_diff():
    rng = np.random.default_rng(3)
    th, td = rng.uniform(0, 1.4, (2, 50))
    pd = rng.uniform(0, np.pi, 50)
    back = half_diff(*from_half_diff(th, td, pd))
    assert np.allclose(back, (th, td, pd), atol=1e-12)


@pytest.mark.slow
def test_a_stack_is_recovered_from_its_fourier_bsdf_file(tmp_path, hidden):
    # the file stores the solved operators in float32: the parameters come back to 1e-4
    path = tmp_path / "hidden.bsdf"
    layersim.export(hidden, path)
    t0 = time.perf_counter()
    result = layersim.fit(_template(), path)
    print(f"fit from the .bsdf file: {time.perf_counter() - t0:.1f} s\n{result.summary()}")
    for name, value in result.params.items():
        assert value == pytest.approx(TRUTH[name], rel=1e-4), name
    assert result.residual < 1e-6


@pytest.mark.slow
def test_a_stack_is_recovered_from_its_rgl_file(tmp_path, hidden):
    # resolution 32: the export itself reports a 1.4 % relative L2 error of f cos(theta_o);
    # the parameters come back within 2 %
    path = tmp_path / "hidden.rgl.bsdf"
    export = layersim.export(hidden, path, format="rgl")
    assert export.error < 0.02
    result = layersim.fit(_template(), path)
    print(result.summary())
    for name, value in result.params.items():
        assert value == pytest.approx(TRUTH[name], rel=0.02), name


def _write_foreign(bsdf, folder) -> None:
    """``hidden.bsdf``, the export of ``bsdf``, and ``foreign.bsdf``, the same table with its
    inner nodes moved off the Gauss-Lobatto rule: nodes layersim knows no rule of."""
    table = layersim.export(bsdf, folder / "hidden.bsdf")
    x = table.nodes
    table.nodes = np.where(np.abs(x) < 1, x * np.float32(1 - 1e-5), x).astype(np.float32)
    table.write(folder / "foreign.bsdf")


def test_a_fourier_table_on_foreign_nodes_is_evaluated_as_renderers_do(tmp_path, hidden):
    _write_foreign(hidden, tmp_path)
    assert isinstance(read_table(tmp_path / "hidden.bsdf"), layersim.BSDF)
    foreign = read_table(tmp_path / "foreign.bsdf")
    assert isinstance(foreign, TableTarget) and "renderer evaluation" in foreign.source
    target = as_target(tmp_path / "foreign.bsdf")
    wi, wo = direction_pairs()
    assert len(target.wi) == len(wi)
    gap = (np.asarray(hidden.eval(wi, wo))[:, None] - target.f) * wo[:, 2:]
    # Catmull-Rom on the file's nodes against the solver's interpolation: 8e-4 RMS
    assert 0 < np.sqrt(np.mean(gap ** 2)) < 2e-3


def test_merl_targets_leave_out_grazing_and_unmeasured_samples(merl_file):
    table = read_merl(merl_file)
    assert table.missing > 0 and not table.measured.all()
    target = as_target(merl_file)
    assert target.channels == 3 and "MERL file" in target.source
    assert np.allclose(target.f, LAMBERT, rtol=1e-12)       # channels in the file's order
    cos_max = np.cos(np.radians(MERL_THETA_MAX))
    wi, wo = direction_pairs()
    grazing = wo[:, 2] < cos_max
    assert grazing.any() and np.all(target.wo[:, 2] >= cos_max - 1e-9)
    th, td, _ = half_diff(wi, wo)
    patch = _unmeasured(th, td, 0) & ~grazing
    assert patch.any()
    assert len(target.wi) <= len(wi) - grazing.sum() - patch.sum()
    th, td, _ = half_diff(target.wi, target.wo)
    assert not _unmeasured(th, td, 0).any()


@pytest.mark.slow
def test_a_stack_is_recovered_from_a_merl_file(tmp_path):
    # MERL's grid (trilinear in sqrt(theta_h), 1-degree theta_d and phi_d) reads the stack
    # back to 3e-3 in f cos(theta_o) at the coat's peak: the parameters come back within 1 %
    bsdf = layersim.solve(layersim.Scene.from_dict(_merl_scene()))
    path = tmp_path / "painted.binary"
    write_merl_of(path, bsdf.eval, _unmeasured)
    target = as_target(path)
    gap = (np.asarray(bsdf.eval(target.wi, target.wo)) - target.f) * target.wo[:, 2:]
    assert np.max(np.abs(gap)) < 5e-3
    t0 = time.perf_counter()
    result = layersim.fit(_merl_template(), path)
    print(f"fit from the MERL file: {time.perf_counter() - t0:.1f} s\n{result.summary()}")
    for name, value in result.params.items():
        assert value == pytest.approx(MERL_TRUTH[name], rel=0.01), name
    plot_fit(tmp_path / "fit.png", result, target, read_table(path))   # NaN where no data
    assert (tmp_path / "fit.png").stat().st_size > 10_000


def test_wrong_channels_and_unreadable_files_are_refused(tmp_path, merl_file):
    path = merl_file
    one = {"layer": [{"kind": "conductor", "ior": [0.2, 3.0],
                      "roughness": {"fit": [0.2, 0.5]}}]}
    with pytest.raises(ValueError, match=r"template has 1 channel\(s\), MERL file .* has 3"):
        layersim.fit(one, path)
    short = tmp_path / "short.binary"
    short.write_bytes(path.read_bytes()[:1000])
    with pytest.raises(FileFormatError, match="short.binary: 1000 bytes"):
        as_target(short)
    junk = tmp_path / "junk.bsdf"
    junk.write_bytes(b"not a table at all")
    with pytest.raises(FileFormatError, match="neither a Fourier .bsdf file"):
        as_target(junk)
    with pytest.raises(FileFormatError, match="absent.bsdf: cannot read"):
        as_target(tmp_path / "absent.bsdf")


def test_cli_refuses_wrong_channels_and_unreadable_targets_on_one_line(tmp_path, capsys,
                                                                      merl_file):
    path = merl_file
    template = tmp_path / "one.toml"
    template.write_text('[[layer]]\nkind = "conductor"\nior = [0.2, 3.0]\n'
                        'roughness = { fit = [0.2, 0.5] }\n')
    out = str(tmp_path / "fitted.toml")
    assert main(["fit", str(template), str(path), "-o", out, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "1 channel(s), MERL file" in err and "has 3" in err
    (tmp_path / "short.binary").write_bytes(b"\0" * 12)
    assert main(["fit", str(template), str(tmp_path / "short.binary"), "-o", out]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "dimensions (0, 0, 0)" in err


@pytest.mark.slow
def test_rgl_channels_follow_the_file_and_the_template(tmp_path):
    rgb = layersim.solve(layersim.Scene.from_dict(_merl_scene()))
    layersim.export(rgb, tmp_path / "rgb.bsdf", format="rgl", resolution=8, color="rgb")
    assert as_target(tmp_path / "rgb.bsdf").channels == 3
    layersim.export(rgb, tmp_path / "spectral.bsdf", format="rgl", resolution=8)
    with pytest.raises(FileFormatError, match=r"give the template \[stack\] wavelengths"):
        as_target(tmp_path / "spectral.bsdf")
    target = as_target(tmp_path / "spectral.bsdf", wavelengths=(450.0, 550.0, 650.0))
    assert target.channels == 3 and np.all(target.f >= 0)
    assert len(target.wi) == len(direction_pairs()[0])       # slices up to 89.9 degrees
    # slices only up to 60 degrees: pairs with an elevation beyond are left out
    table = rgl_table.read(tmp_path / "rgb.bsdf")
    table.theta_i = table.theta_i * np.float32(np.radians(60.0) / table.theta_i.max())
    table.write(tmp_path / "to60.bsdf")
    target = as_target(tmp_path / "to60.bsdf")
    cos60 = np.cos(np.radians(60.0))
    assert 0 < len(target.wi) < len(direction_pairs()[0])
    assert target.wi[:, 2].min() >= cos60 - 1e-6 and target.wo[:, 2].min() >= cos60 - 1e-6


@pytest.mark.slow
def test_cli_fits_a_table_on_foreign_nodes_and_plots_it(tmp_path, hidden, capsys):
    _write_foreign(hidden, tmp_path)
    template = tmp_path / "template.toml"
    template.write_text('[[layer]]\nkind = "dielectric"\nior = 1.5\n'
                        'roughness = { fit = [0.2, 0.5] }\n\n[[layer]]\nkind = "conductor"\n'
                        'ior = [0.2, 3.0]\nroughness = { fit = [0.25, 0.6] }\n')
    out, png = tmp_path / "fitted.toml", tmp_path / "fit.png"
    assert main(["fit", str(template), str(tmp_path / "foreign.bsdf"), "-o", str(out),
                 "--plot", str(png), "--quiet"]) == 0
    fitted = layersim.Scene.from_toml(out)
    # the renderers' Catmull-Rom evaluation (8e-4 RMS from the solver's): within 2 %
    assert fitted.layers[0].alpha_u == pytest.approx(0.3, rel=0.02)
    assert fitted.layers[1].alpha_u == pytest.approx(0.4, rel=0.02)
    assert png.stat().st_size > 10_000
    assert "rms residual" in capsys.readouterr().out
