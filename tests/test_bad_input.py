"""Bad input of every kind (files, options, environment, the Python API) gets one clear line:
on the command line ``layersim: error: ...`` on stderr, exit status 2, no traceback, nothing
written, and before any heavy work; in Python a TypeError that says what to pass, or a
layersim error naming the file, layer or field. Also the command line a new user expects
(``--version``, examples in ``--help``, ``solve --like``, ``plan`` printing a refused plan)
and per-channel ``g`` of media."""

import os
import subprocess
import sys
import time
import tracemalloc
import warnings
from pathlib import Path

import numpy as np
import pytest

import layersim
from layersim import config
from layersim.cli import main as cli_main
from layersim.plan import MD_MAX
from layersim.scene import MAX_ORDERS

GLASS = """
[[layer]]
kind = "dielectric"
ior = 1.5
roughness = 0.3

[discretization]
n = 32
md = 48
"""

GOLD = """
[[layer]]
kind = "conductor"
ior = [0.143552, 3.98397]
roughness = 0.3

[discretization]
n = 48
"""

LACQUER = """
[[layer]]
kind = "dielectric"
ior = 1.5
roughness = 0.4
"""


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Two small solved stacks (glass: transmissive; gold: opaque), their scenes, a .bsdf
    table and damaged or foreign files."""
    d = tmp_path_factory.mktemp("bad")
    for name, text in (("glass", GLASS), ("gold", GOLD), ("lacquer", LACQUER)):
        (d / f"{name}.toml").write_text(text)
    for name in ("glass", "gold"):
        layersim.solve(layersim.Scene.from_toml(d / f"{name}.toml")).save(d / f"{name}.lsim")
    layersim.export(layersim.BSDF.load(d / "glass.lsim"), d / "glass.bsdf")
    data = (d / "glass.lsim").read_bytes()
    (d / "truncated.lsim").write_bytes(data[: len(data) // 2])
    (d / "head.lsim").write_bytes(data[:100])
    (d / "empty.lsim").write_bytes(b"")
    rng = np.random.default_rng(1)
    (d / "random.lsim").write_bytes(rng.integers(0, 256, 4000, dtype=np.uint8).tobytes())
    (d / "garbage.toml").write_bytes(b"\xe3\x81" + rng.integers(0, 256, 500,
                                                               dtype=np.uint8).tobytes())
    return d


def _one_line(err: str, *words) -> str:
    """The single ``layersim: error:`` line of ``err``, checked to contain ``words``."""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("layersim: error: "), err
    assert "Traceback" not in err and "allow_pickle" not in err and "pickle" not in err
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def _refused(argv, capsys, *words, cwd=None) -> str:
    """Run the command in-process: exit status 2, one line containing ``words``, and no file
    written in ``cwd``."""
    before = set(Path(cwd).iterdir()) if cwd else None
    assert cli_main([str(a) for a in argv]) == 2
    line = _one_line(capsys.readouterr().err, *words)
    if cwd:
        assert set(Path(cwd).iterdir()) == before
    return line


# ---- files ------------------------------------------------------------------------------------

@pytest.mark.parametrize("name, words", [
    ("truncated.lsim", ("truncated.lsim", "damaged or truncated")),
    ("head.lsim", ("head.lsim", "damaged or truncated")),
    ("empty.lsim", ("empty.lsim", "empty")),
    ("random.lsim", ("random.lsim", "not a saved layersim BSDF")),
    ("glass.toml", ("glass.toml", "scene file", "solve")),
    ("missing.lsim", ("missing.lsim", "No such file")),
])
def test_info_on_a_damaged_or_foreign_file_says_what_it_is(files, capsys, name, words):
    _refused(["info", files / name], capsys, *words, cwd=files)


@pytest.mark.parametrize("command", [
    ["eval", "{f}", "--wi", "0,0,1", "--wo", "0,0,1"],
    ["subtract", "{f}", "{g}", "--side", "top"],
    ["subtract", "{g}", "{f}", "--side", "top"],
    ["plot", "{f}", "--wi", "30,0"],
    ["export", "{f}"],
    ["solve", "{t}", "--like", "{f}"],
])
def test_a_truncated_bsdf_file_is_refused_by_every_command(files, capsys, command,
                                                           monkeypatch):
    monkeypatch.chdir(files)
    argv = [a.format(f=files / "truncated.lsim", g=files / "glass.lsim",
                     t=files / "lacquer.toml") for a in command]
    _refused(argv, capsys, "truncated.lsim", "damaged or truncated", cwd=files)


@pytest.mark.parametrize("make, words", [
    (lambda data: data[:200], ("size mismatch", "truncated")),
    (lambda data: data[:7], ("truncated header",)),
    (lambda data: b"", ("empty",)),
    (lambda data: data + b"extra", ("size mismatch",)),
])
def test_a_damaged_bsdf_table_is_one_line(files, capsys, tmp_path, make, words):
    bad = tmp_path / "bad.bsdf"
    bad.write_bytes(make((files / "glass.bsdf").read_bytes()))
    _refused(["eval", bad, "--wi", "0,0,1", "--wo", "0,0,1"], capsys, "bad.bsdf", *words,
             cwd=tmp_path)


def test_info_describes_a_bsdf_table(files, capsys):
    """A .bsdf file given to info: its header and the albedos of the operators it converts
    to, those of the BSDF it was exported from; BSDF.load refuses it, naming what it is."""
    assert cli_main(["info", str(files / "glass.bsdf")]) == 0
    out = capsys.readouterr().out
    assert "SCATFUN v1" in out and "albedo" in out
    glass = layersim.BSDF.load(files / "glass.lsim")
    R, T = glass.albedo([0.0, 0.0, 1.0])
    assert f"0.0    {float(R):.5f}   {float(T):.5f}" in out
    with pytest.raises(layersim.FileFormatError, match="tabulated Fourier .bsdf file"):
        layersim.BSDF.load(files / "glass.bsdf")


def test_load_never_needs_pickle(files):
    """A saved BSDF holds plain arrays only: it loads with allow_pickle=False and every array
    in it has a numeric or string dtype."""
    with np.load(files / "glass.lsim", allow_pickle=False) as d:
        kinds = {d[k].dtype.kind for k in d.files}
    assert kinds <= set("biufU"), kinds
    bsdf = layersim.BSDF.load(files / "glass.lsim")
    assert bsdf.grid.n == 32


def test_binary_garbage_as_a_scene_names_the_file(files, capsys, monkeypatch):
    monkeypatch.chdir(files)
    _refused(["solve", files / "garbage.toml"], capsys, "garbage.toml", "not UTF-8 text",
             cwd=files)
    _refused(["plan", files / "garbage.toml"], capsys, "garbage.toml", cwd=files)


# ---- options ----------------------------------------------------------------------------------

def _no_solve(*args, **kwargs):
    raise AssertionError("the command started the work before checking its options")


def test_an_unwritable_output_is_refused_before_the_solve(files, capsys, monkeypatch, tmp_path):
    monkeypatch.setattr("layersim.cli.solve", _no_solve)
    missing = tmp_path / "nonexistent" / "x.lsim"
    _refused(["solve", files / "glass.toml", "-o", missing], capsys, "nonexistent",
             "does not exist")
    _refused(["solve", files / "glass.toml", "-o", tmp_path], capsys, "is a folder")
    _refused(["export", files / "glass.toml", "-o", missing.with_suffix(".bsdf")], capsys,
             "does not exist")
    _refused(["plot", files / "glass.toml", "--wi", "30,0", "-o",
              missing.with_suffix(".png")], capsys, "does not exist")
    _refused(["subtract", files / "glass.lsim", files / "glass.lsim", "--side", "top", "-o",
              missing], capsys, "does not exist")
    assert not (tmp_path / "nonexistent").exists()


def _unwritable_places(tmp_path):
    """Output places where no file can be created, as (path factory, words of the reason):
    a virtual file system (refuses files that the permission bits allow, also to root), a
    folder that does not exist, and a "folder" that is a file."""
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    places = [(lambda name: tmp_path / "nonexistent" / name, ("does not exist",)),
              (lambda name: blocker / name, ("is a file, not a folder",))]
    if Path("/proc/self").is_dir():
        places.append((lambda name: Path("/proc") / name, ("cannot write there",)))
    return places


@pytest.mark.parametrize("command, option, name", [
    (["solve", "{d}/glass.toml"], "-o", "x.lsim"),
    (["export", "{d}/glass.toml"], "-o", "x.bsdf"),
    (["plot", "{d}/glass.toml", "--wi", "30,0"], "-o", "x.png"),
    (["plot", "{d}/glass.toml", "--blocks"], "-o", "x.png"),
    (["subtract", "{d}/glass.lsim", "{d}/glass.lsim", "--side", "top"], "-o", "x.lsim"),
    (["design", "{examples}/design_coated_copper.toml"], "-o", "x.toml"),
    (["design", "{examples}/design_coated_copper.toml"], "--plot", "x.png"),
    (["fit-ndf", "{d}/view.npz"], "-o", "x.npz"),
    (["fit-ndf", "{d}/view.npz", "-o", "{tmp}/ndf.npz"], "--plot", "x.png"),
    (["bench", "--quick"], "--out", "report"),
])
def test_every_output_option_is_checked_before_the_work(files, capsys, monkeypatch, tmp_path,
                                                        command, option, name):
    """Each output that a command writes is refused, on one line naming the option and why,
    before the work starts: also where the permission bits would allow it (``/proc``)."""
    import layersim.bench
    import layersim.ndf.workflow
    import layersim.statistical.design     # noqa: F401 (the package's `design` is a function)
    for module, attr in (("layersim.cli", "solve"), ("layersim.cli", "subtract"),
                         ("layersim.cli", "_load"), ("layersim.cli", "export")):
        monkeypatch.setattr(f"{module}.{attr}", _no_solve)
    monkeypatch.setattr(layersim.bench, "run", _no_solve)
    monkeypatch.setattr(layersim.ndf.workflow, "fit_files", _no_solve)
    monkeypatch.setattr(sys.modules["layersim.statistical.design"], "designs", _no_solve)
    examples = Path(__file__).resolve().parents[1] / "examples"
    argv = [a.format(d=files, examples=examples, tmp=tmp_path) for a in command]
    for place, words in _unwritable_places(tmp_path):
        if option == "--out" and "does not exist" in words:
            continue                     # the bench creates its folder and missing parents
        line = _refused(argv + [option, place(name)], capsys, *words)
        assert line.startswith(f"layersim: error: {option} "), line


def test_an_existing_output_file_is_checked_for_writing(files, capsys, monkeypatch, tmp_path):
    """An existing output that cannot be opened for writing (a pipe that no one reads) is
    refused before the solve, and an existing writable file is left as it was by the check."""
    monkeypatch.setattr("layersim.cli.solve", _no_solve)
    pipe = tmp_path / "pipe"
    os.mkfifo(pipe)
    _refused(["solve", files / "glass.toml", "-o", pipe], capsys, f"-o {pipe}",
             "cannot write there")
    pipe.unlink()
    from layersim.cli import _output
    mine = tmp_path / "old.lsim"
    mine.write_bytes(b"old")
    before = mine.stat().st_mtime_ns
    assert _output(mine, "-o") == mine
    assert mine.read_bytes() == b"old" and mine.stat().st_mtime_ns == before
    assert sorted(tmp_path.iterdir()) == [mine]       # the probe file is gone


def test_an_unknown_or_absent_backend_is_refused_before_the_bench(capsys, tmp_path,
                                                                  monkeypatch):
    import layersim.bench
    monkeypatch.setattr(layersim.bench, "run", _no_solve)
    out = tmp_path / "bench"
    _refused(["bench", "--out", out, "--backend", "cuda9"], capsys, "cuda9",
             "unknown Monte Carlo backend", "warp-cpu")
    from layersim.montecarlo import available_backends
    absent = [b for b in ("warp-cuda", "opencl") if b not in available_backends()]
    if absent:
        _refused(["bench", "--out", out, "--backend", absent[0]], capsys, absent[0],
                 "not available")
    (tmp_path / "file").write_text("")
    _refused(["bench", "--out", tmp_path / "file"], capsys, "is a file, not a folder")
    _refused(["bench", "--out", tmp_path / "file" / "sub"], capsys, "is a file, not a folder")
    assert not out.exists()


@pytest.mark.parametrize("argv, words", [
    (["eval", "x.lsim", "--wi", "0,0,1"], ("the following arguments are required: --wo",
                                            "layersim eval --help")),
    (["solve", "x.toml", "--bogus"], ("unrecognized arguments: --bogus",)),
    (["frobnicate"], ("invalid choice: 'frobnicate'",)),
    (["subtract", "a.lsim", "b.lsim", "--side", "left"], ("invalid choice: 'left'",)),
])
def test_option_errors_are_one_line_too(capsys, argv, words):
    with pytest.raises(SystemExit) as exc:
        cli_main(argv)
    assert exc.value.code == 2
    _one_line(capsys.readouterr().err, *words)


def test_subtract_on_two_discretisations_says_how_to_solve_the_known_layer(files, capsys,
                                                                           tmp_path):
    _refused(["subtract", files / "gold.lsim", files / "glass.lsim", "--side", "top", "-o",
              tmp_path / "x.lsim"], capsys, "different grids", "--like STACK.lsim",
             cwd=tmp_path)


@pytest.mark.parametrize("alpha, words", [
    ("0.3", ("--alpha", "2 comma-separated finite numbers A_TOP,A_BOTTOM", "'0.3'")),
    ("0.3,x", ("--alpha", "A_TOP,A_BOTTOM")),
    ("-0.1,0.2", ("--alpha -0.1,0.2", "roughness hints must be >= 0")),
])
def test_export_alpha_is_named_as_the_two_roughness_hints(files, capsys, monkeypatch,
                                                           tmp_path, alpha, words):
    """--alpha holds the Beckmann-equivalent roughness of the top and bottom surface (header
    fields of the .bsdf file), not angles: help and errors say so, before the solve."""
    monkeypatch.setattr("layersim.cli.solve", _no_solve)
    line = _refused(["export", files / "glass.toml", "-o", tmp_path / "x.bsdf", "--alpha",
                     alpha], capsys, *words, cwd=tmp_path)
    assert "THETA" not in line and "PHI" not in line
    with pytest.raises(SystemExit):
        cli_main(["export", "--help"])
    assert "--alpha A_TOP,A_BOTTOM" in capsys.readouterr().out


def test_an_unknown_image_format_is_refused_before_the_solve(files, capsys, monkeypatch,
                                                            tmp_path):
    monkeypatch.setattr("layersim.cli.solve", _no_solve)
    _refused(["plot", files / "glass.toml", "--wi", "30,0", "-o", tmp_path / "x.xyz"], capsys,
             "unknown image format .xyz", ".png", cwd=tmp_path)


def test_plot_of_an_order_the_bsdf_does_not_have(files, capsys, monkeypatch):
    monkeypatch.chdir(files)
    _refused(["plot", files / "glass.lsim", "--blocks", "--order", "100000"], capsys,
             "--order 100000", "0 to 47", "md = 48", cwd=files)
    _refused(["plot", files / "glass.lsim", "--blocks", "--phi-d", "nan"], capsys,
             "--phi-d", "finite", cwd=files)


def test_eval_with_huge_components_normalises_without_warnings(files, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert cli_main(["eval", str(files / "glass.lsim"), "--wi", "1e308,1e308,1e308",
                         "--wo", "0,0,1"]) == 0
    out = capsys.readouterr().out
    assert "wi = (0.57735, 0.57735, 0.57735)" in out
    expected = layersim.BSDF.load(files / "glass.lsim").eval(np.ones(3) / np.sqrt(3),
                                                             [0.0, 0.0, 1.0])
    assert f"f = {float(expected):.6g} 1/sr" in out


@pytest.mark.parametrize("argv", [
    ["bench", "--quick", "--out", "{d}/bench-device", "--scene", "vandehulst_slab"],
    ["design", "{examples}/design_coated_copper.toml"],
    ["info", "{d}/glass.lsim"],
    ["export", "{d}/glass.lsim", "-o", "{d}/device.bsdf"],
])
def test_an_absent_cuda_device_is_one_line_for_every_command(files, capfd, environment, argv):
    """LAYERSIM_DEVICE naming a device this machine lacks stops every command on one line
    before its work, counting the C-level output too (capfd): bench and design used to take
    the refusal for the scene's, print it among their output and go on with Monte Carlo."""
    environment.setenv("LAYERSIM_DEVICE", "cuda:99")
    examples = Path(__file__).resolve().parents[1] / "examples"
    before = set(files.iterdir())
    assert cli_main([a.format(d=files, examples=examples) for a in argv]) == 2
    out, err = capfd.readouterr()
    assert out == ""
    _one_line(err, "LAYERSIM_DEVICE='cuda:99'", "use 'cpu'")
    assert set(files.iterdir()) == before


