"""Table 2 row 6 of Zeltner & Jakob 2018 (benchmarks/speed/table2.py): what the reduced
discretisation that table2.py uses (n = 224, md = 300) changes against the planner's (n = 390,
md = 426).

Solves both (the second is the long one, several minutes and about 1 GiB above the baseline on a
2-core machine), then compares ``BSDF.eval`` at 20000 random pairs of directions within 80 degrees
of the normal, relative to the planner's value where it exceeds 1 % of the peak, and the
directional albedo at 12 incident directions.

Usage::

    python benchmarks/speed/table2_row6_accuracy.py
    # output: benchmarks/speed/table2_row6_accuracy.txt
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np

import layersim

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tests"))
from conftest import random_directions  # noqa: E402  (the tests' direction sampler)

LAYERS = [{"kind": "dielectric", "ior": 1.5, "roughness": [0.15, 0.05]},
          {"kind": "conductor", "ior": [0.143552, 3.98397], "roughness": [0.05, 0.15]}]
PLANS = (("reduced", {"n": 224, "md": 300}), ("default", None))


def main() -> None:
    out = {}
    for tag, disc in PLANS:
        scene = {"layer": LAYERS}
        if disc:
            scene["discretization"] = disc
        t = time.perf_counter()
        out[tag] = layersim.solve(layersim.Scene.from_dict(scene))
        print(tag, out[tag].info["n"], out[tag].info["md"],
              f"{time.perf_counter() - t:.1f} s", flush=True)
    rng = np.random.default_rng(1)
    wi, wo = random_directions(rng, 20000), random_directions(rng, 20000)
    up = (wi[:, 2] > np.cos(np.radians(80))) & (wo[:, 2] > np.cos(np.radians(80)))
    wi, wo = wi[up], wo[up]
    fr, fd = out["reduced"].eval(wi, wo), out["default"].eval(wi, wo)
    peak = np.abs(fd).max()
    lobe = np.abs(fd) > 0.01 * peak
    rel = np.abs(fr - fd)[lobe] / np.abs(fd)[lobe]
    print("pairs", up.sum(), "in lobe", lobe.sum(), "peak", peak)
    print("relative diff in lobe: median %.3g p90 %.3g p99 %.3g max %.3g"
          % tuple(np.quantile(rel, [0.5, 0.9, 0.99, 1.0])))
    print("abs diff / peak: max %.3g" % (np.abs(fr - fd).max() / peak))
    th, ph = np.radians([0, 30, 60, 75]), np.radians([0, 45, 90])
    w = np.array([[np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)]
                  for t in th for p in ph])
    Rr, _ = out["reduced"].albedo(w)
    Rd, _ = out["default"].albedo(w)
    print("albedo reduced", np.round(Rr, 5))
    print("albedo default", np.round(Rd, 5))
    print("albedo max abs diff %.3g" % np.abs(Rr - Rd).max())


if __name__ == "__main__":
    main()
