"""Strongly forward-scattering media: the delta-M scaled solver (Wiscombe 1977) vs Monte Carlo.

Part 1 solves HG media with g = 0.95 and 0.99 (tau 5, albedo 0.95 and 1), alone and between two
rough dielectric interfaces (Beckmann alpha 0.1, eta 1.5 above, 1 below), with the planner's
discretisation (solve seconds after a warm-up solve that builds the Warp kernels), and
compares the albedos R and T at 0, 30 and 60 degrees with ``layersim.montecarlo.simulate`` on
the same scene (``--particles`` paths per angle; the standard errors are printed).

Part 2 is the measurement behind ``layersim.ingredients.medium.G_EXACT_MAX``: the medium alone
(tau 5, albedo 0.95) solved with the whole Legendre series ("exact") and delta-M scaled to the
grid's moments, at n = 64 and 196, with the time of the medium operator and the albedo at
normal incidence (``R0``, ``T0``) and at the ordinate nearest 60 degrees (``R60``).

Part 3 is the measurement behind ``layersim.plan.layers.DELTA_M_MOMENTS``: g = 0.99 alone,
delta-M scaled with N = n - 1 moments for n = 16 ... 196.

Run: ``python benchmarks/features/forward_media.py [--particles 4000000]``; output in
``benchmarks/features/forward_media.txt``.
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

import layersim
import layersim.ingredients.medium as medium
import layersim.montecarlo as mc
from layersim.operators.operator import Grid
from layersim.config import settings
from layersim.outofcore.memory import cap_arenas


def scene(g: float, albedo: float, between: bool) -> layersim.Scene:
    layers = [{"kind": "medium", "tau": 5.0, "albedo": albedo, "g": g}]
    if between:
        layers = ([{"kind": "dielectric", "ior": 1.5, "roughness": 0.1}] + layers
                  + [{"kind": "dielectric", "ior": 1.0, "roughness": 0.1}])
    name = f"g{g}_albedo{albedo}_{'between' if between else 'alone'}"
    return layersim.Scene.from_dict({"stack": {"name": name}, "layer": layers})


def part1(particles: int) -> float:
    print(f"## 1. solver vs Monte Carlo ({particles:.0e} paths per angle, warp-cpu)")
    print(f"{'case':34s} {'n':>4s} {'md':>4s} {'solve s':>8s} {'deg':>4s} {'R':>8s} "
          f"{'R_mc':>8s} {'+-':>7s} {'T':>8s} {'T_mc':>8s} {'+-':>7s} {'|dR|':>7s} {'|dT|':>7s}")
    worst = 0.0
    # Warp builds or loads the projection kernels on first use: not part of a solve's time
    layersim.solve(layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.3}]}))
    for between in (False, True):
        for g in (0.95, 0.99):
            for albedo in (0.95, 1.0):
                sc = scene(g, albedo, between)
                t0 = time.perf_counter()
                bsdf = layersim.solve(sc)
                dt = time.perf_counter() - t0
                for deg in (0.0, 30.0, 60.0):
                    th = np.radians(deg)
                    wi = np.array([np.sin(th), 0.0, np.cos(th)])
                    R, T = (float(np.ravel(x)[0]) for x in bsdf.albedo(wi))
                    res = mc.simulate(sc, wi=wi, particles=particles, backend="warp-cpu", seed=1)
                    Rm = float(np.ravel(res.reflectance)[0])
                    Tm = float(np.ravel(res.transmittance)[0])
                    sR = float(np.ravel(res.reflectance_stderr)[0])
                    sT = float(np.ravel(res.transmittance_stderr)[0])
                    worst = max(worst, abs(R - Rm), abs(T - Tm))
                    print(f"{sc.name:34s} {bsdf.info['n']:4d} {bsdf.info['md']:4d} {dt:8.2f} "
                          f"{deg:4.0f} {R:8.5f} {Rm:8.5f} {sR:7.1e} {T:8.5f} {Tm:8.5f} {sT:7.1e} "
                          f"{abs(R - Rm):7.1e} {abs(T - Tm):7.1e}", flush=True)
    print(f"largest |solver - Monte Carlo| albedo difference: {worst:.2e}\n")
    return worst


def _medium_albedo(grid: Grid, g: float, exact: bool):
    keep = medium.G_EXACT_MAX
    medium.G_EXACT_MAX = 1.0 if exact else 0.0
    try:
        sc = medium.hg_scaling(grid, g, 0.95, 5.0)
        t0 = time.perf_counter()
        alb = medium.medium_operator(grid, sc.moments, 0.95, g, 5.0, 1.0).albedo_nodes()
        dt = time.perf_counter() - t0
    finally:
        medium.G_EXACT_MAX = keep
    j60 = int(np.argmin(np.abs(grid.mu - 0.5)))
    return sc, dt, alb["Rt"][-1], alb["Ttb"][-1], alb["Rt"][j60]


def part2() -> None:
    print("## 2. whole series ('exact') vs delta-M, medium alone (tau 5, albedo 0.95)")
    print(f"{'n':>4s} {'g':>5s} {'method':7s} {'N':>5s} {'f':>8s} {'seconds':>8s} {'R0':>8s} "
          f"{'T0':>8s} {'R60':>8s}")
    for n in (64, 196):
        grid = Grid.make("gauss-lobatto", n)
        for g in (0.8, 0.9, 0.95, 0.97):
            for exact in (True, False):
                sc, dt, R0, T0, R60 = _medium_albedo(grid, g, exact)
                print(f"{n:4d} {g:5.2f} {'exact' if exact else 'delta-M':7s} {sc.moments:5d} "
                      f"{sc.f:8.1e} {dt:8.2f} {R0:8.5f} {T0:8.5f} {R60:8.5f}", flush=True)
    print()


def part3() -> None:
    print("## 3. delta-M moments N = n - 1, g = 0.99 alone (tau 5, albedo 0.95)")
    print(f"{'n':>4s} {'N':>4s} {'f':>7s} {'seconds':>8s} {'R0':>9s} {'T0':>9s} {'R60':>9s}")
    for n in (16, 32, 64, 128, 196):
        sc, dt, R0, T0, R60 = _medium_albedo(Grid.make("gauss-lobatto", n), 0.99, False)
        print(f"{n:4d} {sc.moments:4d} {sc.f:7.4f} {dt:8.2f} {R0:9.6f} {T0:9.6f} {R60:9.6f}")
    print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=float, default=4e6)
    args = ap.parse_args()
    cap_arenas(settings().malloc_arenas)     # this script owns its process
    print(f"# forward_media.py --particles {args.particles:.0e}")
    print(f"# machine: {platform.node()} {platform.processor() or platform.machine()}, "
          f"{__import__('os').cpu_count()} cores\n")
    part1(int(args.particles))
    part2()
    part3()


if __name__ == "__main__":
    main()