@pytest.mark.parametrize("argv, words", [
    (["eval", "{g}", "--wi", "0,0.5,-0.8", "--wo", "0,0,1"], ("opaque from below", "--wi")),
    (["eval", "{g}", "--wi", "0,0,1", "--wo", "0.3,0,-0.9"], ("opaque from below", "--wo")),
    (["plot", "{g}", "--wi", "120,0"], ("opaque from below", "THETA < 90")),
    (["eval", "{g}", "--wi", "1,0,0", "--wo", "0,0,1"], ("horizon",)),
    (["eval", "{g}", "--wi", "0,0,0", "--wo", "0,0,1"], ("nonzero",)),
    (["eval", "{g}", "--wi", "nan,0,1", "--wo", "0,0,1"], ("finite",)),
])
def test_directions_the_stack_cannot_take(files, capsys, monkeypatch, argv, words):
    monkeypatch.chdir(files)
    _refused([a.format(g=files / "gold.lsim") for a in argv], capsys, *words, cwd=files)


def test_the_validator_and_the_planner_share_the_order_limit(tmp_path, capsys):
    assert MAX_ORDERS == MD_MAX
    scene = tmp_path / "huge.toml"
    scene.write_text(GLASS.replace("md = 48", f"md = {MD_MAX + 1}"))
    _refused(["plan", scene], capsys, "huge.toml", "discretization.md", str(MD_MAX))


