"""Table 2 of Zeltner & Jakob 2018: a dielectric coating (eta 1.5) over gold
([0.143552, 3.98397], red channel), seven roughness combinations, solved by `layersim.solve`
at the planner's discretisation. Each row runs in a fresh process (so that the peak resident
memory is the row's own); the paper's numbers (4-core i7-6700K, UMFPACK) are printed beside ours.

Columns: total solve time (plan + projection + adding; the time this script spends measuring
the layers' densities inside the solve, before the adding releases them, is left out: on the
isotropic rows it converts the operators to the coupled representation to count them as the
paper does), adding only, density of the top, bottom
and combined operators (nonzeros over all entries of the coupled representation, modes
-(md-1)..md-1, as in the paper), storage of the combined operator, peak resident memory of the
process and, in parentheses, above its baseline (resident memory after importing numpy,
scipy, Warp and layersim and warming up Warp's kernels, ~210 MiB), the plan's memory estimate
(:mod:`layersim.aniso.plan`) and its ratio to the peak above baseline, and the
discretisation.

Usage::

    python benchmarks/speed/table2.py              # all rows (row 6 at a reduced n, see below)
    python benchmarks/speed/table2.py 4 5          # selected rows
    python benchmarks/speed/table2.py --row 4      # one row in this process (used internally)

Row 6 (both layers 1:3 anisotropic, the narrow axis 0.05 in the coating) needs n = 390 and
md = 426 at the planner's accuracy (the coating's refraction lobe sets n = 390; estimated
7.0 GiB); that plan takes several minutes on a 2-core machine (``python
benchmarks/speed/memory_phases.py 6 --default``; figures in docs/performance.md). It is run at
``n = 224, md = 300``: the smallest n at which the coating's discrete operator does not create
energy (n = 196 and 210 are refused by the energy check: 1.00000x and 1.0012), and marked as
such.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from types import SimpleNamespace

import layersim
from layersim import solver
from layersim.aniso import AnisoOperator
from layersim.aniso import plan as aplan
from layersim.config import settings
from layersim.outofcore import memory

GOLD = [0.143552, 3.98397]
ROWS = [  # (top alpha_u, alpha_v), (bottom alpha_u, alpha_v), paper: total s, adding s,
    #       sparsity top %, bottom %, combined %, storage MiB
    ((0.1, 0.1), (0.05, 0.05), 2.6, 0.6, 0.011, 0.019, 0.022, 2.8),
    ((0.1, 0.1), (0.1, 0.1), 2.6, 0.6, 0.011, 0.017, 0.02, 2.6),
    ((0.1, 0.1), (0.3, 0.3), 2.2, 0.3, 0.011, 0.008, 0.018, 2.3),
    ((0.1, 0.1), (0.05, 0.15), 26.8, 16.9, 0.011, 0.489, 0.208, 31.1),
    ((0.1, 0.1), (0.1, 0.3), 24.2, 16.9, 0.011, 0.336, 0.144, 27.3),
    ((0.15, 0.05), (0.05, 0.15), 900.0, 780.0, 0.059, 0.087, 0.01, 214.1),
    ((0.3, 0.1), (0.1, 0.3), 67.5, 52.2, 0.29, 0.336, 0.39, 31.3),
]
#: Discretisation overrides (row index from 1): see the module docstring about row 6.
OVERRIDES = {6: {"n": 224, "md": 300}}


def paper_ms(top, bottom) -> int:
    """The coupling half-width of the paper's solves: its eq. (25) for the more anisotropic
    layer (``layersim.aniso.plan.ms_one_percent``), without the planner's margin, so that the
    timings compare like with like; 0 for the isotropic rows."""
    layers = [SimpleNamespace(alpha_u=a[0], alpha_v=a[1]) for a in (top, bottom)]
    return max(aplan.ms_one_percent(layer) for layer in layers)


def _density(op) -> float:
    """Nonzeros over all entries of the coupled representation (percent)."""
    if not isinstance(op, AnisoOperator):
        op = AnisoOperator.from_iso(op)
    return 100.0 * op.density()


def run_row(k: int) -> dict:
    memory.cap_arenas(settings().malloc_arenas)     # the row's process is this script's
    top, bottom = ROWS[k - 1][:2]
    scene = {"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": list(top)},
                       {"kind": "conductor", "ior": GOLD, "roughness": list(bottom)}]}
    scene["discretization"] = dict(OVERRIDES.get(k, {}))
    if paper_ms(top, bottom):
        scene["discretization"]["ms"] = paper_ms(top, bottom)
    # warm up Warp (kernel modules load once per process; compiled modules are cached on disk)
    layersim.solve(layersim.Scene.from_dict({"layer": [
        {"kind": "conductor", "ior": [0.2, 3.0], "roughness": [0.3, 0.2]}],
        "discretization": {"n": 16, "md": 4}}))
    with open("/proc/self/statm") as f:   # resident memory of the imported, warmed-up process
        baseline = int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    captured = {}
    measuring = [0.0]               # seconds spent measuring the densities, not solving
    original = solver._layer_operator

    def keep(plan, grid, sc, i, *args, **kwargs):
        op = original(plan, grid, sc, i, *args, **kwargs)
        t = time.perf_counter()
        captured[i] = _density(op)      # now: the adding releases the layers' blocks
        measuring[0] += time.perf_counter() - t
        return op

    solver._layer_operator = keep
    t0 = time.perf_counter()
    bsdf = layersim.solve(layersim.Scene.from_dict(scene))
    total = time.perf_counter() - t0 - measuring[0]
    solver._layer_operator = original
    op = bsdf.operators[0]
    return {
        "row": k, "total": total, "adding": bsdf.info["seconds"]["adding"],
        "projection": bsdf.info["seconds"]["projection"],
        "top": captured[0], "bottom": captured[1], "combined": _density(op),
        "storage": op.memory_bytes() / 2**20,
        "rss": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "baseline": baseline, "estimate": bsdf.plan.memory_bytes / 2**20,
        "n": bsdf.info["n"], "md": bsdf.info["md"], "ms": bsdf.info["ms"],
        "representation": bsdf.info.get("representation", "isotropic"),
    }


def main(argv) -> int:
    if argv[:1] == ["--row"]:
        print(json.dumps(run_row(int(argv[1]))))
        return 0
    rows = [int(a) for a in argv] or list(range(1, len(ROWS) + 1))
    print(f"machine: {os.cpu_count()} cores; layersim threads (LAYERSIM_THREADS): "
          f"{settings().threads}; load average at start {os.getloadavg()[0]:.1f}")
    head = (f"{'row':>3} {'top':>11} {'bottom':>11} | {'total s':>15} {'adding s':>15} | "
            f"{'top %':>13} {'bottom %':>13} {'combined %':>13} | {'storage MiB':>15} | "
            f"{'peak RSS MiB (above base)':>25} | {'estimate MiB (/above)':>21} | "
            "discretisation")
    print(head)
    print("    (ours / paper)" + " " * 20 + "(ours / paper in each column)")
    for k in rows:
        proc = subprocess.run([sys.executable, __file__, "--row", str(k)], capture_output=True,
                              text=True)
        if proc.returncode:
            print(f"{k:>3} failed: {proc.stderr.strip().splitlines()[-1]}")
            continue
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        p = ROWS[k - 1]
        tag = " (reduced)" if k in OVERRIDES else ""
        pt = f"{p[2] / 60:.0f} min" if p[2] >= 600 else f"{p[2]:.1f}"
        pa = f"{p[3] / 60:.0f} min" if p[3] >= 600 else f"{p[3]:.1f}"
        print(f"{k:>3} {str(p[0]):>11} {str(p[1]):>11} | {r['total']:6.1f} / {pt:>6} "
              f"{r['adding']:6.1f} / {pa:>6} | {r['top']:6.3f}/{p[4]:<6.3f} "
              f"{r['bottom']:6.3f}/{p[5]:<6.3f} {r['combined']:6.3f}/{p[6]:<6.3f} | "
              f"{r['storage']:6.1f} / {p[7]:<6.1f} | {r['rss']:11.0f} ({r['rss'] - r['baseline']:5.0f})"
              f"       | {r['estimate']:8.0f} ({r['estimate'] / (r['rss'] - r['baseline']):4.2f}x)"
              f"       | n={r['n']} "
              f"md={r['md']} ms={r['ms']} {r['representation']}{tag}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
