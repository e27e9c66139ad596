"""Solves to a tolerance and the error estimate (layersim.accuracy) against refined solves.

For each scene of ``benchmarks/scenes/`` (the isotropic ones by default) it solves

* on the planner's default discretisation, with the error estimate (``error_estimate=True``);
* to ``tol`` = 1e-2, 1e-3 and 1e-4 (``tol=``),

and measures each result's error against a reference solve at twice its ``n`` and ``md``
(1.5 times where the limits refuse twice): relative L2 of bin energies, 18 x 36 bins per side,
worst of 0, 30, 60 and 80 degrees (what the estimate estimates). It prints the estimate, the
measured error, their ratio (the estimate is meant to lie above the error and within 3 times
it), the discretisation reached, and the wall time against the default solve's.

Usage: python benchmarks/accuracy.py [--tol T ...] [SCENE ...]   (names in benchmarks/scenes/,
without .toml; --tol: only these tolerances, default 1e-2 1e-3 1e-4)
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import layersim
from layersim import accuracy
from layersim.errors import InfeasibleError

SCENES = Path(__file__).parent / "scenes"
DEFAULT = ("vandehulst_slab", "dusty_gold", "coated_gold", "coated_hg_diffuse")
TOLS = (1e-2, 1e-3, 1e-4)


def reference(scene, bsdf):
    """A solve at 2 (else 1.5) times ``bsdf``'s n and md, and the scale used."""
    for scale in (2.0, 1.5):
        try:
            return layersim.solve(accuracy.scaled(scene, bsdf.info["n"], bsdf.info["md"],
                                                  scale)), scale
        except InfeasibleError:
            continue
    return None, None


def measure(name: str, label: str, scene, bsdf, seconds: float, t_default: float) -> None:
    ref, scale = reference(scene, bsdf)
    est = bsdf.error_estimate
    if ref is None:
        print(f"{name:18s} {label:12s} n={bsdf.info['n']:4d} md={bsdf.info['md']:4d} "
              f"estimate {est:.2e}  no reference (2x and 1.5x refused)  {seconds:6.2f} s "
              f"({seconds / t_default:.2f} x default)", flush=True)
        return
    err = float(accuracy.relative_errors(accuracy.bin_table(bsdf),
                                         accuracy.bin_table(ref)).max())
    print(f"{name:18s} {label:12s} n={bsdf.info['n']:4d} md={bsdf.info['md']:4d} "
          f"estimate {est:.2e}  measured {err:.2e} ({scale:g}x ref)  ratio {est / err:6.2f}  "
          f"{seconds:6.2f} s ({seconds / t_default:.2f} x default)", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--tol", type=float, action="append")
    parser.add_argument("scenes", nargs="*")
    args = parser.parse_args()
    names = args.scenes or DEFAULT
    tols = args.tol or TOLS
    print(f"# python benchmarks/accuracy.py {' '.join(sys.argv[1:])}   ({platform.node()}, "
          f"{os.cpu_count()} cores: times are wall times, their ratios side by side)")
    print(f"# estimate: {accuracy.SAFETY} x the largest of the distances to companions at "
          + " and ".join(f"{r:.3g} (weight {w:g})" for r, w in accuracy.COMPANIONS)
          + " of n and md; "
          f"ladder scales {', '.join(f'{s:.3g}' for s in accuracy.LADDER)}")
    for name in names:
        scene = layersim.Scene.from_toml(SCENES / f"{name}.toml")
        t0 = time.perf_counter()
        layersim.solve(scene)
        t_default = time.perf_counter() - t0
        t0 = time.perf_counter()
        bsdf = layersim.solve(scene, error_estimate=True)
        measure(name, "default+est", scene, bsdf, time.perf_counter() - t0, t_default)
        for tol in tols:
            t0 = time.perf_counter()
            try:
                bsdf = layersim.solve(scene, tol=tol)
            except InfeasibleError as exc:
                print(f"{name:18s} tol {tol:<8g} not reached: {exc}", flush=True)
                continue
            measure(name, f"tol {tol:g}", scene, bsdf, time.perf_counter() - t0, t_default)


if __name__ == "__main__":
    main()
