"""Sweep files (montecarlo/sweep.py): scenes x angles x channels as walks; one-line errors."""

import math
import textwrap

import pytest

from layersim.errors import SceneError, SweepError
from layersim.montecarlo.sweep import MAX_PATHS, direction, read_sweep

SLAB = """
[[layer]]
kind = "dielectric"
ior = 1.5
roughness = 0.3
[[layer]]
kind = "medium"
tau = 1.0
albedo = 0.8
g = 0.5
"""
RGB_GOLD = """
[[layer]]
kind = "dielectric"
ior = 1.5
roughness = 0.1
[[layer]]
kind = "conductor"
ior = [[0.2, 3.6], [0.5, 2.4], [1.3, 1.9]]
roughness = 0.2
"""


@pytest.fixture
def folder(tmp_path):
    (tmp_path / "scenes").mkdir()
    (tmp_path / "scenes" / "slab.toml").write_text(SLAB)
    (tmp_path / "scenes" / "gold.toml").write_text(RGB_GOLD)
    return tmp_path


def _sweep(folder, body):
    path = folder / "sweep.toml"
    path.write_text(textwrap.dedent(body))
    return path


GOOD = """
[sweep]
scenes = ["scenes/slab.toml", "scenes/gold.toml"]
angles = [[0, 0], [40, 90]]
paths = 1e6
bins = [4, 3]
seed = 9
backend = "warp-cpu"
"""


def test_scenes_angles_channels_become_walks_in_order(folder, monkeypatch, tmp_path_factory):
    monkeypatch.chdir(tmp_path_factory.mktemp("elsewhere"))   # paths are relative to the file
    walks, texts, options = read_sweep(_sweep(folder, GOOD))
    # slab: 1 channel x 2 angles; gold: 3 channels x 2 angles
    assert len(walks) == 2 + 6
    assert [w.scene.name for w in walks] == ["slab", "slab"] + [
        f"gold[{c}]" for c in "RGB"] * 2
    assert walks[1].wi == pytest.approx((0.0, math.sin(math.radians(40)),
                                         math.cos(math.radians(40))), abs=1e-15)
    assert walks[0].mu_edges == (0.0, 0.25, 0.5, 0.75, 1.0)
    assert walks[0].phi_edges == pytest.approx((0, 2 * math.pi / 3, 4 * math.pi / 3, 2 * math.pi))
    assert {(w.seed, w.backend, w.max_steps) for w in walks} == {(9, "warp-cpu", 100_000)}
    assert walks[3].scene.stacks[0][1].ior == pytest.approx(complex(0.5, 2.4))
    assert texts == {"scenes/slab.toml": SLAB, "scenes/gold.toml": RGB_GOLD}
    assert (options["paths"], options["stderr"], options["bins"]) == (1_000_000, None, (4, 3))
    assert options["walk_scene"] == [0, 0] + [1] * 6
    assert options["walk_channel"] == [0, 0, 0, 1, 2, 0, 1, 2]
    assert options["scene_names"] == ["slab", "gold"]


def test_chosen_channels_stderr_target_and_light_from_below(folder):
    body = GOOD.replace('scenes = ["scenes/slab.toml", "scenes/gold.toml"]',
                        'scenes = ["scenes/gold.toml"]\nchannels = [2]\nstderr = 1e-4')
    body = body.replace("paths = 1e6\n", "")
    walks, _, options = read_sweep(_sweep(folder, body))
    assert [w.scene.name for w in walks] == ["gold[B]", "gold[B]"]
    assert (options["paths"], options["stderr"]) == (MAX_PATHS, 1e-4)
    below = GOOD.replace("scenes/gold.toml", "scenes/slab.toml").replace(
        '"scenes/slab.toml", "scenes/slab.toml"', '"scenes/slab.toml"').replace(
        "[40, 90]", "[150, 0]")
    walks, _, _ = read_sweep(_sweep(folder, below))
    assert walks[1].wi[2] == pytest.approx(-math.cos(math.radians(30)))


def test_direction_is_a_unit_vector():
    for theta, phi in [(0, 0), (30, 45), (89.9, 300), (120, 10)]:
        assert math.fsum(x * x for x in direction(theta, phi)) == pytest.approx(1.0, abs=1e-15)


ERRORS = [
    ("angles = [[0, 0], [40, 90]]", "angles = [[0, 0], [90, 0]]", "field 'angles[1]': theta"),
    ("angles = [[0, 0], [40, 90]]", "angles = [[0, 0], [40]]", "field 'angles[1]': must be"),
    ("angles = [[0, 0], [40, 90]]", "angles = []", "field 'angles': must be a non-empty"),
    ("angles = [[0, 0], [40, 90]]", "angles = [[0, 0], [100, 0]]",
     "field 'angles[1]': theta 100 > 90 lights the stack from below, but scene 'gold' is opaque"),
    ("paths = 1e6", "paths = 0", "field 'paths': must be in [1, "),
    ("paths = 1e6", "paths = 1.5", "field 'paths': must be an integer"),
    ("paths = 1e6", "", "field 'paths': give paths (per walk), a stderr target, or both"),
    ("paths = 1e6", "paths = 1e6\nstderr = 2", "field 'stderr': must be a number in (0, 1)"),
    ("bins = [4, 3]", "bins = [4]", "field 'bins': must be [n_mu, n_phi]"),
    ("bins = [4, 3]", "bins = [4, 0]", "field 'bins[1]': must be in [1, "),
    ("seed = 9", "seed = -1", "field 'seed': must be in [0, "),
    ('backend = "warp-cpu"', 'backend = "gpu"', "field 'backend': must be one of"),
    ("seed = 9", "seed = 9\nchannels = [3]", "field 'channels': channel 3 does not exist"),
    ("seed = 9", "seed = 9\nchannels = [0, 0]", "field 'channels': must be \"all\" or"),
    ("seed = 9", "seed = 9\nparticles = 5", "field 'particles': unknown field (allowed:"),
    ('scenes = ["scenes/slab.toml", "scenes/gold.toml"]', "", "field 'scenes': missing"),
    ('scenes = ["scenes/slab.toml", "scenes/gold.toml"]', 'scenes = ["scenes/none.toml"]',
     "field 'scenes[0]': no scene file"),
    ('scenes = ["scenes/slab.toml", "scenes/gold.toml"]', 'scenes = ["scenes/slab.toml"] * 2',
     "not a TOML sweep file"),
    ("[sweep]", "[sweep]\n[other]", "a sweep file holds one [sweep] table and nothing else"),
]


@pytest.mark.parametrize("old,new,message", ERRORS)
def test_bad_fields_are_named_in_one_line(folder, old, new, message):
    assert old in GOOD
    path = _sweep(folder, GOOD.replace(old, new))
    with pytest.raises(SweepError) as info:
        read_sweep(path)
    text = str(info.value)
    assert text.startswith(str(path) + ": ") and message in text and "\n" not in text


def test_a_bad_scene_file_is_named(folder):
    (folder / "scenes" / "gold.toml").write_text(RGB_GOLD.replace("ior = 1.5", "ior = -1"))
    with pytest.raises(SceneError, match="gold.toml"):
        read_sweep(_sweep(folder, GOOD))


def test_a_missing_sweep_file_is_one_line(tmp_path):
    with pytest.raises(SweepError, match="cannot read the sweep file"):
        read_sweep(tmp_path / "nothing.toml")
