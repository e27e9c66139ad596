"""A material-test render of a solved stack with Mitsuba 3 (``layersim render``).

The scene is a unit sphere with the stack as its BSDF (the ``layersim`` plug-in, whose local
frame on a sphere is Mitsuba's shading frame: ``z`` the normal), a perspective camera, a point
light and an environment map generated here (nothing is downloaded): a sky whose colour runs
from a pale horizon to blue at the zenith, a dim warm ground, and a small bright sun-like disc.
It renders in ``llvm_ad_rgb`` where LLVM >= 16 is found (whole wavefronts per BSDF call, in
Dr.Jit's evaluated mode, which a Python BSDF needs), else in ``scalar_rgb`` (one ray per call:
much slower).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .llvm import point_drjit_to_llvm

#: Sky colours (linear RGB): horizon, zenith, ground.
HORIZON, ZENITH, GROUND = (0.9, 0.9, 0.85), (0.3, 0.5, 0.9), (0.2, 0.18, 0.15)
#: The sun: direction (polar angle from +y, azimuth; radians), angular radius (radians),
#: radiance (linear, relative to the sky's).
SUN_THETA, SUN_PHI, SUN_RADIUS, SUN_RADIANCE = 0.6, 1.0, 0.06, 40.0


def sky_bitmap(width: int = 128, height: int = 64) -> np.ndarray:
    """The environment map, ``(height, width, 3)`` float32 linear RGB in Mitsuba's
    latitude-longitude layout (rows from the +y pole down, ``y`` up in world space)."""
    theta = (np.arange(height) + 0.5) / height * np.pi
    phi = (np.arange(width) + 0.5) / width * 2 * np.pi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    up = np.clip(np.cos(T), 0.0, 1.0)[..., None]
    sky = (1 - up) * np.array(HORIZON) + up * np.array(ZENITH)
    sky[T > np.pi / 2] = GROUND
    d = np.stack([np.sin(T) * np.cos(P), np.cos(T), np.sin(T) * np.sin(P)], -1)
    sun = np.array([np.sin(SUN_THETA) * np.cos(SUN_PHI), np.cos(SUN_THETA),
                    np.sin(SUN_THETA) * np.sin(SUN_PHI)])
    sky = sky + SUN_RADIANCE * (d @ sun > np.cos(SUN_RADIUS))[..., None]
    return sky.astype(np.float32)


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

