"""``layersim mc`` on several devices and a Dask cluster, and sweep files through the command
(layersim/mc_scaleout.py, layersim/mc_commands.py, montecarlo/sweep.py)."""

import numpy as np
import pytest

from layersim.cli import main

SCENES = {
    "slab.toml": '[[layer]]\nkind = "medium"\nalbedo = 0.95\ng = 0.5\ntau = 2.0\n',
    "gold.toml": ('[[layer]]\nkind = "dielectric"\nior = 1.5\nroughness = 0.2\n'
                  '[[layer]]\nkind = "conductor"\nior = [0.143552, 3.98397]\nroughness = 0.1\n'),
    "paint.toml": ('[[layer]]\nkind = "dielectric"\nior = 1.5\nroughness = 0.3\n'
                   '[[layer]]\nkind = "medium"\ntau = 1.0\nalbedo = [0.5, 0.8, 0.95]\ng = 0.5\n'),
}
ANGLES = ["0,0", "35,20", "70,180"]
COMMON = ["--batch", "700", "--no-plot"]
SWEEP = """[sweep]
scenes = ["slab.toml", "gold.toml", "paint.toml"]
angles = [[0, 0], [35, 20], [70, 180]]
paths = 2000
bins = [3, 4]
seed = 3
backend = "warp-cpu"
"""


@pytest.fixture
def folder(tmp_path):
    for name, text in SCENES.items():
        (tmp_path / name).write_text(text)
    (tmp_path / "sweep.toml").write_text(SWEEP)
    return tmp_path


def _single_runs(folder):
    """Each scene alone, in this process, with the sweep's options: tallies in sweep order."""
    words = []
    for name in SCENES:
        out = folder / f"single_{name}.npz"
        argv = ["mc", str(folder / name), "--paths", "2000", "--bins", "3,4", "--seed", "3",
                "--backend", "warp-cpu", *COMMON, "-o", str(out)]
        for a in ANGLES:
            argv += ["--wi", a]
        assert main(argv) == 0
        words.append(np.load(out)["tally_w"])
    return np.concatenate(words)


@pytest.mark.slow
def test_a_local_cluster_sweep_equals_single_process_runs_bit_for_bit(folder, capsys):
    out = folder / "sweep.npz"
    assert main(["mc", str(folder / "sweep.toml"), "--workers", "2", *COMMON, "-o",
                 str(out)]) == 0
    z = np.load(out)
    assert str(z["device"]).startswith("dask: 2 workers at tcp://")
    assert list(z["scene_names"]) == ["slab", "gold", "paint"]
    assert list(z["walk_scene"]) == [0] * 3 + [1] * 3 + [2] * 9        # paint: 3 channels
    assert list(z["particles"]) == [2000] * 15 and bool(z["complete"])
    single = _single_runs(folder)
    assert z["tally_w"].shape == single.shape and np.array_equal(z["tally_w"], single)
    assert len({z["tally_w"][i].tobytes() for i in range(15)}) == 15     # walks differ
    assert "paint[G] at 35,20 deg" in capsys.readouterr().out


def test_two_device_threads_equal_this_process(folder):
    plain, threads = folder / "plain.npz", folder / "threads.npz"
    base = ["mc", str(folder / "sweep.toml"), *COMMON]
    assert main(base + ["-o", str(plain)]) == 0
    assert main(base + ["--devices", "cpu,cpu", "-o", str(threads)]) == 0
    a, b = np.load(plain), np.load(threads)
    assert np.array_equal(a["tally_w"], b["tally_w"])
    assert str(b["device"]) == "warp-cpu on cpu, cpu"


@pytest.mark.parametrize("extra,message", [
    (["--workers", "2", "--devices", "all"], "--workers and --devices exclude each other"),
    (["--workers", "0"], "--workers must be >= 1, got 0"),
    (["--tls-cert", "c.pem"], "--tls-cert applies to --cluster only"),
    (["--cluster", "tls://h:1", "--tls-ca-file", "/no/ca_file.pem", "--tls-cert", "c.pem"],
     "--tls-ca-file: cannot read the file '/no/ca_file.pem'"),
    (["--devices", "cpu,,cpu"], "devices: expected 'all' or a comma-separated list"),
    (["--devices", "cuda:0"], "device 'cuda:0' is not a device of backend 'warp-cpu'"),
    (["--paths", "10"], "--paths: the sweep file"),
    (["--wi", "30,0"], "--wi: the sweep file"),
    (["--max-steps", "10"], "--max-steps: the sweep file"),
])
def test_bad_options_are_one_line_before_any_walk(folder, capsys, extra, message):
    out = folder / "x.npz"
    assert main(["mc", str(folder / "sweep.toml"), *COMMON, *extra, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("layersim: error: ") and message in err and err.count("\n") == 1
    assert not out.exists()


def test_a_bad_sweep_field_is_named(folder, capsys):
    (folder / "sweep.toml").write_text(SWEEP.replace("[70, 180]", "[90, 0]"))
    assert main(["mc", str(folder / "sweep.toml"), "-o", str(folder / "x.npz")]) == 2
    assert "sweep.toml: field 'angles[2]': theta must be" in capsys.readouterr().err


def test_a_scene_still_needs_wi(folder, capsys):
    assert main(["mc", str(folder / "slab.toml"), "-o", str(folder / "x.npz")]) == 2
    assert "--wi THETA,PHI is required for a scene" in capsys.readouterr().err