@pytest.mark.parametrize("n, md", [(4096, MD_MAX), (2000, 2000), (4096, None)])
def test_huge_discretisations_are_refused_from_the_estimate(tmp_path, capsys, monkeypatch, n,
                                                            md):
    """Refused before the pre-pass (which would take 8-30 s and GBs here): it is never
    called, the refusal takes a few MB, and the plan is printed with the refusal in it."""
    import layersim.plan

    def no_prepass(*args, **kwargs):
        raise AssertionError("the pre-pass ran for a plan refused at its lower bound")

    monkeypatch.setattr(layersim.plan, "interface_lengths", no_prepass)
    scene = tmp_path / "huge.toml"
    scene.write_text(GLASS.replace("n = 32", f"n = {n}").replace(
        "md = 48", f"md = {md}" if md else ""))
    with config.configure(max_memory=2 << 30):
        status = cli_main(["plan", str(scene)])
        out, err = capsys.readouterr()
        tracemalloc.start()
        cli_main(["plan", str(scene)])
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        capsys.readouterr()
    assert status == 2
    line = _one_line(err, "needs at least", "GiB", "lower n or md")
    assert f"refused: {line.removeprefix('layersim: error: ')}" in out
    assert f"ordinates: n = {n}" in out
    assert peak < 50 << 20, peak


