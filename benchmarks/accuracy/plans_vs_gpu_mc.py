"""How close the planner's default discretisation (and a solve to tol = 1e-3) comes to the
Monte Carlo reference at 1e9 paths: per scene of ``benchmarks/scenes/`` and incidence 0, 30 and
60 degrees, the fraction of populated 18 x 36 bins (both sides) within 3 standard errors (Poisson
floor E / N added), the relative L2 difference of bin energies and the albedo difference in
standard errors; with the solve's error estimate (``layersim.plan.accuracy``) beside it.

Usage (on a GPU machine): python benchmarks/accuracy/plans_vs_gpu_mc.py [--tol T ...] [paths]
[backend] [SCENE[:KEY=VALUE,...] ...] (default 1e9, warp-cuda, every scene, tol 1e-3;
``--tol 0``: the default plan only). ``KEY=VALUE`` set ``[discretization]`` fields over the
planner's (e.g. ``additive_validation:ms=8`` keeps the planned n and md and widens the coupled
modes). Output of runs on an NVIDIA H100: benchmarks/accuracy/plans_vs_gpu_mc.txt.
"""
import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import layersim
import layersim.montecarlo as mc
from layersim.errors import LayersimError

SCENES = Path(__file__).resolve().parents[1] / "scenes"
MU_EDGES = np.linspace(0.0, 1.0, 19)
PHI_EDGES = np.linspace(0.0, 2.0 * np.pi, 37)
ANGLES = (0.0, 30.0, 60.0)


def compare(bsdf, scene, paths: int, backend: str, seed: int) -> str:
    rows = []
    for k, theta in enumerate(ANGLES):
        t = np.radians(theta)
        wi = np.array([np.sin(t), 0.0, np.cos(t)])
        mono = scene.channel(0) if scene.channels > 1 else scene
        res = mc.simulate(mono, wi, paths, mu_edges=MU_EDGES, phi_edges=PHI_EDGES,
                          backend=backend, seed=seed + k)
        e = bsdf.bin_energies(wi, MU_EDGES, PHI_EDGES)
        ours = np.stack([np.asarray(e[s]).reshape(18, 36, -1)[..., 0] for s in ("top", "bottom")])
        est = np.stack([np.asarray(res.bins[s]).reshape(18, 36, -1)[..., 0] for s in ("top", "bottom")])
        sig = np.stack([np.asarray(res.bins_stderr[s]).reshape(18, 36, -1)[..., 0]
                        for s in ("top", "bottom")])
        sig = np.sqrt(sig ** 2 + np.maximum(est, 0.0) / paths)
        populated = (est > 0) | (ours > 1e-12)
        inside = float(np.mean((np.abs(ours - est) <= 3 * sig + 1e-15)[populated]))
        l2 = float(np.sqrt(np.sum((ours - est) ** 2) / np.sum(est ** 2)))
        R = float(np.atleast_1d(bsdf.albedo(wi)[0])[0])
        r, sr = float(np.atleast_1d(res.reflectance)[0]), float(np.atleast_1d(res.reflectance_stderr)[0])
        rows.append(f"{theta:3.0f} deg: {100 * inside:5.1f} % in 3 sigma, L2 {l2:.1e}, "
                    f"dR {(R - r) / max(sr, 1e-12):+5.1f} se")
    return " | ".join(rows)


def load(spec: str):
    """The scene of ``NAME[:KEY=VALUE,...]``, with the planner's n and md and the given
    [discretization] fields."""
    name, _, fields = spec.partition(":")
    scene = layersim.Scene.from_toml(SCENES / f"{name}.toml")
    if not fields:
        return scene
    plan = layersim.make_plan(scene, refuse=False)
    disc = {"n": plan.n, "md": plan.md}
    disc.update({k: int(v) for k, v in (f.split("=") for f in fields.split(","))})
    return replace(scene, discretization=replace(scene.discretization, **disc))


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--tol", type=float, action="append")
    parser.add_argument("paths", nargs="?", default="1e9")
    parser.add_argument("backend", nargs="?", default="warp-cuda")
    parser.add_argument("scenes", nargs="*")
    args = parser.parse_args()
    paths = int(float(args.paths))
    backend = args.backend
    names = args.scenes or sorted(p.stem for p in SCENES.glob("*.toml"))
    tols = [t for t in (args.tol or [1e-3]) if t > 0]
    print(f"# {paths:.0e} paths per direction, backend {backend}; bins 18 x 36 per side")
    for name in names:
        scene = load(name)
        runs = [("default", {"error_estimate": True})]
        runs += [(f"tol {t:g}", {"tol": t}) for t in tols]
        for label, kw in runs:
            t0 = time.perf_counter()
            try:
                bsdf = layersim.solve(scene, **kw)
            except LayersimError as exc:
                print(f"{name:22s} {label:8s} refused: {str(exc)[:160]}", flush=True)
                continue
            sec = time.perf_counter() - t0
            print(f"{name:22s} {label:8s} n={bsdf.info['n']:4d} md={bsdf.info['md']:5d} "
                  f"estimate {bsdf.error_estimate:.1e} ({sec:.1f} s): "
                  + compare(bsdf, scene, paths, backend, 100), flush=True)


if __name__ == "__main__":
    main()
