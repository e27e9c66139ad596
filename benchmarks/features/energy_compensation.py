"""Energy-loss compensation (``energy_compensation``): conservation and solver vs Monte Carlo.

Usage: ``python benchmarks/features/energy_compensation.py [PATHS] [BACKEND]`` (default 1e7
warp-cpu).
Prints

1. single rough dielectric interfaces (Beckmann and GGX, alpha 0.1-1, eta 1.1-3), lit from
   either side at 0-85 degrees: the largest |R + T - 1| of the solver with
   "multiple-scattering" (and without compensation, for scale);
2. mirrors: conductors of eta 1 and k 1e6 (Fresnel 1 - 4e-12 on average; built as a Scene
   directly, past the scene file's guard rail k <= 100) and k 100 (F_avg = 0.9996, where the
   multiple-scattering term rightly absorbs a little more): the largest |R - 1|;
3. an 8-interface non-absorbing stack (rough glass/air interfaces, alpha 0.3): R + T;
4. four stacks (the last one that of 3.), solver against PATHS Monte Carlo paths: R and T
   with their standard errors.
"""

from __future__ import annotations

import sys
import time

import numpy as np

import layersim
import layersim.montecarlo as mc
from layersim.scene import Conductor, Scene

ANGLES = np.radians(np.arange(0, 86, 5))


def directions(side: float):
    return np.stack([np.sin(ANGLES), 0 * ANGLES, side * np.cos(ANGLES)], -1)


def conservation(mode: str, dist: str, alpha: float, eta: float) -> float:
    scene = layersim.Scene.from_dict({"stack": {"energy_compensation": mode}, "layer": [
        {"kind": "dielectric", "ior": eta, "roughness": alpha, "distribution": dist}]})
    bsdf = layersim.solve(scene)
    worst = 0.0
    for side in (1.0, -1.0):
        r, t = bsdf.albedo(directions(side))
        worst = max(worst, float(np.abs(r + t - 1.0).max()))
    return worst


def part_dielectric():
    print("1. single rough dielectric interface, max |R + T - 1| over both sides, 0-85 deg")
    print(f"{'dist':9s} {'alpha':>5s} {'eta':>4s} {'multiple-scattering':>20s} {'none':>8s}")
    overall = 0.0
    for dist in ("beckmann", "ggx"):
        for alpha in (0.1, 0.3, 0.6, 1.0):
            for eta in (1.1, 1.5, 2.2, 3.0):
                ms = conservation("multiple-scattering", dist, alpha, eta)
                none = conservation("none", dist, alpha, eta)
                overall = max(overall, ms)
                print(f"{dist:9s} {alpha:5.2f} {eta:4.1f} {ms:20.2e} {none:8.4f}", flush=True)
    print(f"largest |R + T - 1| with multiple-scattering: {overall:.2e}\n")


def mirror(k: float, alpha: float, dist: str, mode: str) -> float:
    layer = Conductor(ior=complex(1.0, k), alpha_u=alpha, alpha_v=alpha, distribution=dist,
                      energy_compensation=mode)
    r, _ = layersim.solve(Scene(stacks=((layer,),))).albedo(directions(1.0))
    return float(np.abs(r - 1).max())


def part_mirror():
    print("2. mirror conductors (eta 1), max |R - 1| at 0-85 deg, multiple-scattering")
    print(f"{'dist':9s} {'alpha':>5s} {'k = 1e6':>9s} {'k = 100':>9s} {'none, 1e6':>10s}")
    for dist in ("beckmann", "ggx"):
        for alpha in (0.1, 0.3, 0.6, 1.0):
            print(f"{dist:9s} {alpha:5.2f} {mirror(1e6, alpha, dist, 'multiple-scattering'):9.2e}"
                  f" {mirror(100.0, alpha, dist, 'multiple-scattering'):9.2e}"
                  f" {mirror(1e6, alpha, dist, 'none'):10.4f}", flush=True)
    print()