def test_plan_prints_a_plan_over_the_memory_limit_with_its_refusal(capsys):
    """A bundled scene over the limit: the plan is printed whole (layers, orders, memory) with
    the reason it is refused, and the status says it cannot be solved as it is."""
    scene = Path(__file__).parents[1] / "benchmarks" / "scenes" / "coated_gold.toml"
    with config.configure(max_memory=1 << 20):
        assert cli_main(["plan", str(scene)]) == 2
        out, err = capsys.readouterr()
        with pytest.raises(layersim.InfeasibleError) as exc:
            layersim.make_plan(layersim.Scene.from_toml(scene))
    assert "layer 0 (dielectric): project" in out and "estimated memory" in out
    assert f"refused: {exc.value}" in out
    _one_line(err, "over the limit of 0.00 GiB")


# ---- environment ------------------------------------------------------------------------------

@pytest.fixture
def environment(monkeypatch):
    """Set LAYERSIM_* variables for one test: the settings are read again from them."""
    monkeypatch.setattr(config, "_active", None)
    return monkeypatch


@pytest.mark.parametrize("value", ["tpu", "cuda:x", "gpu0"])
def test_an_unknown_device_names_the_variable(files, capsys, environment, value):
    environment.setenv("LAYERSIM_DEVICE", value)
    _refused(["eval", files / "glass.toml", "--wi", "0,0,1", "--wo", "0,0,1"], capsys,
             "LAYERSIM_DEVICE", repr(value), "'cpu', 'cuda' or 'cuda:N'")


