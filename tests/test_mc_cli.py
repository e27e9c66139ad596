"""``layersim mc`` / ``layersim compare``: result files, resuming, stopping, comparing
(montecarlo/campaign.py, resultfile.py, compare.py; layersim/mc_commands.py)."""

import math
import random
import signal
import subprocess
import sys
import time
import tomllib

import numpy as np
import pytest

import layersim.montecarlo as mc
from layersim import Scene, solve
from layersim.cli import main
from layersim.montecarlo import compare, resultfile
from layersim.montecarlo.campaign import InProcess, Stopped, run_walks, walks_of
from layersim.montecarlo.work import PathRange, run_range

SLAB = """[[layer]]
kind = "dielectric"
ior = 1.5
roughness = 0.3

[[layer]]
kind = "medium"
tau = 1.0
albedo = [0.5, 0.8, 0.95]
g = 0.5
"""
WI = np.array([math.sin(math.radians(30)), 0.0, math.cos(math.radians(30))])
MU, PHI = np.linspace(0, 1, 4), np.linspace(0, 2 * math.pi, 5)


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "slab.toml"
    path.write_text(SLAB)
    return path


def _mc(scene_file, out, *extra):
    return main(["mc", str(scene_file), "--wi", "30,0", "--paths", "3000", "--batch", "1000",
                 "--bins", "3,4", "--backend", "warp-cpu", "--seed", "5", "--no-plot",
                 "-o", str(out), *extra])


def test_file_reads_with_numpy_alone_and_equals_simulate(scene_file, tmp_path):
    out = tmp_path / "run.npz"
    assert _mc(scene_file, out) == 0
    z = np.load(out, allow_pickle=False)           # no pickles: numpy alone reads it
    assert str(z["format"]) == "layersim-mc" and z["scenes"][0] == SLAB
    assert z["wi"].shape == (3, 3) and list(z["walk_channel"]) == [0, 1, 2]
    assert np.allclose(z["theta_deg"], 30.0) and z["tally_w"].dtype == np.uint64
    ref = mc.simulate(Scene.from_toml(scene_file), WI, 3000, MU, PHI, backend="warp-cpu",
                      seed=5, batch_size=1000)
    for key in ("reflectance", "transmittance", "absorbed", "reflectance_stderr"):
        assert np.array_equal(z[key], getattr(ref, key)), key       # bit for bit
    assert np.array_equal(z["bins_top"], np.moveaxis(ref.bins["top"], -1, 0))
    assert np.array_equal(z["bins_bottom_stderr"], np.moveaxis(ref.bins_stderr["bottom"], -1, 0))
    assert list(z["particles"]) == [3000] * 3 and bool(z["complete"])
    f = resultfile.load(out)
    assert f.result(1).reflectance == ref.reflectance[1]
    whole = run_range(PathRange(_walks()[2], 0, 3000))      # the walk in one range
    assert np.array_equal(f.tally(2).w, whole.w) and f.tally(2).events == whole.events


class Interrupting:
    """An executor that yields ranges in a shuffled order (chunks of ``chunk`` ranges, as
    several workers would complete them) and raises KeyboardInterrupt after ``stop`` ranges."""

    def __init__(self, seed: int, chunk: int = 4, stop: int | None = None):
        self.rng, self.chunk, self.stop = random.Random(seed), chunk, stop

    def map(self, ranges):
        done, pool = 0, []
        it = iter(ranges)
        while True:
            while len(pool) < self.chunk:
                r = next(it, None)
                if r is None:
                    break
                pool.append(r)
            if not pool:
                return
            r = pool.pop(self.rng.randrange(len(pool)))
            if self.stop is not None and done == self.stop:
                raise KeyboardInterrupt
            done += 1
            yield r, run_range(r)


def _scene():
    return Scene.from_dict(tomllib.loads(SLAB), default_name="slab")


def _walks(seed=5):
    return walks_of(_scene(), [WI], MU, PHI, seed, 100_000, "warp-cpu")


def _run(out, executor=None, target=None, paths=4000, restart=False):
    return run_walks(_walks(), paths, batch=500, target_stderr=target, executor=executor,
                     out=out, scene_texts=[SLAB], walk_channel=[0, 1, 2], restart=restart,
                     every=0.0)


