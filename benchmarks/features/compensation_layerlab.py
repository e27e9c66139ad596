"""Albedos of layerlab's validation stacks with and without energy compensation.

Usage: ``python benchmarks/features/compensation_layerlab.py``. Coated gold (coating eta 1.5 over
gold, red channel of layerlab's tutorial sec. 6.4) at the roughness pairs 0.1/0.1, 0.1/0.3, 0.3/0.3,
and the Henyey-Greenstein slab under a rough coating on a diffuse base
(``benchmarks/scenes/coated_hg_diffuse.toml``): reflectance at 0, 30, 60 and 80 degrees with
``energy_compensation`` "none", "layerlab" and "multiple-scattering". These are the numbers to
hold against layerlab's ``conserveEnergy=True`` results (not available in this repository).
"""

from __future__ import annotations

import time

import numpy as np

import layersim

GOLD = [0.143552, 3.98397]
ANGLES = np.radians([0, 30, 60, 80])


def coated_gold(top: float, bottom: float, mode: str) -> dict:
    return {"stack": {"energy_compensation": mode}, "layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": top},
        {"kind": "conductor", "ior": GOLD, "roughness": bottom}]}


def coated_hg(mode: str) -> dict:
    return {"stack": {"energy_compensation": mode}, "layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.1},
        {"kind": "medium", "albedo": 0.95, "g": 0.5, "tau": 2.0},
        {"kind": "diffuse", "albedo": 0.5}]}


def main():
    print("machine: shared 2-core CI VM; command: "
          "python benchmarks/features/compensation_layerlab.py")
    print("reflectance at 0 / 30 / 60 / 80 deg")
    cases = [(f"coated gold {t:g}/{b:g}", lambda m, t=t, b=b: coated_gold(t, b, m))
             for t, b in ((0.1, 0.1), (0.1, 0.3), (0.3, 0.3))]
    cases.append(("HG slab under a coat on a diffuse base", coated_hg))
    for name, make in cases:
        for mode in ("none", "layerlab", "multiple-scattering"):
            t0 = time.perf_counter()
            bsdf = layersim.solve(layersim.Scene.from_dict(make(mode)))
            wi = np.stack([np.sin(ANGLES), 0 * ANGLES, np.cos(ANGLES)], -1)
            r, _ = bsdf.albedo(wi)
            print(f"{name:40s} {mode:20s} " + " ".join(f"{x:.5f}" for x in r)
                  + f"  ({time.perf_counter() - t0:.1f} s)", flush=True)


if __name__ == "__main__":
    main()