def test_cuda_without_a_gpu_is_one_line(files, capfd, environment):
    from layersim.kernels.runtime import cuda_available
    if cuda_available():
        pytest.skip("this machine has a CUDA device")
    environment.setenv("LAYERSIM_DEVICE", "cuda")
    assert cli_main(["eval", str(files / "glass.toml"), "--wi", "0,0,1", "--wo", "0,0,1"]) == 2
    _one_line(capfd.readouterr().err, "LAYERSIM_DEVICE='cuda'", "no CUDA device", "'cpu'")
    with pytest.raises(config.ConfigError, match="device='cuda:3'"):
        layersim.solve(files / "glass.toml", device="cuda:3")


# ---- Python API -------------------------------------------------------------------------------

def test_solve_takes_a_scene_a_path_or_a_dict(files):
    scene = layersim.Scene.from_toml(files / "gold.toml")
    wi = [0.3, 0.0, np.sqrt(0.91)]
    ref = layersim.solve(scene).albedo(wi)[0]
    for arg in (files / "gold.toml", str(files / "gold.toml")):
        assert layersim.solve(arg).albedo(wi)[0] == pytest.approx(float(ref), rel=1e-12)
    data = {"layer": [{"kind": "conductor", "ior": [0.143552, 3.98397], "roughness": 0.3}],
            "discretization": {"n": 48}}
    assert layersim.solve(data).albedo(wi)[0] == pytest.approx(float(ref), rel=1e-12)


