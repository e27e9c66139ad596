"""Conductor-base inference of `layersim design`: a bottom lobe without a base that no
dielectric stack reaches gets a conductor, with a one-line note; a lobe a dielectric reaches
keeps a dielectric; a base the targets give wins."""

import tomllib
import warnings
from pathlib import Path

import pytest

import layersim
from layersim.statistical import TargetError, designs
from layersim.statistical.design import InferredBaseWarning

ROOT = Path(__file__).resolve().parents[1]
METAL = [{"energy": [0.9, 0.7, 0.5], "roughness": 0.15}]


def kinds(design):
    return [layer["kind"] for layer in design.data["layer"]]


@pytest.mark.slow
def test_a_metal_coloured_lobe_gets_a_conductor_base_and_a_note_naming_the_bound():
    d = designs(METAL)[0]
    assert kinds(d) == ["conductor"]
    note, = d.notes
    assert "\n" not in note and note.startswith('lobe 1: base = "conductor" inferred')
    # why: the 1-layer dielectric bound at this roughness (Bati et al. 2021 sec. 5.2.1)
    assert "reaches at most 0.35" in note and "needs 0.9" in note
    with pytest.warns(InferredBaseWarning, match="lobe 1: base = \"conductor\" inferred") as w:
        scenes = layersim.design(METAL)
    assert w[0].filename == __file__                   # attributed to the caller
    assert scenes[0].channel(0).layers[0].kind == "conductor"


@pytest.mark.slow
def test_the_inferred_base_lies_under_the_coats_of_a_multi_lobe_target():
    d = designs([{"energy": 0.04, "roughness": 0.1},
                 {"energy": [0.8, 0.6, 0.4], "roughness": 0.3}])[0]
    assert kinds(d)[0] == "dielectric" and kinds(d)[-1] == "conductor"
    assert len(d.notes) == 1 and d.notes[0].startswith("lobe 2: ")


@pytest.mark.parametrize("lobes", [
    [{"energy": 0.2, "roughness": 0.15}],                         # 1 layer
    pytest.param([{"energy": [0.2, 0.15, 0.1], "roughness": 0.15}],   # coloured: 2 layers
                 marks=pytest.mark.slow),
    [{"energy": 0.04, "roughness": 0.1}, {"energy": 0.06, "roughness": 0.3}],
])
def test_a_lobe_a_dielectric_reaches_keeps_a_dielectric(lobes):
    with warnings.catch_warnings():
        warnings.simplefilter("error", InferredBaseWarning)
        found = designs(lobes)
        layersim.design(lobes)
    assert all("conductor" not in kinds(d) and not d.notes for d in found)


def test_an_explicit_base_wins():
    with pytest.raises(TargetError, match=r"lobe 1: field 'energy'.*reaches at most 0\.35"):
        designs([{**METAL[0], "base": "dielectric"}])
    d = designs([{"energy": 0.2, "roughness": 0.15, "base": "conductor"}])
    assert kinds(d[0]) == ["conductor"] and not d[0].notes


def test_targets_neither_base_reaches_name_both_bounds():
    # a specular lobe under a rough one: no base makes it sharper than the coat's spread
    with pytest.raises(TargetError, match="lobe 2: field 'roughness'.*with a conductor base"):
        designs([{"energy": 0.04, "roughness": 0.3}, {"energy": 0.3, "roughness": 0.0}])


@pytest.mark.slow
def test_the_example_sets_that_give_a_conductor_base_need_it():
    """Every set of examples/design_targets.toml that writes base = "conductor" would get
    one without it where a dielectric cannot reach it, and the same stack."""
    sets = tomllib.loads((ROOT / "examples" / "design_targets.toml").read_text())["set"]
    for s in sets:
        if s["name"] not in ("grey conductor", "gold-like conductor"):
            continue
        given = designs(s["lobe"])[0]
        left_open = designs([{k: v for k, v in s["lobe"][0].items() if k != "base"}])[0]
        assert left_open.data == given.data and left_open.notes


def test_cli_design_says_in_one_line_that_it_inferred_the_base(tmp_path, capsys):
    from layersim.cli import main
    targets, out = tmp_path / "metal.toml", tmp_path / "stack.toml"
    targets.write_text("[[lobe]]\nenergy = [0.9, 0.7, 0.5]\nroughness = 0.15\n")
    assert main(["design", str(targets), "--no-verify", "-o", str(out)]) == 0
    notes = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("note: ")]
    assert len(notes) == 1 and 'base = "conductor" inferred' in notes[0]
    text = out.read_text()
    assert 'inferred' in text.splitlines()[1]              # the note, as a comment
    assert layersim.Scene.from_toml(out).channel(0).layers[0].kind == "conductor"
