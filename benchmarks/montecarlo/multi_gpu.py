"""Paths per second of the Monte Carlo walk on 1, 2, ..., N devices of one host (not a test).

Runs the scenes of ``benchmarks/montecarlo/mc_throughput.py`` (an index-matched HG slab; a coated
anisotropic conductor), lit at 30 degrees, through
:class:`layersim.montecarlo.executors.Devices` (one thread per device) on the first 1, 2, ..., N
devices, the same paths and seed each time, and prints a scaling table: paths/s, speed-up over
one device and efficiency (speed-up / devices). Every run's tally must equal the one-device tally
bit for bit (``same``); any difference is reported and the script exits 1.

The script imports this checkout's layersim through a staging folder of links
(``benchmarks/checkout.py``), so it runs from a copy of the tree without installing it; the header
names the command, machine, date and commit (``benchmarks/headline.py``). With no CUDA device it
says so and exits 0; with one it measures that device and says there is no scaling to show.
``--backend warp-cpu --devices cpu,cpu`` runs two threads on Warp's CPU device (each launch on
one core): on an idle host that shows whether Warp's launches release the GIL.

Usage::

    python benchmarks/montecarlo/multi_gpu.py [--seconds 5] [--devices cuda:0,cuda:1] \\
        [--backend warp-cuda] [--scenes slab coated]
"""

from __future__ import annotations

import argparse
import atexit
import math
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path[:0] = [str(HERE), str(HERE.parent)]
from checkout import stage  # noqa: E402
from headline import commit, machine  # noqa: E402

#: Paths per range (one launch): large enough that launch overheads vanish on each device.
BATCH = {"warp-cpu": 1 << 16, "opencl": 1 << 20, "warp-cuda": 1 << 26}
SEED = 5


def _import_checkout():
    """Import this checkout's layersim from a staging folder (not an installed copy)."""
    folder = tempfile.mkdtemp(prefix="layersim-stage-")
    atexit.register(shutil.rmtree, folder, True)
    site = stage(ROOT, Path(folder) / "site")
    sys.path.insert(0, str(site))
    import layersim
    if not Path(layersim.__file__).resolve().is_relative_to(ROOT.resolve()):
        raise SystemExit(f"multi_gpu.py: imported {layersim.__file__}, not this checkout")
    return layersim


def _walk(layersim, scene_dict, backend):
    from layersim.montecarlo.work import Walk
    from mc_throughput import WI
    mu = tuple(float(x) for x in [i / 10 for i in range(11)])
    phi = tuple(2 * math.pi * i / 12 for i in range(13))
    return Walk(layersim.Scene.from_dict(scene_dict), tuple(float(x) for x in WI), mu, phi, SEED,
                100_000, backend)


def _run(walk, devices, paths):
    """(seconds, tally) of ``paths`` paths of ``walk`` spread over ``devices``."""
    from layersim.montecarlo.executors import Devices
    from layersim.montecarlo.work import split
    total = None
    t0 = time.perf_counter()
    with Devices(walk.backend, devices) as ex:
        for _, t in ex.map(split(walk, 0, paths, BATCH[walk.backend])):
            total = t if total is None else total + t
    return time.perf_counter() - t0, total


def _paths_for(walk, device, seconds) -> int:
    """Paths (a multiple of the batch) that ``device`` walks in about ``seconds``."""
    from layersim.montecarlo.work import PathRange, run_range
    batch = BATCH[walk.backend]
    t0 = time.perf_counter()
    run_range(PathRange(walk, batch, batch), device)
    rate = batch / max(time.perf_counter() - t0, 1e-9)
    return max(1, round(rate * seconds / batch)) * batch


def _same(a, b) -> str:
    import numpy as np
    ok = (a.particles == b.particles and a.events == b.events and a.truncated == b.truncated
          and np.array_equal(a.w, b.w))
    return "same" if ok else "DIFFERENT"


def measure(layersim, name, scene_dict, backend, devices, seconds) -> bool:
    """Print the rows of one scene; False if a tally differs from the one-device tally."""
    from layersim.montecarlo.work import PathRange, run_range
    walk = _walk(layersim, scene_dict, backend)
    for d in devices:                                        # load the kernel on every device
        run_range(PathRange(walk, 0, 1024), d)
    paths = _paths_for(walk, devices[0], seconds)
    paths = max(paths, 8 * len(devices) * BATCH[backend])   # enough ranges to balance N devices
    base = None
    all_same = True
    for n in range(1, len(devices) + 1):
        sec, tally = _run(walk, devices[:n], paths)
        rate = paths / sec
        base = base or (rate, tally)
        same = _same(tally, base[1])
        all_same &= same == "same"
        speedup = rate / base[0]
        print(f"{name:8s} {n:7d} {paths:11.3e} {sec:8.2f} {rate:12.4e} {speedup:8.2f} "
              f"{speedup / n:10.2f} {same:>9s}  {', '.join(devices[:n])}", flush=True)
    return all_same


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--backend", default="warp-cuda", choices=["warp-cuda", "opencl", "warp-cpu"])
    ap.add_argument("--devices", default="all",
                    help="'all' (every device of the backend) or a list such as cuda:0,cuda:1")
    ap.add_argument("--scenes", nargs="*", default=["slab", "coated"])
    ap.add_argument("--seconds", type=float, default=5.0,
                    help="approximate time of the one-device run of each scene")
    args = ap.parse_args(argv)
    layersim = _import_checkout()
    from layersim.montecarlo.backends import device_names
    from layersim.montecarlo.executors.devices import parse_devices
    from mc_throughput import SCENES
    unknown = [s for s in args.scenes if s not in SCENES]
    if unknown:
        ap.error(f"unknown scene {unknown[0]!r}; choose from {', '.join(SCENES)}")
    present = device_names(args.backend)
    devices = parse_devices(args.devices) or present
    missing = [d for d in devices if d not in present]
    if present and missing:
        ap.error(f"device {missing[0]!r} is not visible here (visible: {', '.join(present)})")
    print("# multi_gpu.py: walk paths/s on 1..N devices of one host (Devices executor)")
    print(f"# command: python benchmarks/montecarlo/multi_gpu.py {' '.join(argv or sys.argv[1:])}")
    print(f"# machine: {machine(args.backend != 'warp-cpu')}")
    print(f"# date: {time.strftime('%Y-%m-%d %H:%M')}; commit: {commit()}")
    print(f"# layersim {layersim.__version__} from {Path(layersim.__file__).parent}; "
          f"load average (1 min) {os.getloadavg()[0]:.2f}; batch {BATCH[args.backend]} paths")
    if not present:
        print(f"no {args.backend} device is visible here: nothing to measure "
              f"(on a CUDA machine check nvidia-smi and CUDA_VISIBLE_DEVICES)")
        return 0
    if len(devices) == 1:
        print(f"only one {args.backend} device ({devices[0]}) is visible: its paths/s below, "
              "no scaling to show")
    print(f"{'scene':8s} {'devices':>7s} {'paths':>11s} {'seconds':>8s} {'paths/s':>12s} "
          f"{'speed-up':>8s} {'efficiency':>10s} {'tallies':>9s}  devices")
    ok = all([measure(layersim, s, SCENES[s], args.backend, devices, args.seconds)
              for s in args.scenes])
    print(f"# load average (1 min) at the end: {os.getloadavg()[0]:.2f}")
    if not ok:
        print("tallies DIFFER from the one-device run: the split changed the integers")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
