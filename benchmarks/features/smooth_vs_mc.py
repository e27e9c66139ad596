"""Smooth (roughness 0) interfaces: the solver against the Monte Carlo reference.

Three stacks of issue 18: a smooth coating over rough gold, a smooth coating over an HG medium
over a diffuse base, and a scattering slab between two smooth interfaces (transmissive). For
each incident direction it prints the solver's and Monte Carlo's albedos with the difference in
Monte Carlo standard errors, and the fraction of populated bins (8 x 12 per side) within 3 and 4
sigma (sigma: Monte Carlo standard error with the Poisson floor E / N of a bin receiving energy
E per path). The specular (delta) parts sit in the bins of their directions on both sides.

Usage: python benchmarks/features/smooth_vs_mc.py [paths] [backend]   (default 1e7, auto)
"""

from __future__ import annotations

import platform
import sys
import time

import numpy as np

import layersim
import layersim.montecarlo as mc

MU_EDGES = np.linspace(0.0, 1.0, 9)
PHI_EDGES = np.linspace(0.0, 2 * np.pi, 13)
GOLD = [0.143552, 3.98397]

SCENES = {
    "smooth coating over rough gold": {"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0},
        {"kind": "conductor", "ior": GOLD, "roughness": 0.2}]},
    "smooth coating over HG medium over diffuse": {"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0},
        {"kind": "medium", "albedo": 0.9, "g": 0.5, "tau": 1.0},
        {"kind": "diffuse", "albedo": 0.6}]},
    "HG slab between two smooth interfaces": {"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0},
        {"kind": "medium", "albedo": 0.95, "g": 0.3, "tau": 1.0},
        {"kind": "dielectric", "ior": 1.0, "roughness": 0}]},
}
INCIDENCE = (0.0, 30.0, 55.0, 80.0)     # mirror directions off the bin edges


def unit(theta_deg: float, phi_deg: float = 20.0) -> np.ndarray:
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def compare(name: str, d: dict, theta: float, paths: int, backend: str, seed: int) -> dict:
    scene = layersim.Scene.from_dict(d)
    t0 = time.perf_counter()
    bsdf = layersim.solve(scene)
    t_solve = time.perf_counter() - t0
    wi = unit(theta)
    res = mc.simulate(scene, wi, paths, mu_edges=MU_EDGES, phi_edges=PHI_EDGES,
                      backend=backend, seed=seed)
    R, T = (float(x) for x in bsdf.albedo(wi))
    bins = bsdf.bin_energies(wi, MU_EDGES, PHI_EDGES)
    # with the Poisson floor of nearly empty bins (MCResult.z_scores)
    z = np.concatenate([res.z_scores(side, bins[side]) for side in ("top", "bottom")])
    out = {"R": R, "T": T, "mcR": res.reflectance, "mcT": res.transmittance,
           "zR": (R - res.reflectance) / max(res.reflectance_stderr, 1e-15),
           "zT": (T - res.transmittance) / max(res.transmittance_stderr, 1e-15),
           "bins": z.size, "in3": float(np.mean(z <= 3.0)), "in4": float(np.mean(z <= 4.0)),
           "zmax": float(z.max()), "n": bsdf.grid.n, "md": bsdf.operators[0].m,
           "solve_s": t_solve}
    print(f"{name:45s} {theta:4.0f} seed {seed}  n={out['n']:4d} md={out['md']:3d} solve {t_solve:5.2f} s  "
          f"R {R:.6f} mc {res.reflectance:.6f} ({out['zR']:+5.2f} se)  "
          f"T {T:.6f} mc {res.transmittance:.6f} ({out['zT']:+5.2f} se)  "
          f"bins {out['bins']:3d}: {100 * out['in3']:5.1f} % <= 3 sigma, "
          f"{100 * out['in4']:5.1f} % <= 4, max {out['zmax']:.2f}", flush=True)
    return out


def main() -> None:
    paths = int(float(sys.argv[1])) if len(sys.argv) > 1 else 10_000_000
    backend = sys.argv[2] if len(sys.argv) > 2 else "auto"
    print(f"# {paths:.3g} paths per direction, backend {backend}, {platform.node()} "
          f"({platform.processor() or platform.machine()})")
    # one seed per run: runs with one seed share their random numbers, path by path, so that
    # their Monte Carlo errors would be correlated across directions and scenes
    seed = 1000
    for name, d in SCENES.items():
        for theta in INCIDENCE:
            compare(name, d, theta, paths, backend, seed)
            seed += 1


if __name__ == "__main__":
    main()
