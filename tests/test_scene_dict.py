"""``Scene.to_dict``: every layer kind written back to the scene format, read back to an equal
scene (directly and through the TOML writer), and the refusal of a layer that has no table."""

import glob
import tomllib
from pathlib import Path

import numpy as np
import pytest

import layersim
from layersim.errors import SceneError
from layersim.scene import Measured, Scene
from layersim.tomlwrite import dumps

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
#: The example scene files (the design target files beside them are not scenes).
SCENE_FILES = [p for p in sorted(glob.glob(str(EXAMPLES / "*.toml")))
               if "layer" in tomllib.loads(Path(p).read_text())]

SCENES = {
    "filmed rgb stack": {
        "stack": {"name": "film", "top_ior": 1.2, "wavelengths": [650.0, 550.0, 450.0]},
        "layer": [{"kind": "dielectric", "ior": [1.5, 1.52, 1.55], "roughness": [0.1, 0.2],
                   "distribution": "ggx", "rotation": 30.0,
                   "film": {"thickness": 300.0, "ior": 1.38}},
                  {"kind": "medium", "tau": [0.5, 1.0, 2.0], "albedo": 0.9, "g": [0.1, 0.2, 0.3]},
                  {"kind": "conductor", "ior": [[0.2, 3.6], [0.5, 2.5], [1.4, 1.9]],
                   "roughness": 0.3}],
        "discretization": {"n": 64, "md": 80}},
    "compensated, height-correlated": {
        "stack": {"energy_compensation": "multiple-scattering", "shadowing": "height-correlated"},
        "layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.4, "distribution": "ggx"},
                  {"kind": "dielectric", "ior": 1.3, "roughness": 0.0},
                  {"kind": "diffuse", "albedo": [0.2, 0.4, 0.6]}]},
    "tabulated": {
        "layer": [{"kind": "conductor", "ior": [0.2, 3.6], "distribution": "tabulated",
                   "ndf": {"theta": [0.0, 30.0, 60.0, 90.0], "phi": [0.0, 90.0, 180.0, 270.0],
                           "D": [[2.0] * 4, [1.0] * 4, [0.2] * 4, [0.0] * 4]}}]},
}


def _same(a: Scene, b: Scene) -> None:
    assert a.stacks == b.stacks
    assert (a.top_ior, a.name, a.wavelengths, a.discretization) == \
        (b.top_ior, b.name, b.wavelengths, b.discretization)
    for x, y in zip(a.stacks[0], b.stacks[0]):
        if getattr(x, "ndf", None) is not None:
            np.testing.assert_allclose(x.ndf.D, y.ndf.D, rtol=1e-12)


@pytest.mark.parametrize("data", SCENES.values(), ids=SCENES.keys())
def test_round_trip(data):
    scene = Scene.from_dict(data)
    _same(Scene.from_dict(scene.to_dict()), scene)
    _same(Scene.from_dict(tomllib.loads(dumps(scene.to_dict()))), scene)


@pytest.mark.parametrize("path", SCENE_FILES, ids=lambda p: Path(p).name)
def test_examples_round_trip(path):
    scene = layersim.Scene.from_toml(path)
    _same(Scene.from_dict(scene.to_dict(), default_name=scene.name), scene)


def test_measured_base_is_refused_naming_the_layer():
    scene = Scene(stacks=((Measured(),),))
    with pytest.raises(SceneError) as e:
        scene.to_dict()
    assert e.value.layer == 0 and "measured" in str(e.value)