@pytest.mark.parametrize("order", ["in order", "shuffled"])
def test_interrupted_and_resumed_equals_uninterrupted(tmp_path, order):
    whole = _run(tmp_path / "whole.npz")
    out = tmp_path / "cut.npz"
    first = Interrupting(1, chunk=1 if order == "in order" else 5, stop=9)
    with pytest.raises(Stopped) as stop:
        _run(out, first)
    cut = resultfile.load(out)
    assert not cut.complete and stop.value.paths == 9 * 500 == int(cut.done[:, 2].sum())
    if order == "shuffled":
        assert cut.pending.size > 0          # ranges done beyond the in-order prefix
    second = Interrupting(2, chunk=1 if order == "in order" else 3)
    _run(out, second)
    a, b = resultfile.load(tmp_path / "whole.npz"), resultfile.load(out)
    assert bool(b.complete)
    assert np.array_equal(a.tally_w, b.tally_w) and np.array_equal(a.tally_counts, b.tally_counts)
    assert np.array_equal(a.done, b.done) and b.done.tolist() == [[i, 0, 4000] for i in range(3)]
    assert [p.total().particles for p in whole.progress] == [4000] * 3


def test_stderr_stop_does_not_depend_on_completion_order(tmp_path):
    target = 6e-3
    ref = mc.simulate(_scene(), WI, 20_000, MU, PHI,
                      backend="warp-cpu", seed=5, batch_size=500, target_stderr=target)
    runs = [_run(tmp_path / "a.npz", InProcess(), target, 20_000),
            _run(tmp_path / "b.npz", Interrupting(3, chunk=6), target, 20_000)]
    files = [resultfile.load(tmp_path / n) for n in ("a.npz", "b.npz")]
    assert np.array_equal(files[0].tally_w, files[1].tally_w)
    assert list(files[0].particles) == list(files[1].particles) == list(ref.particles)
    assert np.all(files[1].particles < 20_000) and np.all(files[1].target_met)
    assert np.array_equal(files[1].reflectance, ref.reflectance)
    assert files[1].pending.size == 0 and runs[1].complete