@pytest.mark.parametrize("call, words", [
    (lambda d: layersim.solve(None), ("solve() takes a Scene", "NoneType")),
    (lambda d: layersim.solve(42), ("solve() takes a Scene", "int")),
    (lambda d: layersim.solve(d / "gold.toml", like=42), ("like=", "solved BSDF", "int")),
    (lambda d: layersim.Scene.from_toml(None), ("path", "NoneType")),
    (lambda d: layersim.Scene.from_toml({"layer": []}), ("Scene.from_dict",)),
    (lambda d: layersim.BSDF.load(None), ("BSDF.load takes the path", "NoneType")),
    (lambda d: layersim.BSDF.load(d / "glass.lsim").albedo("up"), ("wi", "[0, 0, 1]", "str")),
    (lambda d: layersim.BSDF.load(d / "glass.lsim").eval([0, 0, 1], None), ("wo", "None")),
    (lambda d: layersim.BSDF.load(d / "glass.lsim").albedo({"z": 1}), ("wi", "dict")),
    (lambda d: layersim.BSDF.load(d / "glass.lsim").bin_energies([0, 0, 1], "a", [0, 1]),
     ("mu_edges", "bin edges")),
    (lambda d: layersim.BSDF.load(d / "glass.lsim").save(None), ("BSDF.save", "NoneType")),
    (lambda d: layersim.make_plan(None), ("make_plan() takes a Scene", "NoneType")),
    (lambda d: layersim.export(None, d / "x.bsdf"), ("export() takes a solved BSDF",)),
])
def test_the_api_says_what_to_pass(files, call, words):
    with pytest.raises(TypeError) as exc:
        call(files)
    for w in words:
        assert w in str(exc.value)


@pytest.mark.parametrize("call, error, words", [
    (lambda d: layersim.solve(d / "garbage.toml"), layersim.SceneError, ("garbage.toml",)),
    (lambda d: layersim.solve(d / "gold.toml", like=d / "truncated.lsim"),
     layersim.FileFormatError, ("truncated.lsim",)),
    (lambda d: layersim.BSDF.load(d / "random.lsim"), layersim.FileFormatError,
     ("random.lsim", "not a saved layersim BSDF")),
    (lambda d: layersim.BSDF.load(d / "glass.lsim").albedo([1e308] * 3), ValueError,
     ("|v| = inf",)),
])
def test_the_api_names_the_file_or_the_value(files, call, error, words):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(error) as exc:
            call(files)
    assert "pickle" not in str(exc.value)
    for w in words:
        assert w in str(exc.value)


def test_make_plan_takes_a_path_or_a_dict_as_solve_does(files):
    plan = layersim.make_plan(files / "glass.toml")
    assert (plan.n, plan.md) == (32, 48)
    assert layersim.make_plan({"layer": [{"kind": "diffuse", "albedo": 0.5}]}).md == 1
    with pytest.raises(ValueError, match="threads must be an integer"):
        layersim.solve(files / "glass.toml", threads="x")


