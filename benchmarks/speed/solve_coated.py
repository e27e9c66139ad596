"""Time ``layersim.solve`` on isotropic coated conductors and show the accuracy beside the time.

Rows: a dielectric coating (eta 1.5, Beckmann alpha_top) over gold (eta + ik = 0.143552 + 3.98397i,
the red channel of the layerlab tutorial, Beckmann alpha_bottom): the isotropic rows of Table 2 of
the Layer Laboratory paper (Zeltner & Jakob 2018), plus 0.05/0.05 and 0.3/0.3, for which layerlab
timings are known. For each row the planner's own discretisation (n, md) is timed (best of
``--repeat`` runs, after one warm-up that compiles the Warp kernels), split into plan,
projection (per layer) and adding; sparsity and storage of the stack are reported.

Accuracy: each row is also solved on a finer discretisation (1.5x the ordinates and orders), and
the error of the default solve against it is reported as
* ``albedo_err``: max |R - R_ref| over incidence angles 0..85 degrees, and
* ``bsdf_err``: relative L2 error of the energy in 18 x 36 bins (|cos theta_o| x phi_o) for
  incidence at 0, 30, 60 degrees.

Reference figures: the paper's 4-core desktop took 2.6 / 2.6 / 2.2 s in total
for the three Table 2 rows; layerlab (C++/TBB, Release, 2 cores), at its own heuristic (n = 196,
m = 267 for those rows), 1.3-1.4 s; 0.05/0.05 (n = 394, m = 671) 2.6 s; 0.3/0.3 (n = 92, m = 61)
2.6 s.

Usage::

    python benchmarks/speed/solve_coated.py [--repeat 3] [--json out.json] [--no-reference]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import numpy as np

import layersim
from layersim.scene import Scene

GOLD = [0.143552, 3.98397]
ROWS = [  # (alpha_top, alpha_bottom, paper seconds, layerlab seconds)
    (0.1, 0.05, 2.6, 1.35),
    (0.1, 0.1, 2.6, 1.35),
    (0.1, 0.3, 2.2, 1.35),
    (0.05, 0.05, None, 2.6),
    (0.3, 0.3, None, 2.6),
]


def scene(top, bottom, n=None, md=None):
    data = {"stack": {"name": f"coated_gold_{top}_{bottom}"}, "layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": top},
        {"kind": "conductor", "ior": GOLD, "roughness": bottom}]}
    if n is not None:
        data["discretization"] = {"n": n, "md": md}
    return Scene.from_dict(data)


def directions(theta_deg):
    th = np.radians(theta_deg)
    return np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], axis=-1)


def accuracy(bsdf, ref):
    angles = np.arange(0.0, 86.0, 5.0)
    R, _ = bsdf.albedo(directions(angles))
    Rr, _ = ref.albedo(directions(angles))
    mu_edges = np.linspace(0.0, 1.0, 19)
    phi_edges = np.linspace(0.0, 2 * np.pi, 37)
    num = den = 0.0
    for th in (0.0, 30.0, 60.0):
        wi = directions(np.array(th))
        a = bsdf.bin_energies(wi, mu_edges, phi_edges)["top"]
        b = ref.bin_energies(wi, mu_edges, phi_edges)["top"]
        num += np.sum((a - b) ** 2)
        den += np.sum(b ** 2)
    return float(np.max(np.abs(R - Rr))), float(np.sqrt(num / den))


def run(repeat: int, with_reference: bool):
    layersim.solve(scene(0.3, 0.3))  # warm-up: compile kernels
    rows = []
    for top, bottom, paper, layerlab in ROWS:
        sc = scene(top, bottom)
        best = None
        for _ in range(repeat):
            b = layersim.solve(sc)
            if best is None or b.info["seconds"]["total"] < best.info["seconds"]["total"]:
                best = b
        info = best.info
        op = best.operators[0]
        row = {
            "alpha_top": top, "alpha_bottom": bottom, "n": info["n"], "md": info["md"],
            "seconds": info["seconds"], "nnz": info["nnz"],
            "density": op.density(), "storage_mib": op.memory_bytes() / 2 ** 20,
            "paper_seconds": paper, "layerlab_seconds": layerlab,
        }
        if with_reference:
            n_ref = int(round(1.5 * info["n"] / 2)) * 2
            ref = layersim.solve(scene(top, bottom, n_ref, int(1.5 * info["md"])))
            row["reference"] = {"n": n_ref, "md": int(1.5 * info["md"])}
            row["albedo_err"], row["bsdf_err"] = accuracy(best, ref)
        rows.append(row)
        print_row(row, header=len(rows) == 1)
    return rows


def print_row(r, header=False):
    if header:
        print(f"{'top':>5} {'bot':>5} {'n':>5} {'md':>5} {'plan':>6} {'proj':>6} {'add':>6} "
              f"{'total':>6} {'paper':>6} {'llab':>6} {'dens%':>6} {'MiB':>6} "
              f"{'albedo_err':>10} {'bsdf_err':>9}")
    s = r["seconds"]
    fmt = lambda v: f"{v:6.2f}" if v is not None else "     -"
    err = (f"{r['albedo_err']:10.2e} {r['bsdf_err']:9.2e}" if "albedo_err" in r else "")
    print(f"{r['alpha_top']:5.2f} {r['alpha_bottom']:5.2f} {r['n']:5d} {r['md']:5d} "
          f"{s['plan']:6.2f} {s['projection']:6.2f} {s['adding']:6.2f} {s['total']:6.2f} "
          f"{fmt(r['paper_seconds'])} {fmt(r['layerlab_seconds'])} "
          f"{100 * r['density']:6.3f} {r['storage_mib']:6.1f} {err}", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", help="write the results here")
    ap.add_argument("--no-reference", action="store_true", help="skip the accuracy solves")
    args = ap.parse_args()
    rows = run(args.repeat, not args.no_reference)
    if args.json:
        out = {"machine": {"cpu": platform.processor() or platform.machine(),
                           "cores": os.cpu_count(), "python": platform.python_version(),
                           "numpy": np.__version__, "layersim": layersim.__version__},
               "command": "python benchmarks/speed/solve_coated.py " + " ".join(
                   f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items()
                   if v not in (None, False)),
               "rows": rows, "date": time.strftime("%Y-%m-%d")}
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
