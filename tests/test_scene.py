"""Scene contract: parsing, derived optics, and clear errors for malformed input."""

import math
import subprocess
import sys
import textwrap

import pytest

import layersim
from layersim import SceneError
from layersim.cli import main as cli_main

GOLD = [0.143552, 3.98397]


def test_toml_and_dict_give_the_same_scene(tmp_path):
    text = textwrap.dedent("""
        [stack]
        name = "demo"
        top_ior = 1.0

        [[layer]]
        kind = "dielectric"
        ior = 1.5
        roughness = [0.1, 0.2]
        rotation = 30

        [[layer]]
        kind = "medium"
        albedo = 0.95
        g = 0.5
        tau = 2.0

        [[layer]]
        kind = "conductor"
        ior = [0.143552, 3.98397]
        roughness = 0.2
    """)
    path = tmp_path / "demo.toml"
    path.write_text(text)
    a = layersim.Scene.from_toml(path)
    b = layersim.Scene.from_dict({
        "stack": {"name": "demo", "top_ior": 1.0},
        "layer": [{"kind": "dielectric", "ior": 1.5, "roughness": [0.1, 0.2], "rotation": 30},
                  {"kind": "medium", "albedo": 0.95, "g": 0.5, "tau": 2.0},
                  {"kind": "conductor", "ior": GOLD, "roughness": 0.2}]})
    assert a.stacks == b.stacks and a.name == b.name == "demo"
    d = a.layers[0]
    assert (d.alpha_u, d.alpha_v) == (0.1, 0.2) and d.anisotropic
    assert math.isclose(d.rotation, math.radians(30))
    assert a.opaque and a.bottom_ior is None
    # indices: the medium sits in the coating's dielectric; gold is relative to it
    assert a.ior_above(1) == 1.5
    assert a.relative_ior(2) == pytest.approx(complex(*GOLD) / 1.5)


def test_rgb_values_make_three_channels():
    s = layersim.Scene.from_dict({"layer": [
        {"kind": "medium", "albedo": [0.6, 0.8, 0.95], "g": 0.2, "tau": 1},
        {"kind": "conductor", "ior": [[0.14, 3.98], [0.38, 2.38], [1.44, 1.60]],
         "roughness": 0.1}]})
    assert s.channels == 3
    assert [s.channel(c).layers[0].albedo for c in range(3)] == [0.6, 0.8, 0.95]
    assert s.channel(2).layers[1].ior == complex(1.44, 1.60)
    with pytest.raises(ValueError, match="channel"):
        s.layers


def test_transmissive_stack_has_a_bottom_medium():
    s = layersim.Scene.from_dict({"stack": {"top_ior": 1.33}, "layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.1},
        {"kind": "medium", "albedo": 0.5, "tau": 1}]})
    assert not s.opaque and s.bottom_ior == 1.5
    assert s.relative_ior(0) == pytest.approx(1.5 / 1.33)


# (scene dict, expected words in the message: layer/field names)
BAD_SCENES = [
    ({}, ["no layers"]),
    ({"layer": []}, ["non-empty"]),
    ({"layers": [{"kind": "diffuse", "albedo": 0.5}]}, ["unknown top-level", "layers"]),
    ({"layer": [{"albedo": 0.5}]}, ["layer 0", "'kind'", "missing"]),
    ({"layer": [{"kind": "velvet"}]}, ["layer 0", "unknown kind", "velvet"]),
    ({"layer": [{"kind": "diffuse", "albedo": 1.2}]}, ["layer 0 (diffuse)", "'albedo'", "<= 1"]),
    ({"layer": [{"kind": "diffuse", "albedo": -0.1}]}, ["'albedo'", ">= 0"]),
    ({"layer": [{"kind": "diffuse"}]}, ["'albedo'", "required"]),
    ({"layer": [{"kind": "medium", "albedo": 0.5, "tau": -1}]}, ["layer 0 (medium)", "'tau'"]),
    ({"layer": [{"kind": "medium", "albedo": 0.5, "tau": float("inf")}]}, ["'tau'", "finite"]),
    ({"layer": [{"kind": "medium", "albedo": float("nan"), "tau": 1}]}, ["'albedo'", "finite"]),
    ({"layer": [{"kind": "medium", "albedo": 0.5, "g": 1.0, "tau": 1}]}, ["'g'", "< 1"]),
    ({"layer": [{"kind": "medium", "albedo": 0.5, "g": -1.5, "tau": 1}]}, ["'g'"]),
    ({"layer": [{"kind": "medium", "albedo": "high", "tau": 1}]}, ["'albedo'", "number"]),
    ({"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": -0.1}]},
     ["layer 0 (dielectric)", "'roughness'", ">= 0"]),
    ({"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": [0.1, 0.2, 0.3]}]},
     ["'roughness'", "alpha_u, alpha_v"]),
    ({"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": [0.0, 0.2]}]},
     ["'roughness'", "smooth along one axis"]),
    ({"layer": [{"kind": "dielectric", "ior": 0.0}]}, ["'ior'", "> 0"]),
    ({"layer": [{"kind": "dielectric", "ior": 1.5, "rougness": 0.1}]},
     ["layer 0 (dielectric)", "'rougness'", "unknown field"]),
    ({"layer": [{"kind": "dielectric", "ior": 1.5, "distribution": "phong"}]},
     ["'distribution'", "phong"]),
    ({"layer": [{"kind": "conductor", "ior": 1.5}]}, ["layer 0 (conductor)", "'ior'", "[eta, k]"]),
    ({"layer": [{"kind": "conductor", "ior": [0.2, 0.0]}]}, ["'ior.k'", "> 0"]),
    ({"layer": [{"kind": "conductor", "ior": [-0.2, 3.0]}]}, ["'ior.eta'", ">= 0"]),
    ({"layer": [{"kind": "diffuse", "albedo": 0.5}, {"kind": "medium", "albedo": 0.5, "tau": 1}]},
     ["layer 0 (diffuse)", "bottom layer"]),
    ({"layer": [{"kind": "conductor", "ior": GOLD}, {"kind": "diffuse", "albedo": 0.5}]},
     ["layer 0 (conductor)", "bottom layer"]),
    ({"layer": [{"kind": "medium", "albedo": [0.5, 0.6], "tau": 1}]}, ["'albedo'", "3"]),
    ({"stack": {"top_ior": -1}, "layer": [{"kind": "diffuse", "albedo": 0.5}]},
     ["stack.top_ior", "> 0"]),
    ({"stack": {"top_index": 1.0}, "layer": [{"kind": "diffuse", "albedo": 0.5}]},
     ["top_index"]),
    ({"layer": [{"kind": "diffuse", "albedo": 0.5}], "discretization": {"n": 15}},
     ["discretization.n", "even"]),
    ({"layer": [{"kind": "diffuse", "albedo": 0.5}], "discretization": {"m": 10}},
     ["[discretization]", "'m'"]),
    ({"layer": [{"kind": "diffuse", "albedo": 0.5}], "discretization": {"md": 0}},
     ["discretization.md"]),
    ({"layer": [{"kind": "diffuse", "albedo": 0.5}],
      "discretization": {"quadrature": "trapezoid"}}, ["quadrature", "trapezoid"]),
    ({"layer": [{"kind": "diffuse", "albedo": 0.5}],
      "discretization": {"quadrature": "simpson38", "n": 12}}, ["3k + 1"]),
    ({"layer": [{"kind": "dielectric", "ior": 1.5, "rotation": True}]}, ["'rotation'", "number"]),
]