def test_solve_like_a_saved_file(files):
    like = layersim.BSDF.load(files / "gold.lsim")
    a = layersim.solve(files / "lacquer.toml", like=files / "gold.lsim")
    assert (a.grid.n, a.operators[0].m) == (like.grid.n, like.operators[0].m)


# ---- per-channel g ----------------------------------------------------------------------------

def test_per_channel_g_solves_each_channel_with_its_own_phase_function():
    """A medium with g = [0, 0.5, 0.8]: each channel equals the monochromatic solve of its g
    on the same discretisation, and forward scattering transmits more (the three differ)."""
    layer = {"kind": "medium", "tau": 1.0, "albedo": 0.9}
    disc = {"n": 32}
    rgb = layersim.solve({"layer": [{**layer, "g": [0.0, 0.5, 0.8]}], "discretization": disc})
    assert rgb.channels == 3
    wi = [0.0, 0.0, 1.0]
    R, T = rgb.albedo(wi)
    for c, g in enumerate((0.0, 0.5, 0.8)):
        mono = layersim.solve({"layer": [{**layer, "g": g}], "discretization": disc},
                              like=rgb)
        r, t = mono.albedo(wi)
        assert R[c] == pytest.approx(float(r), rel=1e-12)
        assert T[c] == pytest.approx(float(t), rel=1e-12)
    assert T[0] < T[1] < T[2] and R[0] > R[1] > R[2]
    scene = layersim.Scene.from_dict({"layer": [{**layer, "g": [0.0, 0.5, 0.8]}]})
    assert "g=(0, 0.5, 0.8)" in scene.describe()
    with pytest.raises(layersim.SceneError, match=r"layer 0 \(medium\): field 'g\[1\]'"):
        layersim.Scene.from_dict({"layer": [{**layer, "g": [0.0, 1.0, 0.5]}]})


# ---- a new user's command line ----------------------------------------------------------------

def test_version_and_examples_in_every_help(capsys):
    with pytest.raises(SystemExit) as exc:
        cli_main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"layersim {layersim.__version__}"
    for command in ("plan", "solve", "info", "bench", "export", "eval", "plot", "subtract"):
        with pytest.raises(SystemExit):
            cli_main([command, "--help"])
        out = capsys.readouterr().out
        assert "examples:" in out and f"layersim {command} " in out, command


