"""The CUDA walk's launch settings, measured (not a test): paths/s of the warp-cuda walk for
each register cap (``montecarlo.backends.CUDA_MAX_REGISTERS``) and particles per thread
(``GPU_PARTICLES_PER_THREAD``), on the scenes of ``benchmarks/montecarlo/walk_vs_base.py`` at
10 x 12 and 18 x 36 bins, 30 degrees. Best of 3 runs of 2^28 paths after a warm-up; ``same`` says
whether the bins equal those of the first setting (the settings change scheduling, never the
arithmetic).

Usage (on a machine with a CUDA GPU)::

    python benchmarks/montecarlo/walk_tuning.py > benchmarks/montecarlo/walk_tuning_h100.txt
"""

from __future__ import annotations

import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

import layersim
import layersim.montecarlo as mc
from layersim.montecarlo import backends

sys.path.insert(0, str(Path(__file__).resolve().parent))
from walk_vs_base import SCENES  # noqa: E402

SETTINGS = [(cap, pt) for cap in (None, 72, 64, 56, 48) for pt in (4, 8)]
PATHS, BATCH = 1 << 28, 1 << 26


def main() -> None:
    wi = np.array([math.sin(math.radians(30)), 0.0, math.cos(math.radians(30))])
    print("# walk_tuning.py: warp-cuda walk paths/s per register cap and particles per thread")
    print(f"# command: python benchmarks/montecarlo/walk_tuning.py; "
          f"date {time.strftime('%Y-%m-%d %H:%M')}; Python {platform.python_version()}")
    print(f"# in use: cap {backends.CUDA_MAX_REGISTERS}, "
          f"{backends.GPU_PARTICLES_PER_THREAD} particles per thread")
    chosen = (backends.CUDA_MAX_REGISTERS, backends.GPU_PARTICLES_PER_THREAD)
    for n_mu, n_phi in ((10, 12), (18, 36)):
        mu, phi = np.linspace(0, 1, n_mu + 1), np.linspace(0, 2 * np.pi, n_phi + 1)
        for name, data in SCENES.items():
            scene = layersim.Scene.from_dict(data)
            ref = None
            for cap, pt in SETTINGS:
                backends.CUDA_MAX_REGISTERS, backends.GPU_PARTICLES_PER_THREAD = cap, pt
                mc.simulate(scene, wi, 1 << 20, mu, phi, backend="warp-cuda", batch_size=BATCH)
                best, res = 0.0, None
                for _ in range(3):
                    res = mc.simulate(scene, wi, PATHS, mu, phi, backend="warp-cuda",
                                      batch_size=BATCH, seed=3)
                    best = max(best, float(np.sum(res.particles)) / res.seconds)
                bins = np.asarray(res.bins["top"])
                same = ref is None or np.array_equal(bins, ref)
                ref = bins if ref is None else ref
                per_path = float(np.sum(res.events)) / float(np.sum(res.particles))
                mark = "  <- in use" if (cap, pt) == chosen else ""
                print(f"{n_mu}x{n_phi:<3} {name:14} cap {str(cap):4} per_thread {pt}  "
                      f"{best:.3e} paths/s  {best * per_path:.3e} events/s  same={same}{mark}  "
                      f"{res.device}", flush=True)
    backends.CUDA_MAX_REGISTERS, backends.GPU_PARTICLES_PER_THREAD = chosen


if __name__ == "__main__":
    main()
