"""Bin tables of scenes solved on a ladder of discretisations: the data the error estimate of
:mod:`layersim.plan.accuracy` is designed and checked on
(``benchmarks/accuracy/estimator_study.py``).

Each scene is solved at the scales :data:`layersim.plan.accuracy.LADDER` of the planner's ``n`` and
``md`` (0.354 ... 2.83; rungs the limits refuse are skipped), and the bin table of each solve
(:func:`layersim.plan.accuracy.bin_table`: 18 x 36 bins per side at 0, 30, 60, 80 degrees) is
written, with the rung's ``n``, ``md`` and wall time, to
``benchmarks/accuracy/convergence/SCENE.npz`` (float32, compressed; a scene whose file exists is
skipped, so the run can be resumed).

Scenes: the isotropic ones of ``benchmarks/scenes/`` and single layers / coated conductors of a
wider range of roughness (:data:`EXTRA`), so that the estimate is judged on more than the
scenes it is reported on.

Usage: python benchmarks/accuracy/convergence_tables.py [NAME ...]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

import layersim
from layersim.plan import accuracy
from layersim.errors import InfeasibleError
from layersim.plan import make_plan

SCENES = Path(__file__).resolve().parents[1] / "scenes"
OUT = Path(__file__).parent / "convergence"
GOLD = [0.143552, 3.98397]

#: Scenes of benchmarks/scenes/ used (isotropic: anisotropic references take too long here).
FILES = ("vandehulst_slab", "coated_gold", "coated_hg_diffuse", "dusty_gold", "ggx_coated_gold")


def _coated(top, bottom):
    return {"stack": {"name": f"coated_gold_{top}_{bottom}"}, "layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": top},
        {"kind": "conductor", "ior": GOLD, "roughness": bottom}]}


#: Further scenes, as dicts: single rough interfaces and coated gold at other roughnesses.
EXTRA = {
    "dielectric_0.1": {"stack": {"name": "dielectric_0.1"}, "layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.1}]},
    "dielectric_0.3": {"stack": {"name": "dielectric_0.3"}, "layer": [
        {"kind": "dielectric", "ior": 1.33, "roughness": 0.3}]},
    "gold_0.1": {"stack": {"name": "gold_0.1"}, "layer": [
        {"kind": "conductor", "ior": GOLD, "roughness": 0.1}]},
    "gold_0.25": {"stack": {"name": "gold_0.25"}, "layer": [
        {"kind": "conductor", "ior": GOLD, "roughness": 0.25}]},
    "glass_0.3_on_white": {"stack": {"name": "glass_0.3_on_white"}, "layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
        {"kind": "diffuse", "albedo": 0.5}]},
    "glass_0.15_on_white": {"stack": {"name": "glass_0.15_on_white"}, "layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.15},
        {"kind": "diffuse", "albedo": 0.8}]},
    "dielectric_0.5": {"stack": {"name": "dielectric_0.5"}, "layer": [
        {"kind": "dielectric", "ior": 2.0, "roughness": 0.5}]},
    "gold_0.05": {"stack": {"name": "gold_0.05"}, "layer": [
        {"kind": "conductor", "ior": GOLD, "roughness": 0.05}]},
    "forward_slab": {"stack": {"name": "forward_slab"}, "layer": [
        {"kind": "medium", "albedo": 0.95, "tau": 2.0, "g": 0.8},
        {"kind": "diffuse", "albedo": 0.3}]},
    "coated_gold_0.1_0.05": _coated(0.1, 0.05),
    "coated_gold_0.2_0.1": _coated(0.2, 0.1),
    "coated_gold_0.1_0.3": _coated(0.1, 0.3),
    "coated_gold_0.3_0.3": _coated(0.3, 0.3),
}


def load(name: str) -> layersim.Scene:
    if name in EXTRA:
        return layersim.Scene.from_dict(EXTRA[name])
    return layersim.Scene.from_toml(SCENES / f"{name}.toml")


def run(name: str) -> None:
    path = OUT / f"{name}.npz"
    if path.exists():
        print(f"{name}: {path} exists, skipped", flush=True)
        return
    scene = load(name)
    plan = make_plan(scene, refuse=False)
    layersim.solve(accuracy.scaled(scene, plan.n, plan.md, 0.5 ** 0.5))  # warm-up (kernels)
    scales, ns, mds, seconds, tables = [], [], [], [], []
    for scale in accuracy.LADDER:
        rung = accuracy.scaled(scene, plan.n, plan.md, scale)
        t0 = time.perf_counter()
        try:
            bsdf = layersim.solve(rung)
        except InfeasibleError as exc:
            print(f"{name}: scale {scale:.3g} refused: {exc}", flush=True)
            continue
        dt = time.perf_counter() - t0
        scales.append(scale)
        ns.append(bsdf.info["n"])
        mds.append(bsdf.info["md"])
        seconds.append(dt)
        tables.append(accuracy.bin_table(bsdf).astype(np.float32))
        print(f"{name}: scale {scale:.3g} n={ns[-1]} md={mds[-1]} {dt:.1f} s", flush=True)
    OUT.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, scales=np.array(scales), n=np.array(ns), md=np.array(mds),
                        seconds=np.array(seconds), tables=np.array(tables),
                        angles=np.array(accuracy.ANGLES), plan_n=plan.n, plan_md=plan.md)


def main() -> None:
    for name in sys.argv[1:] or (*EXTRA, *FILES):
        run(name)


if __name__ == "__main__":
    main()
