"""Peak resident memory of isotropic solves against the plan's memory estimate.

Each row runs in a fresh process (``resource.getrusage`` peak RSS is per process): Warp is
initialised, the baseline RSS read, the scene solved, and the peak above the baseline printed
beside the plan's estimate (``Plan.memory_bytes``), which is meant to lie above it. Rows:
coated gold (dielectric eta 1.5 over gold, ``benchmarks/solve_coated.py``) at the planner's
discretisation and scaled up as solves to a tolerance climb (:mod:`layersim.accuracy`).

Usage: python benchmarks/memory_iso.py
"""

from __future__ import annotations

import platform
import resource
import subprocess
import sys
from pathlib import Path

ROWS = [(0.1, 0.1, 1.0), (0.1, 0.1, 2.0), (0.05, 0.05, 1.0), (0.05, 0.05, 1.41),
        (0.1, 0.05, 2.0)]


def one(top: float, bottom: float, scale: float) -> None:
    sys.path.insert(0, str(Path(__file__).parent))
    import warp as wp
    from solve_coated import scene

    import layersim
    from layersim import accuracy
    from layersim.plan import make_plan
    wp.init()
    s = scene(top, bottom)
    plan = make_plan(s, refuse=False)
    s = accuracy.scaled(s, plan.n, plan.md, scale)
    plan = make_plan(s, refuse=False)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    layersim.solve(s)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 - base
    print(f"coated gold {top}/{bottom} x{scale:<5g} n={plan.n:5d} md={plan.md:5d}  estimate "
          f"{plan.memory_bytes / 2**20:7.0f} MiB  measured peak {peak / 2**20:7.0f} MiB  "
          f"ratio {plan.memory_bytes / peak:5.2f}", flush=True)


def main() -> None:
    if len(sys.argv) == 4:
        one(*map(float, sys.argv[1:]))
        return
    print(f"# python benchmarks/memory_iso.py   (shared 2-core CI VM, {platform.machine()}; "
          "peak RSS above a baseline with Warp initialised)", flush=True)
    for row in ROWS:
        subprocess.run([sys.executable, __file__, *map(str, row)], check=True)


if __name__ == "__main__":
    main()
