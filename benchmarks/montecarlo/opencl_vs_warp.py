"""The OpenCL walk against the Warp walk, bin by bin, on the bench scenes (not a test).

Both backends run the same walk (the OpenCL C is generated from the Warp functions), so they
must agree within their standard errors. Per scene and incidence angle it runs ``PATHS`` paths on
each backend twice:

* with different seeds (independent estimates): the share of populated bins (both sides, 10 x 12
  bins per side) whose difference lies within 3 combined standard errors, and the largest |z|;
* with the same seed (the same random numbers per path): the largest |z|, which shows how far
  the two compiled walks are from following the same paths (0 for bit-identical tallies).

Usage::

    python benchmarks/montecarlo/opencl_vs_warp.py [PATHS] [--warp warp-cpu] [--scenes NAME ...] \\
        [--angles 0 30 60 85] > benchmarks/montecarlo/opencl_vs_warp.txt

Scenes the Monte Carlo walk cannot run (none at present) are skipped with the reason.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import time
from pathlib import Path

import numpy as np

import layersim
import layersim.montecarlo as mc
from layersim.montecarlo.opencl_device import checked_devices

HERE = Path(__file__).resolve().parent
MU, PHI = np.linspace(0.0, 1.0, 11), np.linspace(0.0, 2 * np.pi, 13)


def zscores(a, b) -> np.ndarray:
    """z of the bin differences over populated bins (both sides, all channels)."""
    out = []
    for side in ("top", "bottom"):
        x, y = np.asarray(a.bins[side]), np.asarray(b.bins[side])
        s = np.hypot(np.asarray(a.bins_stderr[side]), np.asarray(b.bins_stderr[side]))
        pop = s > 0
        out.append((x - y)[pop] / s[pop])
    return np.concatenate(out)


def direction(theta_deg: float) -> np.ndarray:
    th = np.radians(theta_deg)
    return np.array([np.sin(th), 0.0, np.cos(th)])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("paths", nargs="?", type=float, default=1e7)
    ap.add_argument("--warp", default="warp-cpu", choices=["warp-cpu", "warp-cuda"])
    ap.add_argument("--scenes", nargs="*", default=None)
    ap.add_argument("--angles", nargs="*", type=float, default=[0.0, 30.0, 60.0, 85.0])
    args = ap.parse_args()
    paths = int(args.paths)
    files = sorted((HERE.parent / "scenes").glob("*.toml"))
    if args.scenes:
        files = [f for f in files if f.stem in args.scenes]
    commit = subprocess.run(["git", "-C", str(HERE), "log", "-1", "--format=%h %cs"],
                            capture_output=True, text=True).stdout.strip()
    print("# opencl_vs_warp.py: the OpenCL walk against the Warp walk, 10 x 12 bins per side")
    print(f"# command: python benchmarks/montecarlo/opencl_vs_warp.py {args.paths:g} "
          f"--warp {args.warp} --angles {' '.join(f'{a:g}' for a in args.angles)}"
          + (f" --scenes {' '.join(args.scenes)}" if args.scenes else ""))
    print(f"# machine: {platform.machine()}, {os.cpu_count()} cores; commit {commit}; "
          f"date {time.strftime('%Y-%m-%d')}; load average (1 min) {os.getloadavg()[0]:.1f}")
    for c in checked_devices():
        print(f"# OpenCL device: {c.label}: {'builds' if c.ok else c.reason}")
    print(f"\n{'scene':20} {'theta':>5} {'bins':>5} {'in 3 sigma':>10} {'max |z|':>8} "
          f"{'same seed max |z|':>17} {'R opencl':>10} {'R warp':>10} {'sigma R':>8}")
    inside = total = 0
    for f in files:
        scene = layersim.Scene.from_toml(f)
        for theta in args.angles:
            wi = direction(theta)
            runs = {}
            for key, backend, seed in (("cl", "opencl", 1), ("warp", args.warp, 2),
                                       ("warp_same", args.warp, 1)):
                runs[key] = mc.simulate(scene, wi, paths, MU, PHI, backend=backend, seed=seed)
            z = zscores(runs["cl"], runs["warp"])
            z_same = zscores(runs["cl"], runs["warp_same"])
            inside += int(np.sum(np.abs(z) < 3))
            total += z.size
            r_cl, r_w = np.atleast_1d(runs["cl"].reflectance), np.atleast_1d(runs["warp"].reflectance)
            s_r = np.atleast_1d(runs["warp"].reflectance_stderr)
            print(f"{f.stem:20} {theta:5.0f} {z.size:5d} {np.mean(np.abs(z) < 3):10.1%} "
                  f"{np.max(np.abs(z)):8.2f} {np.max(np.abs(z_same)):17.3f} "
                  f"{r_cl[0]:10.6f} {r_w[0]:10.6f} {s_r[0]:8.1e}", flush=True)
    print(f"\n# all: {inside} of {total} populated bins within 3 sigma ({inside / total:.2%})")


if __name__ == "__main__":
    main()
