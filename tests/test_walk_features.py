"""The walk is built for the code paths a scene uses (layersim.kernels.walk.Features): the
records say which paths those are, a kernel built without the others gives the tallies of the
kernel with every path, and the OpenCL translation leaves the same paths out."""
import numpy as np
import pytest

import layersim
import layersim.montecarlo as mc
from layersim.kernels import walk
from layersim.montecarlo.backends import opencl_source
from layersim.montecarlo.stack import StackArrays, flatten

GOLD = [0.143552, 3.98397]
SCENES = {
    "coated gold": ({"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.1},
                               {"kind": "conductor", "ior": GOLD, "roughness": 0.1}]},
                    {"beckmann"}),
    "hg slab": ({"layer": [{"kind": "medium", "albedo": 0.95, "g": 0.5, "tau": 2.0}]},
                {"media"}),
    "ggx coat over hg over diffuse": (
        {"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.3, "distribution": "ggx",
                    "energy_compensation": "multiple-scattering"},
                   {"kind": "medium", "albedo": 0.8, "g": 0.3, "tau": 1.0},
                   {"kind": "diffuse", "albedo": 0.5}]},
        {"ggx", "compensation", "media", "diffuse"}),
    "smooth coat over rough gold": (
        {"layer": [{"kind": "dielectric", "ior": 1.5},
                   {"kind": "conductor", "ior": GOLD, "roughness": [0.1, 0.3]}]},
        {"smooth", "beckmann"}),
    "filmed gold": ({"layer": [{"kind": "conductor", "ior": GOLD, "roughness": 0.2,
                                "film": {"thickness": 400.0, "ior": 1.4}}],
                     "stack": {"wavelengths": [550.0]}},
                    {"beckmann", "film"}),
    "height-correlated ggx coat": (
        {"stack": {"shadowing": "height-correlated-beta"},
         "layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.3, "distribution": "ggx"},
                   {"kind": "conductor", "ior": GOLD, "roughness": 0.2, "distribution": "ggx"}]},
        {"ggx", "height_correlated"}),
    "clear gap between two interfaces": (
        {"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.2},
                   {"kind": "dielectric", "ior": 1.0, "roughness": 0.2}]},
        {"beckmann"}),
}
MU, PHI = np.linspace(0, 1, 6), np.linspace(0, 2 * np.pi, 9)
WI = np.array([np.sin(0.5), 0.0, np.cos(0.5)])


@pytest.mark.parametrize("name", SCENES)
def test_the_records_say_which_paths_the_walk_needs(name):
    data, used = SCENES[name]
    features = flatten(layersim.Scene.from_dict(data)).features
    names = {f for f in vars(walk.Features()) if getattr(features, f)}
    assert names == used
    assert set(features.left_out()) == set(vars(walk.Features())) - used


def test_every_path_is_the_union_and_the_default():
    f = walk.Features(**{k: False for k in vars(walk.Features())})
    assert f.left_out() and not f.interfaces
    assert (f | walk.Features.every()) == walk.Features.every() == walk.Features()
    assert walk.program(walk.Features.every()) is walk.EVERY
    assert walk.program(f) is walk.program(walk.Features(**vars(f)))       # built once


@pytest.mark.slow
@pytest.mark.parametrize("name", ["coated gold", "hg slab", "ggx coat over hg over diffuse",
                                  "filmed gold", "height-correlated ggx coat"])
def test_a_kernel_without_the_unused_paths_walks_the_same_paths(name, monkeypatch):
    """Same seed, same particles: the specialised kernel and the one with every path agree to
    float32 rounding (0.02 standard errors in every bin), and report what was left out."""
    data, used = SCENES[name]
    scene = layersim.Scene.from_dict(data)
    lean = mc.simulate(scene, WI, 50_000, MU, PHI, backend="warp-cpu", seed=4)
    assert set(lean.left_out) == set(vars(walk.Features())) - used
    monkeypatch.setattr(StackArrays, "features", property(lambda self: walk.Features.every()))
    full = mc.simulate(scene, WI, 50_000, MU, PHI, backend="warp-cpu", seed=4)
    assert full.left_out == ()
    for side in ("top", "bottom"):
        s = np.hypot(lean.bins_stderr[side], full.bins_stderr[side])
        diff = np.abs(np.asarray(lean.bins[side]) - np.asarray(full.bins[side]))
        assert np.all(diff <= 0.02 * s + 1e-12)
    assert abs(lean.reflectance - full.reflectance) <= 0.02 * lean.reflectance_stderr + 1e-12


def test_the_opencl_translation_leaves_the_same_paths_out():
    lean = walk.Features(smooth=False, ggx=False, tabulated=False, compensation=False,
                         diffuse=False, measured=False, media=True)
    src, every = opencl_source(lean), opencl_source()
    for fn in ("choose_lobe", "sample_microfacet_tabulated", "sample_measured",
               "sample_smooth", "sample_cosine_hemisphere"):
        assert fn in every and fn not in src
    assert "sample_microfacet" in src and "sample_hg" in src and len(src) < 0.7 * len(every)


@pytest.mark.parametrize("name", ["ggx coat over hg over diffuse",
                                  "height-correlated ggx coat"])
def test_the_opencl_walk_runs_the_specialised_kernel(cl_device, name):
    data, _ = SCENES[name]
    scene = layersim.Scene.from_dict(data)
    a = mc.simulate(scene, WI, 20_000, MU, PHI, backend="opencl", seed=2)
    b = mc.simulate(scene, WI, 20_000, MU, PHI, backend="warp-cpu", seed=2)
    assert a.left_out == b.left_out
    s = np.hypot(a.bins_stderr["top"], b.bins_stderr["top"])
    assert np.all(np.abs(np.asarray(a.bins["top"]) - np.asarray(b.bins["top"])) <= 0.05 * s
                  + 1e-12)
