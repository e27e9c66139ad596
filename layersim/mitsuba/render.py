"""A material-test render of a solved stack with Mitsuba 3 (``layersim render``).

The scene is a unit sphere with the stack as its BSDF (the ``layersim`` plug-in, whose local
frame on a sphere is Mitsuba's shading frame: ``z`` the normal), a perspective camera, a point
light and the environment map of :mod:`layersim.mitsuba.sky` (generated here, nothing is
downloaded): a sky from a pale horizon to blue at the zenith, a dim warm ground, a small sun.
It renders in ``llvm_ad_rgb`` where LLVM >= 16 is found (whole wavefronts per BSDF call, in
Dr.Jit's evaluated mode, which a Python BSDF needs), else in ``scalar_rgb`` (one ray per call:
much slower).
"""

from __future__ import annotations

from pathlib import Path

from .llvm import point_drjit_to_llvm
from .sky import sky_bitmap


def scene_dict(mi, lsim: str, resolution: tuple[int, int], spp: int) -> dict:
    """The Mitsuba scene description of the material test (module docstring)."""
    look = mi.ScalarTransform4f().look_at(origin=[0, 0.8, 4.2], target=[0, 0, 0], up=[0, 1, 0])
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 6},
        "sensor": {"type": "perspective", "fov": 32, "to_world": look,
                   "film": {"type": "hdrfilm", "width": resolution[0],
                            "height": resolution[1], "rfilter": {"type": "gaussian"}},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "sky": {"type": "envmap", "bitmap": mi.Bitmap(sky_bitmap())},
        "lamp": {"type": "point", "position": [2.5, 3.0, 3.0],
                 "intensity": {"type": "rgb", "value": [15.0, 15.0, 15.0]}},
        "sphere": {"type": "sphere", "bsdf": {"type": "layersim", "filename": lsim}},
    }


def start_variant(mi) -> str:
    """Set ``llvm_ad_rgb`` in evaluated mode where it starts, else ``scalar_rgb``; the name."""
    import drjit as dr
    try:
        mi.set_variant("llvm_ad_rgb")
        mi.Float(0.0)                                # raises where LLVM is missing
    except Exception:                                # Dr.Jit's error when LLVM is absent
        mi.set_variant("scalar_rgb")
        return "scalar_rgb"
    dr.set_flag(dr.JitFlag.SymbolicLoops, False)
    dr.set_flag(dr.JitFlag.SymbolicCalls, False)
    return "llvm_ad_rgb"


def render(lsim, output, resolution=(128, 128), spp=16, seed: int = 0) -> str:
    """Render the solved stack in ``lsim`` (a ``.lsim`` file) to the PNG ``output``
    (sRGB, 8 bit); returns the variant used."""
    point_drjit_to_llvm()
    import mitsuba as mi
    from . import register
    variant = start_variant(mi)
    register()
    scene = mi.load_dict(scene_dict(mi, str(Path(lsim).resolve()), resolution, spp))
    image = mi.render(scene, seed=seed)
    mi.util.write_bitmap(str(output), image, write_async=False)
    return variant



def orthographic_dict(mi, lsim: str, resolution: int, spp: int, view) -> dict:
    """The material test seen by an orthographic camera from the unit direction ``view``
    (world space, ``y`` up), the unit sphere filling a ``resolution`` square, under the sky
    alone (no point light): the view of :mod:`layersim.bench.binrender`."""
    d = scene_dict(mi, lsim, (resolution, resolution), spp)
    del d["lamp"]
    origin = [4.0 * float(x) for x in view]
    d["sensor"] = {"type": "orthographic",
                   "to_world": mi.ScalarTransform4f().look_at(origin=origin, target=[0, 0, 0],
                                                              up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": resolution, "height": resolution,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": spp}}
    return d


def render_orthographic(lsim, resolution: int, spp: int, view, seed: int = 0):
    """Render :func:`orthographic_dict` for the solved stack in ``lsim`` (a ``.lsim`` file):
    ``(image, variant)``, the image linear RGB as a numpy array (resolution, resolution, 3)."""
    point_drjit_to_llvm()
    import mitsuba as mi
    from . import register
    variant = start_variant(mi)
    register()
    scene = mi.load_dict(orthographic_dict(mi, str(Path(lsim).resolve()), resolution, spp,
                                           view))
    import numpy as np
    return np.array(mi.render(scene, seed=seed))[..., :3], variant
