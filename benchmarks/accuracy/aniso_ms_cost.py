"""What a larger coupling half-width ``ms`` costs and gains on anisotropic stacks.

For each scene it solves the planner's n and md with the ``ms`` of the 1 % rule (Zeltner & Jakob
2018, eq. (25): ``layersim.aniso.plan.ms_one_percent``, the planner's ``ms`` less its
``MS_MARGIN``), with ``ms + 1``, ``ms + 2`` (the planner's) and ``ms + 4`` (the reference for
the truncation of the coupled modes), and the first once more (the spread of the two gives the
timing noise), and prints the wall
time, the planner's memory estimate (``layersim.plan.make_plan``) and the relative L2 distance of
bin energies from the ``ms + 4`` solve (18 x 36 bins per side, worst of 0, 30, 60, 80 deg;
``layersim.plan.accuracy``).

Scenes: additive_validation (``benchmarks/scenes/``), brushed gold (Beckmann, alpha 0.1 x 0.2),
and Table 2 row 5 of Zeltner & Jakob 2018 (dielectric 0.1 over gold 0.1 x 0.3).

Usage: python benchmarks/accuracy/aniso_ms_cost.py   (output: benchmarks/accuracy/aniso_ms_cost.txt)
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import layersim
from layersim.plan import accuracy
from layersim.aniso import plan as aplan
from layersim.plan import make_plan

GOLD = [0.143552, 3.98397]
SCENES = {
    "additive_validation": Path(__file__).resolve().parents[1] / "scenes"
                           / "additive_validation.toml",
    "brushed_gold": {"layer": [{"kind": "conductor", "ior": GOLD, "roughness": [0.1, 0.2]}]},
    "table2_row5": {"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": [0.1, 0.1]},
                              {"kind": "conductor", "ior": GOLD, "roughness": [0.1, 0.3]}]},
}


def main() -> None:
    # warm up Warp (kernel modules load once per process)
    layersim.solve({"layer": [{"kind": "conductor", "ior": GOLD, "roughness": [0.3, 0.2]}],
                    "discretization": {"n": 16, "md": 4}})
    print("# scene                ms   n    md | seconds | memory estimate MiB | "
          "L2 from ms + 4 (worst angle)")
    for name, source in SCENES.items():
        scene = (layersim.Scene.from_dict(source) if isinstance(source, dict)
                 else layersim.Scene.from_toml(source))
        plan = make_plan(scene)
        rule = plan.ms - aplan.MS_MARGIN
        rows = []
        for ms in (rule, rule + 1, rule + 2, rule + 4, rule):
            sc = replace(scene, discretization=replace(scene.discretization, n=plan.n,
                                                       md=plan.md, ms=ms))
            t0 = time.perf_counter()
            b = layersim.solve(sc)
            rows.append((ms, time.perf_counter() - t0, make_plan(sc).memory_bytes / 2**20,
                         accuracy.bin_table(b)))
        ref = rows[3][3]
        for ms, sec, mib, table in rows:
            err = float(accuracy.relative_errors(table, ref).max())
            print(f"{name:22s} {ms:2d} {plan.n:4d} {plan.md:5d} | {sec:7.1f} | {mib:19.0f} | "
                  f"{err:.1e}", flush=True)


if __name__ == "__main__":
    main()