def test_solve_like_makes_a_known_layer_for_subtract(files, capsys, tmp_path):
    out = tmp_path / "lacquer.lsim"
    assert cli_main(["solve", str(files / "lacquer.toml"), "--like",
                     str(files / "gold.lsim"), "-o", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    gold = layersim.BSDF.load(files / "gold.lsim")
    assert f"n = {gold.grid.n}" in text and f"md = {gold.operators[0].m}" in text
    lacquer = layersim.BSDF.load(out)
    assert lacquer.grid == gold.grid and lacquer.operators[0].m == gold.operators[0].m


def test_subtract_warns_when_the_recovered_layer_creates_energy(files, capsys):
    from layersim.cli import _warn_energy
    glass = layersim.BSDF.load(files / "glass.lsim")
    over = layersim.BSDF([glass.operators[0].map_blocks(lambda m: m * 1.3)])
    worst = float(max(np.max(over.albedo([0, 0, 1])[0] + over.albedo([0, 0, 1])[1]), 1.0))
    _warn_energy(over, [{"energy_max": worst}])
    err = capsys.readouterr().err
    assert err.startswith("warning: the recovered layer creates energy")
    assert "from above at 0-" in err and "from below" in err and "--eps" in err
    _warn_energy(glass, [{"energy_max": 1.0}])
    assert capsys.readouterr().err == ""


def test_subtract_warns_about_directions_hidden_by_total_internal_reflection(files, capsys):
    """Through glass (index 1 above, 1.5 below) a layer below is reached only within the
    critical angle asin(1 / 1.5) = 41.8 deg; a layer above the glass is not hidden."""
    from layersim.cli import _warn_hidden
    glass = layersim.BSDF.load(files / "glass.lsim")
    _warn_hidden(glass, "top")
    err = capsys.readouterr().err
    assert err.startswith("warning:") and "critical angle 41.8 deg" in err
    assert "index 1.5" in err and "not recovered" in err
    _warn_hidden(glass, "bottom")
    _warn_hidden(layersim.BSDF.load(files / "gold.lsim"), "top")
    assert capsys.readouterr().err == ""


class _Recorder:
    def __init__(self):
        self.calls = []

    def __call__(self, phase, done, total, what):
        self.calls.append((phase, done, total, what))


def test_progress_reports_each_layer_and_the_adding():
    rec = _Recorder()
    layersim.solve({"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
                              {"kind": "conductor", "ior": [0.2, 3.0], "roughness": 0.3}],
                    "discretization": {"n": 32}}, progress=rec)
    projection = [c for c in rec.calls if c[0] == "projection"]
    assert projection[0][1:3] == (0, 2) and projection[-1][1:3] == (2, 2)
    assert {c[3] for c in projection if c[3]} == {"layer 0 (dielectric)",
                                                  "layer 1 (conductor)"}
    assert [c[1:3] for c in rec.calls if c[0] == "adding"] == [(0, 1), (1, 1)]


def test_progress_bars_only_on_a_terminal(files, capsys, tmp_path):
    """Under pytest stderr is not a terminal: no bar is drawn. Enabled, the bars name the
    phase and the step under way, and keep redrawing while a step runs."""
    assert cli_main(["solve", str(files / "glass.toml"), "-o", str(tmp_path / "g.lsim")]) == 0
    assert capsys.readouterr().err == ""
    from layersim.cli import ProgressBars
    bars = ProgressBars(True)
    bars.interval = 0.05
    bars("projection", 0, 2, "layer 1 (conductor)")
    time.sleep(0.3)
    bars("projection", 1, 2, "layer 0 (dielectric)")
    bars.close()
    err = capsys.readouterr().err
    assert "projection" in err and "0/2" in err and "1/2" in err
    assert "layer 1 (conductor)" in err and err.count("0/2") >= 3   # redrawn while waiting


# ---- the same as separate processes -----------------------------------------------------------

def _run(args, env=None, cwd=None):
    return subprocess.run([sys.executable, "-m", "layersim.cli", *map(str, args)],
                          capture_output=True, text=True, env={**os.environ, **(env or {})},
                          cwd=cwd, timeout=120)


@pytest.mark.slow
@pytest.mark.parametrize("args, env", [
    (["info", "{d}/truncated.lsim"], {}),
    (["info", "{d}/random.lsim"], {}),
    (["eval", "{d}/glass.toml", "--wi", "0,0,1", "--wo", "0,0,1"], {"LAYERSIM_DEVICE": "tpu"}),
    (["plan", "{d}/glass.toml"], {"LAYERSIM_THREADS": "many"}),
    # a fresh process initialises Warp: none of its native lines may reach the terminal
    (["eval", "{d}/glass.lsim", "--wi", "0,0,1", "--wo", "0,0,1"],
     {"LAYERSIM_DEVICE": "cuda:99"}),
    (["bench", "--quick", "--out", "{d}/bench-device", "--scene", "vandehulst_slab"],
     {"LAYERSIM_DEVICE": "cuda:99"}),
])
def test_a_separate_process_prints_one_line_and_no_traceback(files, args, env):
    res = _run([a.format(d=files) for a in args], env, cwd=files)
    assert res.returncode == 2
    _one_line(res.stderr)


# ---- pictures ---------------------------------------------------------------------------------

def test_block_plots_show_only_the_blocks_that_exist(files, tmp_path):
    """An opaque stack has Rt only: its picture is one panel (narrower than the four of a
    transmissive stack), not three blank ones."""
    import matplotlib.image
    from layersim.solved import plot
    gold, glass = (layersim.BSDF.load(files / f"{n}.lsim") for n in ("gold", "glass"))
    assert plot.present_blocks(gold) == ["Rt"]
    assert sorted(plot.present_blocks(glass)) == ["Rb", "Rt", "Tbt", "Ttb"]
    one = matplotlib.image.imread(plot.plot_blocks(gold, tmp_path / "gold.png", samples=20))
    four = matplotlib.image.imread(plot.plot_blocks(glass, tmp_path / "glass.png", samples=20))
    assert one.shape[1] < 0.75 * four.shape[1]
    assert one[..., :3].std() > 0.05
