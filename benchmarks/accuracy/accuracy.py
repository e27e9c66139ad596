"""Solves to a tolerance and the error estimate (layersim.plan.accuracy) against refined solves.

For each scene of ``benchmarks/scenes/`` (the isotropic ones by default) it solves

* on the planner's default discretisation, with the error estimate (``error_estimate=True``);
* to ``tol`` = 1e-2, 1e-3 and 1e-4 (``tol=``),

and measures each result's error against a reference solve at twice its ``n`` and ``md``
(1.5 times where the limits refuse twice; an anisotropic solve's coupling half-width ``ms``
by the same factor, more than :func:`layersim.plan.accuracy.scaled_ms` refines it): relative L2
of bin energies, 18 x 36 bins per side, worst of 0, 30, 60 and 80 degrees (what the estimate
estimates). It prints the estimate, the
measured error, their ratio (the estimate is meant to lie above the error and within 3 times
it), the discretisation reached, and the wall time against the default solve's.

Usage: python benchmarks/accuracy/accuracy.py [--tol T ...] [SCENE ...]   (names in
benchmarks/scenes/, without .toml; --tol: only these tolerances, default 1e-2 1e-3 1e-4)
       python benchmarks/accuracy/accuracy.py --aniso   (the anisotropic scenes of
:data:`ANISO`, default plan and :data:`TOLS_ANISO`)
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import layersim
from layersim.plan import accuracy
from layersim.errors import InfeasibleError

SCENES = Path(__file__).resolve().parents[1] / "scenes"
DEFAULT = ("vandehulst_slab", "dusty_gold", "coated_gold", "coated_hg_diffuse")
TOLS = (1e-2, 1e-3, 1e-4)
#: Anisotropic (coupled-mode) scenes: the additive validation stack of Zeltner & Jakob 2018,
#: sec. 5.5, and a single brushed gold conductor (Beckmann, alpha 0.1 x 0.2). The
#: stack's references at twice n, md and ms take minutes each on a 2-core machine, so it is
#: measured at the default plan and tol 1e-2 (whose rungs are coarser than the default) only.
ANISO = {
    "additive_validation": SCENES / "additive_validation.toml",
    "brushed_gold": {"stack": {"name": "brushed_gold"},
                     "layer": [{"kind": "conductor", "ior": [0.143552, 3.98397],
                                "roughness": [0.1, 0.2]}]},
}
TOLS_ANISO = {"additive_validation": (1e-2,), "brushed_gold": (1e-2, 1e-3)}


def refined(scene, bsdf, scale: float):
    """``scene`` at ``scale`` times ``bsdf``'s n and md, and for an anisotropic solve at
    ``scale`` times its ms (more than the ladder's rungs refine it: the reference's own
    truncation of the coupled modes is then ~10 times below the solve's)."""
    out = accuracy.scaled(scene, bsdf.info["n"], bsdf.info["md"], scale)
    if not bsdf.info.get("ms"):
        return out
    ms = max(1, round(scale * bsdf.info["ms"]))
    return replace(out, discretization=replace(out.discretization, ms=ms))


def reference(scene, bsdf):
    """A solve at 2 (else 1.5) times ``bsdf``'s n and md (and ms), and the scale used."""
    for scale in (2.0, 1.5):
        try:
            return layersim.solve(refined(scene, bsdf, scale)), scale
        except InfeasibleError:
            continue
    return None, None


def estimate_with(scene, bsdf, ms_of) -> float:
    """The estimate of ``bsdf`` from companions at the scales of ``accuracy.COMPANIONS`` of n
    and md with coupling half-width ``ms_of(scale)`` (None: the planner's)."""
    companions = []
    for r, _ in accuracy.COMPANIONS:
        sc = accuracy.scaled(scene, bsdf.info["n"], bsdf.info["md"], r)
        sc = replace(sc, discretization=replace(sc.discretization, ms=ms_of(r)))
        companions.append(layersim.solve(sc))
    return accuracy.estimate(bsdf, companions)["estimate"]


def measure(name: str, label: str, scene, bsdf, seconds: float, t_default: float) -> None:
    ref, scale = reference(scene, bsdf)
    est = bsdf.error_estimate
    coupling = f" ms={bsdf.info['ms']:2d}" if bsdf.info.get("ms") else ""
    if ref is None:
        print(f"{name:18s} {label:12s} n={bsdf.info['n']:4d} md={bsdf.info['md']:4d}{coupling} "
              f"estimate {est:.2e}  no reference (2x and 1.5x refused)  {seconds:6.2f} s "
              f"({seconds / t_default:.2f} x default)", flush=True)
        return
    err = float(accuracy.relative_errors(accuracy.bin_table(bsdf),
                                         accuracy.bin_table(ref)).max())
    print(f"{name:18s} {label:12s} n={bsdf.info['n']:4d} md={bsdf.info['md']:4d}{coupling} "
          f"estimate {est:.2e}  measured {err:.2e} ({scale:g}x ref)  ratio {est / err:6.2f}  "
          f"{seconds:6.2f} s ({seconds / t_default:.2f} x default)", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--tol", type=float, action="append")
    parser.add_argument("--aniso", action="store_true")
    parser.add_argument("scenes", nargs="*")
    args = parser.parse_args()
    aniso = args.aniso
    scenes = ANISO if aniso else {name: SCENES / f"{name}.toml" for name in args.scenes or DEFAULT}
    print(f"# python benchmarks/accuracy/accuracy.py {' '.join(sys.argv[1:])}   "
          f"({platform.node()}, "
          f"{os.cpu_count()} cores: times are wall times, their ratios side by side)")
    print(f"# estimate: {accuracy.SAFETY} x the largest of the distances to companions at "
          + " and ".join(f"{r:.3g} (weight {w:g})" for r, w in accuracy.COMPANIONS)
          + f" of n and md{' (ms by their square roots)' if aniso else ''}; "
          f"ladder scales {', '.join(f'{s:.3g}' for s in accuracy.LADDER)}")
    for name, source in scenes.items():
        scene = (layersim.Scene.from_dict(source) if isinstance(source, dict)
                 else layersim.Scene.from_toml(source))
        t0 = time.perf_counter()
        layersim.solve(scene)
        t_default = time.perf_counter() - t0
        t0 = time.perf_counter()
        bsdf = layersim.solve(scene, error_estimate=True)
        measure(name, "default+est", scene, bsdf, time.perf_counter() - t0, t_default)
        if aniso:
            ms = bsdf.info["ms"]
            print(f"{name:18s} {'':12s} the same estimate with companions on the same ms: "
                  f"{estimate_with(scene, bsdf, lambda r: None):.2e}; at ms x scale: "
                  f"{estimate_with(scene, bsdf, lambda r: max(1, round(ms * r))):.2e}",
                  flush=True)
        for tol in args.tol or (TOLS_ANISO[name] if aniso else TOLS):
            t0 = time.perf_counter()
            try:
                bsdf = layersim.solve(scene, tol=tol)
            except InfeasibleError as exc:
                print(f"{name:18s} tol {tol:<8g} not reached: {exc}", flush=True)
                continue
            measure(name, f"tol {tol:g}", scene, bsdf, time.perf_counter() - t0, t_default)


if __name__ == "__main__":
    main()
