"""Throughput of the Monte Carlo walk in this checkout against another checkout (the base), side
by side in one run: the guard that shows a slower walk before it lands.

Each checkout runs in its own worker process, which imports that checkout's ``layersim`` (with its
``kernels`` and ``montecarlo`` packages) from a staging folder of links, so that an installed
layersim cannot leak into either side. The driver sends both workers the same runs, alternating
base and new, and keeps the best of ``--repeat`` runs of each after one warm-up run per worker
and backend (which compiles the kernels). Runs use the same seed on both sides, so where the walk's
physics and random-number use are unchanged the tallies agree bit for bit, and the table says so
(``same``); otherwise it gives the largest difference of the bin energies in standard errors.

Scenes: those of ``benchmarks/montecarlo/mc_throughput.py`` (an index-matched HG slab; a coated
anisotropic conductor), a coated isotropic gold, and an RGB medium between a rough coat and a rough
conductor (car paint), all lit at 30 degrees, 10 x 12 bins.

Usage::

    git worktree add /tmp/base <commit>
    python benchmarks/montecarlo/walk_vs_base.py --base /tmp/base [--backends warp-cpu] \\
        [--seconds 3] [--repeat 3] > benchmarks/montecarlo/walk_vs_base_cpu.txt

On a GPU machine name ``--backends warp-cuda`` (and ``opencl``).
"""

from __future__ import annotations

import argparse
import json
import math
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
#: Roughly aluminium at red, green and blue (eta + i k near 650 / 550 / 450 nm); the throughput
#: does not depend on the exact values.
ALUMINIUM = [[1.49, 7.82], [0.96, 6.69], [0.62, 5.47]]
SCENES = {
    "slab": {"layer": [{"kind": "medium", "albedo": 0.95, "g": 0.5, "tau": 2.0}]},
    "coated_aniso": {"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": [0.1, 0.2]},
        {"kind": "conductor", "ior": GOLD, "roughness": [0.2, 0.1]}]},
    "coated_gold": {"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.1},
        {"kind": "conductor", "ior": GOLD, "roughness": 0.1}]},
    "car_paint_rgb": {"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.05},
        {"kind": "medium", "tau": [0.3, 0.8, 1.5], "albedo": [0.9, 0.6, 0.3], "g": 0.3},
        {"kind": "conductor", "ior": ALUMINIUM, "roughness": 0.25}]},
}
THETA_I = 30.0
#: Particles per launch: large enough that launch overheads vanish on each kind of device.
BATCH = {"warp-cpu": 1 << 17, "opencl": 1 << 20, "warp-cuda": 1 << 26}


# ---- worker: runs in the checkout under test -------------------------------------------------

def worker() -> None:
    """Read runs as JSON lines from stdin, simulate, answer with timings and tallies."""
    import numpy as np
    import layersim
    import layersim.kernels
    import layersim.montecarlo as mc

    print(json.dumps({"layersim": layersim.__file__, "kernels": layersim.kernels.__file__,
                      "montecarlo": mc.__file__}), flush=True)
    mu_edges, phi_edges = np.linspace(0.0, 1.0, 11), np.linspace(0.0, 2 * np.pi, 13)
    th = math.radians(THETA_I)
    wi = np.array([math.sin(th), 0.0, math.cos(th)])
    for line in sys.stdin:
        run = json.loads(line)
        try:
            scene = layersim.Scene.from_dict(run["scene"])
        except Exception as exc:           # a base older than a scene's features
            print(json.dumps({"error": str(exc)}), flush=True)
            continue
        res = mc.simulate(scene, wi, run["particles"], mu_edges, phi_edges,
                          backend=run["backend"], seed=run["seed"], batch_size=run["batch"])
        print(json.dumps({
            "seconds": res.seconds, "events": float(np.sum(res.events)), "device": res.device,
            "bins": np.asarray(res.bins["top"]).ravel().tolist(),
            "stderr": np.asarray(res.bins_stderr["top"]).ravel().tolist()}), flush=True)


# ---- driver ------------------------------------------------------------------------------------

