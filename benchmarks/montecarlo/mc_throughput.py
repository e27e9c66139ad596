"""Throughput of the Monte Carlo walk on every backend present (not a test).

Measures paths per second and scattering events per second (medium scatterings plus interface
interactions) for

(a) ``slab``:   an index-matched Henyey-Greenstein slab, albedo 0.95, g 0.5, tau 2;
(b) ``coated``: a coated anisotropic conductor, dielectric eta 1.5, alpha (0.1, 0.2) over gold
                (0.143552 + 3.98397 i), alpha (0.2, 0.1), Beckmann;

both lit at 30 degrees. Each measurement follows a warm-up run (kernel compilation excluded) and
runs for about ``--seconds``. ``cores`` is process CPU time over wall time (CPU backends: how
many cores the run kept busy; the 1-minute load average is recorded too, since other processes
on the machine skew CPU timings). Prints a table and writes JSON (device, versions, command,
results)::

    python benchmarks/montecarlo/mc_throughput.py [--backends warp-cpu opencl] [--seconds 3] \\
        [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

import layersim
import layersim.montecarlo as mc

SCENES = {
    "slab": {"layer": [{"kind": "medium", "albedo": 0.95, "g": 0.5, "tau": 2.0}]},
    "coated": {"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": [0.1, 0.2]},
        {"kind": "conductor", "ior": [0.143552, 3.98397], "roughness": [0.2, 0.1]}]},
}
WI = np.array([math.sin(math.radians(30)), 0.0, math.cos(math.radians(30))])
BATCH = {"warp-cpu": 1 << 18, "opencl": 1 << 20, "warp-cuda": 1 << 26}


def _versions() -> dict:
    import warp as wp
    out = {"python": platform.python_version(), "numpy": np.__version__,
           "warp": wp.__version__, "layersim": layersim.__version__}
    try:
        import pyopencl as cl
        out["pyopencl"] = cl.VERSION_TEXT
    except ImportError:
        pass
    return out


def measure(backend: str, scene, seconds: float) -> dict:
    batch = BATCH[backend]
    mc.simulate(scene, WI, min(batch, 1 << 14), backend=backend, batch_size=batch)  # compile
    n = batch
    while True:                                    # grow until one run lasts ~seconds / 4
        res = mc.simulate(scene, WI, n, backend=backend, batch_size=batch, seed=1)
        if res.seconds >= seconds / 4 or n >= (1 << 34):
            break
        n *= 2 if res.seconds > 0.05 else 8
    n = int(max(n, n * seconds / max(res.seconds, 1e-9)) // batch * batch) or batch
    load = os.getloadavg()[0]
    cpu = time.process_time()
    res = mc.simulate(scene, WI, n, backend=backend, batch_size=batch, seed=2)
    cpu = time.process_time() - cpu
    return {"backend": backend, "device": res.device, "particles": int(res.particles),
            "seconds": res.seconds, "paths_per_s": res.particles / res.seconds,
            "cpu_seconds": cpu, "cores_used": cpu / res.seconds, "load_avg_1min": load,
            "events_per_s": res.events / res.seconds, "events_per_path": res.events / n,
            "reflectance": res.reflectance, "reflectance_stderr": res.reflectance_stderr}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--backends", nargs="*", default=None,
                    help="backends to measure (default: all present)")
    ap.add_argument("--scenes", nargs="*", default=list(SCENES), choices=list(SCENES))
    ap.add_argument("--seconds", type=float, default=3.0, help="approximate time per measurement")
    ap.add_argument("--json", type=Path, default=Path("mc_throughput.json"))
    args = ap.parse_args(argv)
    backends = args.backends or mc.available_backends()
    results = []
    print(f"{'scene':8s} {'backend':10s} {'paths/s':>12s} {'events/s':>12s} {'ev/path':>8s} "
          f"{'cores':>6s}  device")
    for name in args.scenes:
        scene = layersim.Scene.from_dict(SCENES[name])
        for backend in backends:
            r = measure(backend, scene, args.seconds)
            r["scene"] = name
            results.append(r)
            print(f"{name:8s} {backend:10s} {r['paths_per_s']:12.4g} {r['events_per_s']:12.4g} "
                  f"{r['events_per_path']:8.3f} {r['cores_used']:6.2f}  {r['device']}", flush=True)
    ratios = {}
    for name in args.scenes:
        by = {r["backend"]: r for r in results if r["scene"] == name}
        if "opencl" in by and "warp-cpu" in by:
            ratios[name] = by["opencl"]["paths_per_s"] / by["warp-cpu"]["paths_per_s"]
            print(f"{name}: opencl / warp-cpu = {ratios[name]:.2f}")
    report = {"command": " ".join([Path(sys.argv[0]).name] + (argv or sys.argv[1:])),
              "date": time.strftime("%Y-%m-%d %H:%M:%S"), "machine": platform.platform(),
              "processor": platform.processor(), "versions": _versions(),
              "wi": WI.tolist(), "scenes": SCENES, "results": results,
              "opencl_over_warp_cpu": ratios}
    args.json.write_text(json.dumps(report, indent=2))
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