def eight_layers(mode: str):
    layers = [{"kind": "dielectric", "ior": 1.5 if j % 2 == 0 else 1.0, "roughness": 0.3}
              for j in range(8)]
    return layersim.Scene.from_dict({"stack": {"energy_compensation": mode}, "layer": layers})


def part_stack():
    print("3. 8 rough interfaces (glass 1.5 / air alternating, Beckmann alpha 0.3), R + T")
    for mode in ("none", "multiple-scattering", "layerlab"):
        t0 = time.perf_counter()
        bsdf = layersim.solve(eight_layers(mode))
        r, t = bsdf.albedo(directions(1.0))
        print(f"{mode:20s} R + T at 0/30/60/85 deg: "
              + " ".join(f"{x:.5f}" for x in (r + t)[[0, 6, 12, 17]])
              + f"; max |R + T - 1| = {np.abs(r + t - 1).max():.2e} "
              f"({time.perf_counter() - t0:.1f} s)", flush=True)
    print()


STACKS = {
    "coated rough gold, multiple-scattering": {
        "stack": {"energy_compensation": "multiple-scattering"}, "layer": [
            {"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
            {"kind": "conductor", "ior": [0.143552, 3.98397], "roughness": 0.3}]},
    "HG slab under a rough coat on a diffuse base, layerlab": {
        "stack": {"energy_compensation": "layerlab"}, "layer": [
            {"kind": "dielectric", "ior": 1.5, "roughness": 0.5},
            {"kind": "medium", "tau": 1.0, "albedo": 0.9, "g": 0.5},
            {"kind": "diffuse", "albedo": 0.5}]},
    "rough glass slab (GGX 0.6 / Beckmann 0.3, eta 2), multiple-scattering": {
        "stack": {"energy_compensation": "multiple-scattering"}, "layer": [
            {"kind": "dielectric", "ior": 2.0, "roughness": 0.6, "distribution": "ggx"},
            {"kind": "medium", "tau": 0.5, "albedo": 0.95, "g": 0.0},
            {"kind": "dielectric", "ior": 1.0, "roughness": 0.3}]},
}


def part_mc(paths: int, backend: str):
    print(f"4. solver vs Monte Carlo ({paths:.0e} paths, {backend}); z = (solver - MC) / stderr")
    scenes = {name: layersim.Scene.from_dict(data) for name, data in STACKS.items()}
    scenes["8 interfaces (part 3), multiple-scattering"] = eight_layers("multiple-scattering")
    for name, scene in scenes.items():
        bsdf = layersim.solve(scene)
        for deg in (0, 40, 70):
            th = np.radians(deg)
            wi = np.array([np.sin(th), 0.0, np.cos(th)])
            t0 = time.perf_counter()
            res = mc.simulate(scene, wi=wi, particles=paths, mu_edges=np.linspace(0, 1, 2),
                              phi_edges=np.linspace(0, 2 * np.pi, 2), backend=backend, seed=deg)
            r, t = (float(x) for x in bsdf.albedo(wi))
            zr = (r - res.reflectance) / res.reflectance_stderr
            zt = (t - res.transmittance) / max(res.transmittance_stderr, 1e-300)
            print(f"{name[:40]:40s} {deg:2d} deg: R {r:.5f} MC {res.reflectance:.5f} "
                  f"+- {res.reflectance_stderr:.1e} (z {zr:+.2f}); T {t:.5f} MC "
                  f"{res.transmittance:.5f} +- {res.transmittance_stderr:.1e} "
                  f"(z {zt:+.2f}) [{time.perf_counter() - t0:.0f} s]", flush=True)


def main():
    paths = int(float(sys.argv[1])) if len(sys.argv) > 1 else 10_000_000
    backend = sys.argv[2] if len(sys.argv) > 2 else "warp-cpu"
    print("machine: shared 2-core CI VM; command: "
          f"python benchmarks/features/energy_compensation.py {paths:.0e} {backend}\n")
    part_mirror()
    part_stack()
    part_dielectric()
    part_mc(paths, backend)


if __name__ == "__main__":
    main()