class Worker:
    def __init__(self, checkout: Path, staging: Path):
        self.site = stage(checkout.resolve(), staging)
        env = worker_env(self.site)
        self.proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--worker"],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                     env=env, cwd="/")
        line = self.proc.stdout.readline()
        if not line:
            raise SystemExit(f"{checkout}: the worker did not start (see its error above)")
        self.modules = json.loads(line)
        for name, path in self.modules.items():
            if not path.startswith(str(self.site)):
                raise SystemExit(f"{checkout}: imported {name} from {path}")
        self.checkout = checkout

    def run(self, **spec) -> dict:
        self.proc.stdin.write(json.dumps(spec) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise SystemExit(f"{self.checkout}: a worker stopped (see its error above)")
        return json.loads(line)

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait()


def commit_of(checkout: Path) -> str:
    try:
        out = subprocess.run(["git", "-C", str(checkout), "log", "-1", "--format=%h %cs"],
                             capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(checkout), "status", "--porcelain",
                                "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return (out or "unknown") + (" with uncommitted changes" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def agreement(a: dict, b: dict) -> str:
    """``same`` for bit-identical bins, else the largest difference in standard errors."""
    if a["bins"] == b["bins"]:
        return "same"
    z = max(abs(x - y) / math.hypot(sx, sy) for x, y, sx, sy in
            zip(a["bins"], b["bins"], a["stderr"], b["stderr"]) if sx > 0 or sy > 0)
    return f"{z:.2f} sigma"


def main() -> None:
    if sys.argv[1:] == ["--worker"]:
        return worker()
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--base", required=True, type=Path, help="checkout of the base commit")
    ap.add_argument("--backends", nargs="+", default=["warp-cpu"], choices=sorted(BATCH))
    ap.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--seconds", type=float, default=3.0, help="about this long per run")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--machine", default=None, help="how to name the machine in the header")
    ap.add_argument("--base-name", default=None,
                    help="how to name the base (default: its git commit)")
    ap.add_argument("--new-name", default=None,
                    help="how to name this checkout (default: its git commit)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        base = Worker(args.base, Path(tmp) / "base")
        new = Worker(ROOT, Path(tmp) / "new")
        print("# walk_vs_base.py: Monte Carlo walk throughput, this checkout (new) against a base")
        print("# command: python benchmarks/montecarlo/walk_vs_base.py " + " ".join(sys.argv[1:]))
        print(f"# machine: {args.machine or platform.node()} ({platform.machine()}, "
              f"{os.cpu_count()} cores, {platform.processor() or 'cpu'}); Python "
              f"{platform.python_version()}; date {time.strftime('%Y-%m-%d %H:%M')}")
        print(f"# base: {args.base_name or commit_of(args.base)}   new: {args.new_name or commit_of(ROOT)}")
        print(f"# load average (1 min) at the start: {os.getloadavg()[0]:.2f}")
        print(f"# best of {args.repeat} runs after one warm-up run per worker and backend, base and"
              f" new alternating, the same seed on both sides; incidence {THETA_I:g} deg")
        print(f"\n{'scene':14} {'backend':10} {'paths':>9} {'base p/s':>10} {'new p/s':>10} "
              f"{'new/base':>8} {'ev/path':>7} {'new ev/s':>10} {'tallies':>10}  device")
        for backend in args.backends:
            for name in args.scenes:
                spec = dict(scene=SCENES[name], backend=backend, batch=BATCH[backend], seed=7)
                pilots = [w.run(particles=BATCH[backend], **spec) for w in (base, new)]
                failed = [(w, p["error"]) for w, p in zip(("base", "new"), pilots) if "error" in p]
                if failed:                  # warm-up: compile, and size the run
                    print(f"{name:14} {backend:10} not run: {failed[0][0]} cannot read the scene "
                          f"({failed[0][1]})", flush=True)
                    continue
                pilot = new.run(particles=BATCH[backend], **spec)     # sized after the warm-up
                per_s = BATCH[backend] / max(pilot["seconds"], 1e-9)
                n = max(1, round(per_s * args.seconds / BATCH[backend])) * BATCH[backend]
                runs = {"base": [], "new": []}
                for _ in range(args.repeat):
                    runs["base"].append(base.run(particles=n, **spec))
                    runs["new"].append(new.run(particles=n, **spec))
                best = {k: n / min(r["seconds"] for r in v) for k, v in runs.items()}
                r = runs["new"][0]
                print(f"{name:14} {backend:10} {n:9.2e} {best['base']:10.3e} {best['new']:10.3e} "
                      f"{best['new'] / best['base']:8.2f} {r['events'] / n:7.3f} "
                      f"{best['new'] * r['events'] / n:10.3e} "
                      f"{agreement(runs['base'][0], r):>10}  {r['device']}", flush=True)
        base.close()
        new.close()
    print(f"# load average (1 min) at the end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
