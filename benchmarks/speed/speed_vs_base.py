"""Solve times of this checkout against another checkout of layersim (the base), side by side.

Each checkout runs in its own worker process (``PYTHONPATH`` set to the checkout, so that its
``layersim`` is the one imported); the driver sends both the same scenes, alternating base and
new solve by solve, and keeps the best of ``--repeat`` solves of each after one warm-up solve
per worker (which compiles the Warp kernels). Rows: the isotropic coated-gold rows of
``benchmarks/speed/solve_coated.py`` (dielectric eta 1.5 over gold, Beckmann alpha top / bottom) and
three scenes of ``benchmarks/scenes/``, each on its planner's own discretisation (n, md).

Per row it prints the best wall and CPU (process) seconds of each checkout, the ratio base/new,
and the largest relative difference between the two solutions of

* the albedo (top reflectance) at incidence 0, 5, ..., 85 degrees, and
* the energies of 18 x 36 bins (|cos theta_o| x phi_o) of the top side for incidence at 0, 30
  and 60 degrees, relative to the largest bin energy of the same incidence.

Usage (the base checkout without its own install; it imports this environment's packages)::

    git worktree add /tmp/base <commit>          # or: git archive <commit> | tar -x -C /tmp/base
    python benchmarks/speed/speed_vs_base.py --base /tmp/base [--repeat 3] \\
        > benchmarks/speed/speed_vs_base.txt
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(HERE.parent))
from checkout import stage, worker_env  # noqa: E402
GOLD = [0.143552, 3.98397]
COATED = [(0.1, 0.05), (0.1, 0.1), (0.1, 0.3), (0.05, 0.05), (0.3, 0.3)]
SCENES = ["coated_hg_diffuse.toml", "dusty_gold.toml", "ggx_coated_gold.toml"]


def coated(top: float, bottom: float) -> dict:
    """The scene of a row of ``benchmarks/speed/solve_coated.py`` as a dict."""
    return {"stack": {"name": f"coated_gold_{top}_{bottom}"}, "layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": top},
        {"kind": "conductor", "ior": GOLD, "roughness": bottom}]}


def rows() -> list:
    """``(label, scene)``: a dict, or the path of a TOML file."""
    out = [(f"coated gold {t}/{b}", coated(t, b)) for t, b in COATED]
    out += [(name[:-5], str(HERE.parent / "scenes" / name)) for name in SCENES]
    return out


# ---- worker: runs in the checkout under test -------------------------------------------------

def worker() -> None:
    """Read JSON scenes from stdin, solve, write timings and results as JSON lines."""
    import numpy as np
    import layersim
    from layersim.scene import Scene

    mu_edges, phi_edges = np.linspace(0.0, 1.0, 19), np.linspace(0.0, 2 * np.pi, 37)

    def direction(deg):
        th = np.radians(np.atleast_1d(np.asarray(deg, float)))
        return np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], axis=-1)

    import layersim.kernels
    import layersim.montecarlo
    print(json.dumps({"layersim": layersim.__file__, "kernels": layersim.kernels.__file__,
                      "montecarlo": layersim.montecarlo.__file__}), flush=True)
    for line in sys.stdin:
        spec = json.loads(line)
        scene = (Scene.from_toml(spec) if isinstance(spec, str) else Scene.from_dict(spec))
        t0, c0 = time.perf_counter(), time.process_time()
        bsdf = layersim.solve(scene)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        albedo, _ = bsdf.albedo(direction(np.arange(0.0, 86.0, 5.0)))
        bins = [bsdf.bin_energies(direction(th)[0], mu_edges, phi_edges)["top"].ravel().tolist()
                for th in (0.0, 30.0, 60.0)]
        print(json.dumps({"wall": wall, "cpu": cpu, "n": bsdf.info["n"], "md": bsdf.info["md"],
                          "albedo": np.ravel(albedo).tolist(), "bins": bins}), flush=True)


# ---- driver ------------------------------------------------------------------------------------

class Worker:
    def __init__(self, checkout: Path, staging: Path):
        site = stage(checkout, staging)
        self.proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--worker"],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                     env=worker_env(site), cwd="/")
        line = self.proc.stdout.readline()
        if not line:
            raise SystemExit(f"{checkout}: the worker did not start (see its error above)")
        modules = json.loads(line)
        for name, path in modules.items():
            if not path.startswith(str(site)):
                raise SystemExit(f"{checkout}: imported {name} from {path}")
        self.module = f"{checkout} ({modules['layersim']})"

    def solve(self, spec) -> dict:
        self.proc.stdin.write(json.dumps(spec) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise SystemExit("a worker stopped (see its error above)")
        return json.loads(line)

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait()


def differences(a: dict, b: dict) -> tuple[float, float]:
    """Largest relative difference of the albedos, and of the bin energies (relative to the
    largest bin of each incidence)."""
    alb = max(abs(x - y) / max(abs(y), 1e-300) for x, y in zip(a["albedo"], b["albedo"]))
    bins = max(max(abs(x - y) for x, y in zip(p, q)) / max(max(q), 1e-300)
               for p, q in zip(a["bins"], b["bins"]))
    return alb, bins


def main() -> None:
    if sys.argv[1:] == ["--worker"]:
        return worker()
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--base", required=True, help="checkout of the base commit")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--only", help="rows whose label contains this text")
    args = ap.parse_args()
    staging = Path(tempfile.mkdtemp(prefix="speed_vs_base_"))
    base, new = Worker(Path(args.base), staging / "base"), Worker(ROOT, staging / "new")
    print("# speed_vs_base.py: layersim.solve in this checkout (new) against a base checkout")
    print(f"# command: python benchmarks/speed/speed_vs_base.py --base {args.base} "
          f"--repeat {args.repeat}" + (f" --only '{args.only}'" if args.only else ""))
    print(f"# machine: shared 2-core CI VM, beside other jobs ({platform.machine()}, "
          f"{os.cpu_count()} cores, Python {platform.python_version()}); "
          f"date {time.strftime('%Y-%m-%d')}")
    print(f"# load average (1 min) at the start: {os.getloadavg()[0]:.1f}")
    print(f"# base: {base.module}\n# new:  {new.module}")
    print("# best of the repeats after one warm-up solve per worker, base and new alternating;"
          "\n# max rel diff: albedo at 0..85 deg, and 18 x 36 top bin energies at 0/30/60 deg"
          " (relative to the largest bin)")
    for w in (base, new):
        w.solve(coated(0.3, 0.3))
    print(f"\n{'row':28} {'n':>4} {'md':>4} {'base s':>7} {'new s':>7} {'ratio':>6} "
          f"{'base cpu':>8} {'new cpu':>8} {'ratio':>6} {'albedo diff':>11} {'bin diff':>9}")
    for label, spec in rows():
        if args.only and args.only not in label:
            continue
        runs = {"base": [], "new": []}
        for _ in range(args.repeat):
            runs["base"].append(base.solve(spec))
            runs["new"].append(new.solve(spec))
        best = {k: min(r["wall"] for r in v) for k, v in runs.items()}
        cpu = {k: min(r["cpu"] for r in v) for k, v in runs.items()}
        a, b = runs["new"][0], runs["base"][0]
        if (a["n"], a["md"]) != (b["n"], b["md"]):
            raise SystemExit(f"{label}: the plans differ ({a['n']}, {a['md']}) against "
                             f"({b['n']}, {b['md']})")
        alb, bins = differences(a, b)
        print(f"{label:28} {a['n']:4d} {a['md']:4d} {best['base']:7.2f} {best['new']:7.2f} "
              f"{best['base'] / best['new']:6.2f} {cpu['base']:8.2f} {cpu['new']:8.2f} "
              f"{cpu['base'] / cpu['new']:6.2f} {alb:11.1e} {bins:9.1e}", flush=True)
    base.close()
    new.close()
    print(f"# load average (1 min) at the end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
