"""The Mitsuba 3 plug-in (layersim.mitsuba) in Mitsuba's ``cuda_ad_rgb`` variant, on a GPU host.

The same measurements as ``mitsuba_plugin.py`` with the wavefronts on the GPU: the cost per ray of
``eval``, ``pdf`` and ``sample`` against Mitsuba's ``roughconductor`` (2^16 rays per call), the
accuracy of ``eval`` against ``roughconductor`` / ``roughdielectric``, and the white furnace;
then a material-test render of coated gold (``layersim render``'s scene) in ``cuda_ad_rgb``.
The plug-in evaluates layersim's Fourier series with NumPy on the host, so each call copies the
wavefront to the host and back: that copy is part of the cost measured here.

Usage: python benchmarks/features/mitsuba_cuda.py OUT_PNG   (needs mitsuba and a CUDA GPU)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import mitsuba_plugin as mp  # noqa: E402  (sets up mitsuba, drjit and the helpers)

import layersim  # noqa: E402
import layersim.mitsuba as lsm  # noqa: E402
from layersim.mitsuba.render import scene_dict  # noqa: E402

mi, dr = mp.mi, mp.dr


def main(out_png: str) -> None:
    print(f"mitsuba {mi.__version__}, drjit {dr.__version__}; variant cuda_ad_rgb")
    mp.cost_report("cuda_ad_rgb", mp.wavefront_costs, "one wavefront of 2^16 rays per call, "
                   "median of 5 calls")
    mi.set_variant("cuda_ad_rgb")
    lsm.register()
    mp.accuracy_report()
    mp.furnace_report()
    # layersim render's scene, rendered in cuda_ad_rgb (its integrator needs Dr.Jit's
    # symbolic loops and calls off around the Python plug-in, as layersim render sets them)
    dr.set_flag(dr.JitFlag.SymbolicLoops, False)
    dr.set_flag(dr.JitFlag.SymbolicCalls, False)
    lsim = mp.TMP / "coated_gold_rgb.lsim"
    scene = layersim.Scene.from_toml(Path(__file__).resolve().parents[2]
                                     / "examples/coated_gold_rgb.toml")
    layersim.solve(scene).save(lsim)
    t0 = time.perf_counter()
    image = mi.render(mi.load_dict(scene_dict(mi, str(lsim), (200, 200), 64)), seed=0)
    dr.eval(image)
    seconds = time.perf_counter() - t0
    mi.util.write_bitmap(out_png, image, write_async=False)
    print(f"\nrender: coated gold RGB sphere, 200 x 200, 64 spp, cuda_ad_rgb: {seconds:.1f} s "
          f"(with the first compilation) -> {out_png}")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "sphere_cuda.png")
