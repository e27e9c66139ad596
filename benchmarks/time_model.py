"""Calibration of the plan's time model (``layersim.plan.budget``): measured seconds per work unit.

Solves a few isotropic scenes (media alone and between interfaces, coated gold, a narrow
interface, a medium on a large grid) and prints, per part of the model (projection, media,
adding), the work units of the plan (:func:`layersim.plan.budget.work_units`), the measured
seconds and their ratio, then the largest ratio of each part among the parts that took at
least 0.5 s (below that, fixed overheads dominate and a refusal at minutes is not at stake),
from which the constants ``SECONDS_PER_COEFFICIENT``, ``SECONDS_PER_MEDIUM_UNIT`` and
``SECONDS_PER_ADDING_UNIT`` are set (rounded up), and the estimate against the measured total.
The media's seconds are those of their operators built again here
(:func:`layersim.ingredients.medium_operator` on the plan's grid); projection is the rest of
the solve's layer time (the whole interface operator: projection, assembly, energy check);
adding is the solve's adding time.

Run: ``python benchmarks/time_model.py``; output in ``benchmarks/time_model.txt``.
"""

from __future__ import annotations

import os
import platform
import time

from threadpoolctl import threadpool_limits

import layersim
from layersim.config import settings
from layersim.ingredients import medium_operator
from layersim.outofcore.memory import cap_arenas

MED = lambda g, tau=5.0, albedo=0.95: {"kind": "medium", "tau": tau, "albedo": albedo, "g": g}
DIEL = lambda eta, a: {"kind": "dielectric", "ior": eta, "roughness": a}
GOLD = {"kind": "conductor", "ior": [0.143552, 3.98397], "roughness": 0.1}

SCENES = {
    "medium g0.99 alone": ([MED(0.99)], {}),
    "medium g0.99 between alpha 0.1": ([DIEL(1.5, 0.1), MED(0.99, albedo=1.0), DIEL(1.0, 0.1)],
                                       {}),
    "medium g0.5 alone, n 400": ([MED(0.5)], {"n": 400}),
    "medium g0.9 over diffuse, n 256": ([MED(0.9), {"kind": "diffuse", "albedo": 0.5}],
                                        {"n": 256}),
    "coated gold (alpha 0.1 over 0.1)": ([DIEL(1.5, 0.1), GOLD], {}),
    "dielectric alpha 0.05": ([DIEL(1.5, 0.05)], {}),
    "dielectric alpha 0.3 over medium, n 600": ([DIEL(1.5, 0.3), MED(0.7, tau=2.0)],
                                                {"n": 600}),
}


def main() -> None:
    cap_arenas(settings().malloc_arenas)     # this script owns its process
    print("# time_model.py: seconds per work unit of layersim.plan.budget")
    print(f"# machine: {platform.node()} {platform.machine()}, {os.cpu_count()} cores\n")
    parts = ("projection", "media", "adding")
    print(f"{'scene':42s} {'n':>4s} {'md':>4s} " + " ".join(
        f"{p[:5] + ' units':>12s} {p[:5] + ' s':>8s} {'s/unit':>8s}" for p in parts)
        + f" {'est s':>7s} {'total s':>7s}")
    worst = dict.fromkeys(parts, 0.0)
    layersim.solve(layersim.Scene.from_dict({"layer": [DIEL(1.5, 0.3)]}))   # Warp kernels built
    for name, (layers, disc) in SCENES.items():
        data = {"layer": layers}
        if disc:
            data["discretization"] = disc
        scene = layersim.Scene.from_dict(data)
        plan = layersim.make_plan(scene)
        t0 = time.perf_counter()
        bsdf = layersim.solve(scene)
        total = time.perf_counter() - t0
        s = bsdf.info["seconds"]
        t_media = 0.0
        for lp in plan.layers:
            if lp.action == "adding-doubling":
                m = scene.layers[lp.index]
                t1 = time.perf_counter()
                with threadpool_limits(1, user_api="blas"):      # as in layersim.solve
                    medium_operator(plan.grid, plan.md, m.albedo, m.g, m.tau, 1.0)
                t_media += time.perf_counter() - t1
        measured = {"projection": max(0.0, s["layers"] - t_media), "media": t_media,
                    "adding": s["adding"]}
        row = f"{name:42s} {plan.n:4d} {plan.md:4d} "
        for p in parts:
            units = plan.work[p]
            ratio = measured[p] / units if units else 0.0
            if measured[p] >= 0.5:
                worst[p] = max(worst[p], ratio)
            row += f" {units:12.3e} {measured[p]:8.2f} {ratio:8.2e}"
        print(row + f" {plan.seconds['total']:7.1f} {total:7.1f}", flush=True)
    print("\nlargest seconds per unit (parts >= 0.5 s): "
          + ", ".join(f"{p} {worst[p]:.2e}" for p in parts))


if __name__ == "__main__":
    main()
