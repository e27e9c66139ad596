"""The pbrt-v4 material importer (``Scene.from_pbrt``, ``layersim import-pbrt``) and the TOML
writer it uses."""

import math
import tomllib

import pytest

import layersim
from layersim.cli import main
from layersim.errors import SceneError
from layersim.pbrtimport import pbrt_to_dict
from layersim.tomlwrite import dumps

COATED_GOLD = '''# set a of pbrt4_layered.json
Material "coatedconductor"
    "float interface.roughness" [ 0.1 ] "float interface.eta" 1.5
    "float thickness" 0.01 "bool remaproughness" false
    "float conductor.roughness" 0.1
    "spectrum conductor.eta" [ 0.143552 ] "spectrum conductor.k" [ 3.98397 ]
    "integer maxdepth" 100 "integer nsamples" 64
Shape "sphere"
'''


def test_coated_conductor_maps_every_parameter():
    data, notes = pbrt_to_dict(COATED_GOLD)
    assert data["stack"]["shadowing"] == "height-correlated"
    coat, medium, base = data["layer"]
    assert coat == {"kind": "dielectric", "ior": 1.5, "roughness": 0.1, "distribution": "ggx"}
    assert medium == {"kind": "medium", "tau": 0.01, "albedo": 0.0, "g": 0.0}
    assert base["ior"] == [0.143552, 3.98397] and base["roughness"] == 0.1
    assert [n.split(":")[0] for n in notes[:2]] == ["maxdepth", "nsamples"]
    assert all("not needed" in n for n in notes[:2]) and "two-sided" in notes[2]
    scene = layersim.Scene.from_pbrt(COATED_GOLD)
    assert [x.shadowing for x in scene.layers if x.is_interface] == ["height-correlated"] * 2


def test_coated_diffuse_named_material_rgb_and_remap():
    data, notes = pbrt_to_dict('MakeNamedMaterial "paint" "string type" "coateddiffuse" '
                               '"rgb reflectance" [0.2 0.3 0.4] "float roughness" 0.04 '
                               '"float thickness" 0.3 "rgb albedo" [0.9 0.9 0.9] "float g" 0.3')
    coat, medium, base = data["layer"]
    assert coat["roughness"] == pytest.approx(0.2)          # remaproughness: sqrt(0.04)
    assert medium == {"kind": "medium", "tau": 0.3, "albedo": 0.9, "g": 0.3}
    assert base == {"kind": "diffuse", "albedo": [0.2, 0.3, 0.4]}
    assert len(notes) == 1 and "two-sided" in notes[0]
    assert layersim.Scene.from_dict(data).channels == 3


@pytest.mark.parametrize("text, layers", [
    ('Material "diffuse" "rgb reflectance" [0.5 0.5 0.5]', [{"kind": "diffuse", "albedo": 0.5}]),
    ('Material "dielectric" "float eta" 1.33 "float uroughness" 0.09 "float vroughness" 0.09',
     [{"kind": "dielectric", "ior": 1.33, "roughness": 0.3, "distribution": "ggx"}]),
    ('Material "dielectric"', [{"kind": "dielectric", "ior": 1.5, "roughness": 0.0}]),
    ('Material "conductor" "float reflectance" 0.64 "float roughness" 0.2 '
     '"bool remaproughness" false',
     [{"kind": "conductor", "ior": [1.0, 2 * 0.8 / 0.6], "roughness": 0.2,
       "distribution": "ggx"}]),
])
def test_single_layer_materials(text, layers):
    data, _ = pbrt_to_dict(text)
    for key, value in layers[0].items():
        got = data["layer"][0][key]
        assert got == (pytest.approx(value) if not isinstance(value, str) else value), key
    layersim.Scene.from_dict(data)


def test_conductor_reflectance_has_that_normal_incidence_reflectance():
    data, _ = pbrt_to_dict('Material "conductor" "float reflectance" 0.3')
    eta, k = data["layer"][0]["ior"]
    assert ((eta - 1) ** 2 + k ** 2) / ((eta + 1) ** 2 + k ** 2) == pytest.approx(0.3)


@pytest.mark.parametrize("text, field", [
    ('Material "conductor" "spectrum eta" "metal-Au-eta" "spectrum k" "metal-Au-k"', "eta"),
    ('Material "coateddiffuse" "spectrum reflectance" [400 0.2 700 0.4]', "reflectance"),
    ('Material "conductor" "float roughness" 0.1', "eta"),
    ('Material "coateddiffuse" "texture reflectance" "checks"', "reflectance"),
    ('Material "diffuse" "float sigma" 3', "sigma"),
    ('Material "measured" "string filename" "x.bsdf"', "type"),
])
def test_refusals_name_the_parameter(text, field):
    with pytest.raises(SceneError) as e:
        pbrt_to_dict(text)
    assert e.value.field == field and field in str(e.value)


def test_one_material_at_a_time():
    with pytest.raises(SceneError, match="2 Material"):
        pbrt_to_dict('Material "diffuse"\nMaterial "dielectric"')


def test_cli_writes_toml_that_reads_back(tmp_path, capsys):
    src = tmp_path / "gold.pbrt"
    src.write_text(COATED_GOLD)
    out = tmp_path / "gold.toml"
    assert main(["import-pbrt", str(src), "-o", str(out)]) == 0
    data, _ = pbrt_to_dict(COATED_GOLD, "gold")
    assert tomllib.loads(out.read_text()) == data
    assert "maxdepth: not needed" in capsys.readouterr().out
    assert layersim.Scene.from_toml(out).layers == layersim.Scene.from_dict(data).layers


def test_cli_refusal_is_one_line_exit_2(tmp_path, capsys):
    src = tmp_path / "bad.pbrt"
    src.write_text('Material "conductor" "spectrum eta" "metal-Au-eta"')
    assert main(["import-pbrt", str(src), "-o", str(tmp_path / "bad.toml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "eta" in err and not (tmp_path / "bad.toml").exists()


def test_toml_writer_round_trips_values():
    data = {"stack": {"name": "x \"q\"", "wavelengths": [650.0, 550.0, 450.0]},
            "layer": [{"kind": "dielectric", "ior": 1.5, "roughness": [0.1, 0.2],
                       "film": {"thickness": 300.0, "ior": 1.38}},
                      {"kind": "conductor", "ior": [[0.2, 3.6], [0.5, 2.5], [1.4, 1.9]],
                       "roughness": 1e-05}]}
    assert tomllib.loads(dumps(data, "a\nb")) == data
    with pytest.raises(ValueError):
        dumps({"stack": {"top_ior": math.inf}})