@pytest.mark.parametrize("data,words", BAD_SCENES, ids=[str(i) for i in range(len(BAD_SCENES))])
def test_malformed_scenes_are_rejected_with_a_clear_message(data, words):
    with pytest.raises(SceneError) as info:
        layersim.Scene.from_dict(data)
    message = str(info.value)
    for w in words:
        assert w in message, f"{w!r} not in {message!r}"


def test_at_least_twenty_malformed_scenes_are_covered():
    assert len(BAD_SCENES) >= 20


def test_errors_name_the_layer_index_kind_and_field():
    with pytest.raises(SceneError) as info:
        layersim.Scene.from_dict({"layer": [
            {"kind": "dielectric", "ior": 1.5, "roughness": 0.1},
            {"kind": "medium", "albedo": 0.5, "tau": -2}]})
    err = info.value
    assert (err.layer, err.kind, err.field) == (1, "medium", "tau")


def test_invalid_toml_is_reported_with_the_file_name(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[[layer]]\nkind = diffuse\n")
    with pytest.raises(SceneError, match="broken.toml.*not valid TOML"):
        layersim.Scene.from_toml(path)


def test_cli_prints_one_line_and_exits_nonzero_on_bad_input(tmp_path, capsys):
    path = tmp_path / "bad.toml"
    path.write_text('[[layer]]\nkind = "medium"\nalbedo = 1.5\ntau = 1\n')
    assert cli_main(["solve", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert err[0].startswith("layersim: error:") and "albedo" in err[0]
    assert cli_main(["plan", str(tmp_path / "missing.toml")]) == 2


@pytest.mark.slow
def test_cli_subprocess_has_no_traceback(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('[[layer]]\nkind = "conductor"\nior = [0.2, 3.0]\n[[layer]]\n'
                    'kind = "diffuse"\nalbedo = 0.5\n')
    proc = subprocess.run([sys.executable, "-m", "layersim.cli", "plan", str(path)],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip().count("\n") == 0 and "bottom layer" in proc.stderr


def test_cli_solve_writes_a_file_that_info_reloads(tmp_path, capsys):
    scene = tmp_path / "slab.toml"
    scene.write_text('[[layer]]\nkind = "medium"\nalbedo = 0.9\ntau = 2.0\n')
    out = tmp_path / "slab.lsim"
    assert cli_main(["solve", str(scene), "-o", str(out)]) == 0
    solved = capsys.readouterr().out
    assert "ordinates: n = " in solved and "albedo (energy fractions)" in solved
    assert cli_main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "transmissive" in text
    # the albedo table is the same after reloading
    rows = lambda t: [line for line in t.splitlines() if line.strip().startswith(("0.0", "30.0"))]
    assert rows(text) == rows(solved) and len(rows(text)) == 2
    (tmp_path / "junk.lsim").write_text("nope")
    assert cli_main(["info", str(tmp_path / "junk.lsim")]) == 2