def test_other_options_are_refused_with_one_line(scene_file, tmp_path, capsys):
    out = tmp_path / "run.npz"
    assert _mc(scene_file, out) == 0
    capsys.readouterr()
    assert main(["mc", str(scene_file), "--wi", "30,0", "--paths", "3000", "--batch", "1000",
                 "--bins", "3,4", "--backend", "warp-cpu", "--seed", "6", "--no-plot",
                 "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "seed: 5 in the file, 6 now" in err and "--restart" in err
    assert _mc(scene_file, out, "--restart", "--paths", "2000") == 0
    assert list(resultfile.load(out).particles) == [2000] * 3


@pytest.mark.parametrize("args, field", [(["--wi", "90,0"], "--wi"), (["--bins", "0,4"], "--bins"),
                                         (["--paths", "1.5"], "--paths"),
                                         (["--stderr", "-1"], "--stderr"),
                                         (["--backend", "cuda"], "backend")])
def test_bad_input_is_one_line(scene_file, tmp_path, capsys, args, field):
    argv = ["mc", str(scene_file), "--wi", "30,0", "--no-plot", "-o", str(tmp_path / "x.npz")]
    assert main(argv + args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and field in err and "Traceback" not in err
    assert not (tmp_path / "x.npz").exists()


def test_compare_with_itself_is_zero(scene_file, tmp_path, capsys):
    out = tmp_path / "run.npz"
    assert _mc(scene_file, out) == 0
    f = resultfile.load(out)
    for i in range(f.n_walks):
        c = compare.against_walk(f.result(i), f.result(i))
        assert c.populated().size > 0 and np.all(c.populated() == 0.0)
        assert c.albedo_z == {"R": 0.0, "T": 0.0}
    capsys.readouterr()
    assert main(["compare", str(out), str(out)]) == 0
    text = capsys.readouterr().out
    assert text.count("100.0 % of") == 3 and "largest |z| 0.00" in text
    assert main(["compare", str(out), str(scene_file.with_suffix(".nope"))]) == 2


def test_z_map_follows_mcresult_z_scores():
    rng = np.random.default_rng(0)
    res = mc.simulate(_scene().channel(1), WI, 2000,
                      MU, PHI, backend="warp-cpu", seed=1)
    other = res.bins["top"] * (1 + 0.1 * rng.standard_normal(res.bins["top"].shape))
    other[0, 0] = 0.0
    z = compare.z_map(res.bins["top"], res.bins_stderr["top"], res.particles, other)
    assert np.allclose(np.abs(z[np.isfinite(z)]), res.z_scores("top", other))


@pytest.mark.slow
def test_compare_with_a_solved_rough_conductor(tmp_path, capsys):
    scene = tmp_path / "gold.toml"
    scene.write_text('[[layer]]\nkind = "conductor"\nior = [0.143552, 3.98397]\n'
                     'roughness = 0.3\n')
    out = tmp_path / "gold.npz"
    assert main(["mc", str(scene), "--wi", "40,0", "--paths", "1e5", "--bins", "9,18",
                 "--backend", "warp-cpu", "-o", str(out)]) == 0
    assert (tmp_path / "gold.png").stat().st_size > 0
    f = resultfile.load(out)
    bsdf = solve(Scene.from_toml(scene))
    R, _ = bsdf.albedo(f.wi[0])
    bins = bsdf.bin_energies(f.wi[0], f.mu_edges, f.phi_edges)
    c = compare.against_values(f.result(0), float(R), 0.0, bins)
    assert c.within(3.0) >= 0.95 and abs(c.albedo_z["R"]) < 4
    capsys.readouterr()
    assert main(["compare", str(out), str(scene), "--plot", str(tmp_path / "z.png")]) == 0
    assert "solving" in capsys.readouterr().out and (tmp_path / "z.png").stat().st_size > 0


@pytest.mark.slow
def test_ctrl_c_checkpoints_and_exits_130(scene_file, tmp_path):
    out = tmp_path / "run.npz"
    cmd = [sys.executable, "-m", "layersim.cli", "mc", str(scene_file), "--wi", "30,0",
           "--paths", "1e10", "--batch", "20000", "--backend", "warp-cpu", "--no-plot",
           "-o", str(out)]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not out.exists() and time.monotonic() < deadline:     # the first checkpoint
        time.sleep(0.2)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1].startswith("stopped at ")
    f = resultfile.load(out)
    assert not f.complete and f.done[:, 2].sum() == f.particles.sum() > 0
    assert str(f.device)                   # the device is recorded at checkpoints


def test_one_file_holds_walks_of_several_scenes(tmp_path):
    """A sweep's layout: scenes x directions x channels, each walk as simulate gives it."""
    gold = '[[layer]]\nkind = "conductor"\nior = [0.143552, 3.98397]\nroughness = 0.2\n'
    scenes = [_scene(), Scene.from_dict(tomllib.loads(gold), default_name="gold")]
    wis = [WI, np.array([0.0, 0.0, 1.0])]
    walks, where, channel = [], [], []
    for s, scene in enumerate(scenes):
        found = walks_of(scene, wis, MU, PHI, 5, 100_000, "warp-cpu")
        walks += found
        where += [s] * len(found)
        channel += [c for _ in wis for c in range(scene.channels)]
    run_walks(walks, 1000, batch=400, out=tmp_path / "sweep.npz", scene_texts=[SLAB, gold],
              walk_scene=where, walk_channel=channel)
    f = resultfile.load(tmp_path / "sweep.npz")
    assert f.n_walks == 8 and list(f.walk_scene) == [0] * 6 + [1] * 2
    assert f.label(7) == "gold at 0,0 deg" and f.label(1) == "slab[G] at 30,0 deg"
    ref = mc.simulate(scenes[1], wis[1], 1000, MU, PHI, backend="warp-cpu", seed=5)
    assert f.result(7).reflectance == ref.reflectance
    assert np.array_equal(f.result(7).bins["top"], ref.bins["top"])


def test_a_failed_write_keeps_the_previous_file(tmp_path, monkeypatch):
    out = tmp_path / "run.npz"
    campaign = _run(out, paths=1000)
    before = out.read_bytes()

    def broken(fh, **arrays):
        fh.write(b"partial")
        raise OSError("disk full")
    monkeypatch.setattr(np, "savez", broken)
    with pytest.raises(OSError, match="disk full"):
        resultfile.save(out, campaign)
    assert out.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["run.npz"]


def test_compare_refuses_a_source_of_other_channels(scene_file, tmp_path, capsys):
    out = tmp_path / "run.npz"
    assert _mc(scene_file, out) == 0                     # three channels
    mirror = tmp_path / "mirror.toml"
    mirror.write_text('[[layer]]\nkind = "conductor"\nior = [0.2, 3.0]\nroughness = 0.0\n')
    capsys.readouterr()
    assert main(["compare", str(out), str(mirror)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "has 1 channel(s)" in err and "has 3" in err


@pytest.mark.parametrize("change, phrase", [({"--wi": "40,0"}, "incident directions differ"),
                                            ({"--bins": "3,5"}, "bins: 3x4 in the file, 3x5"),
                                            ({"--stderr": "0.01"}, "stderr target: none in "
                                                                   "the file, 0.01 now")])
def test_each_difference_is_named(scene_file, tmp_path, capsys, change, phrase):
    out = tmp_path / "run.npz"
    assert _mc(scene_file, out) == 0
    options = {"--wi": "30,0", "--paths": "3000", "--batch": "1000", "--bins": "3,4",
               "--backend": "warp-cpu", "--seed": "5", "-o": str(out), **change}
    capsys.readouterr()
    assert main(["mc", str(scene_file), "--no-plot", *(x for kv in options.items()
                                                      for x in kv)]) == 2
    err = capsys.readouterr().err
    assert phrase in err and err.count("\n") == 1
