"""Specular paths (layersim.specular_paths): the linearised lobes of ``eval`` against the exact
transport along the same paths.

``eval`` of a path with several near-specular events is the linearised lobe of
:mod:`layersim.specular_paths.lobes` (slopes add; Fresnel and Smith terms constant across the
lobe); albedos and bin energies trace each path exactly (:mod:`layersim.specular_paths.trace`).
For light leaving through the bottom of a glass pane (eta 1.5 then 1.0, both faces of roughness
alpha, Beckmann and GGX) this prints, per incidence, the energy ``eval`` integrates to over a
grid of exit wave vectors around the straight-through direction against the traced energy in
the same grid (the paths carrying at least 1 % of the strongest one's energy: the
straight-through path and the first with two internal reflections; their wider lobes reach
beyond the grid), and the L1
distance between the two distributions over the grid's cells (a fraction of the transmittance):
the linearisation error of ``eval``. The grid spans +-5 lobe widths (``(c1^2 + c2^2)^(1/2)
alpha``) in 20 x 20 cells (wave vectors beyond the horizon left out); the traced side uses
2^19 Sobol nodes per path, whose own quadrature error is part of the L1 distance (about 1e-3).

Usage: python benchmarks/features/specular_paths_eval.py   (output: specular_paths_eval.txt)
"""

from __future__ import annotations

import datetime
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parents[1])]
from headline import commit, machine  # noqa: E402

import layersim  # noqa: E402
from layersim.specular_paths import SpecularPathsBSDF  # noqa: E402
from layersim.specular_paths.paths import Events  # noqa: E402
from layersim.specular_paths.trace import trace_path  # noqa: E402


def _pane(alpha: float, dist: str) -> SpecularPathsBSDF:
    face = lambda eta: {"kind": "dielectric", "ior": eta, "roughness": alpha,
                        "distribution": dist}
    return SpecularPathsBSDF(layersim.Scene.from_dict({"layer": [face(1.5), face(1.0)]}))


def _strong(model, p) -> list:
    """The paths leaving through the bottom with lobes and at least 1 % of the strongest
    one's energy."""
    ev = Events(model.chain, model.faces, p[None])
    xs = [x for x in model.entries[True] if x.rough and not x.path.exit_top]
    e = [float(ev.energy(x.path)[0, 0]) for x in xs]
    return [x for x, v in zip(xs, e) if v >= 0.01 * max(e)]


def _row(bsdf, alpha: float, theta_deg: float) -> str:
    t = math.radians(theta_deg)
    wi = np.array([math.sin(t) * math.cos(0.3), math.sin(t) * math.sin(0.3), math.cos(t)])
    m = bsdf.model.models[0]     # one index per gap: one group of channels
    p = m.p_in(wi[None])[0]
    mu0, mu1 = math.cos(t), math.sqrt(1 - math.sin(t) ** 2 / 2.25)
    width = math.hypot(1, 1) * abs(mu0 - 1.5 * mu1) * alpha
    cells, sub = 20, 12
    edges = np.linspace(-5 * width, 5 * width, cells + 1)
    fine = np.linspace(-5 * width, 5 * width, cells * sub + 1)
    mid = 0.5 * (fine[1:] + fine[:-1])
    X, Y = np.meshgrid(mid, mid, indexing="ij")
    po = p + np.stack([X.ravel(), Y.ravel()], axis=1)
    inside = np.sum(po ** 2, 1) < 1
    wo = np.concatenate([po, -np.sqrt(np.clip(1 - np.sum(po ** 2, 1), 0, 1))[:, None]], 1)
    # f mu dOmega = f / n^2 d^2 p (n = 1 below the pane)
    strong = _strong(m, p)
    f = np.zeros(po.shape[0])
    for x in strong:
        f[inside] += m.eval_path(x, np.broadcast_to(p, po[inside].shape), po[inside])[:, 0]
    lin = (f * (fine[1] - fine[0]) ** 2).reshape(cells, sub, cells, sub).sum(axis=(1, 3))
    traced = np.zeros((cells, cells))
    for x in strong:
        q, w = trace_path(m, x, p, 2 ** 19)
        w = np.where(np.sum(q ** 2, 1) < 1, w[:, 0], 0.0) / 2 ** 19
        H, _, _ = np.histogram2d(q[:, 0] - p[0], q[:, 1] - p[1], bins=[edges, edges],
                                 weights=w)
        traced += H
    total = traced.sum()
    l1 = np.abs(lin - traced).sum() / total
    return (f"  {theta_deg:4.0f} deg: traced {total:.6f}, eval integrates to "
            f"{lin.sum():.6f} ({lin.sum() / total - 1:+.1e}), L1 distance {l1:.1e}")



def main() -> None:
    print("# python benchmarks/features/specular_paths_eval.py")
    print(f"# machine: {machine(False)}")
    print(f"# date: {datetime.datetime.now():%Y-%m-%d %H:%M}; commit: {commit()}")
    for dist in ("beckmann", "ggx"):
        for alpha in (0.003, 0.01, 0.03):
            t0 = time.perf_counter()
            bsdf = _pane(alpha, dist)
            print(f"glass pane, {dist} alpha {alpha:g} (paths built in "
                  f"{time.perf_counter() - t0:.1f} s)")
            for th in (0.0, 30.0, 60.0, 70.0):
                print(_row(bsdf, alpha, th), flush=True)


if __name__ == "__main__":
    main()
