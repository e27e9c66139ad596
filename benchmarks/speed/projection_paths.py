"""Error against run time of the two projection paths for the same interface.

* semi-analytic (host): exact peak series x fitted smooth factor (``layersim.ingredients``);
* numeric: the kernel samples the BSDF on a uniform azimuth grid (at most ``max_samples`` per
  pair), then an FFT (CPU) or a table-driven DFT kernel (CUDA). On CUDA the whole operator is
  also assembled on the device (the default there; ``assembly device``), and, for comparison,
  with the series copied back and assembled on the host (``assembly host``).

Reference: the numeric path with at least 16384 and up to 65536 samples per pair (every pair
sampled far past the length of its series: only rounding, the 1e-12 aliasing bound and the slow
convergence at Fresnel kinks remain, the last ~1e-6 relative). Error: relative L2 over all
blocks and orders of the operator entries B_l[o, i] (energy-weighted coefficients).

Target: on a GPU, the numeric path at equal error >= 10x faster than the host
semi-analytic path. Usage::

    python benchmarks/speed/projection_paths.py [--n 196] [--md 247] [--devices cpu cuda] [--json F]
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np

from layersim.ingredients import interface_operator
from layersim.ingredients.microfacet import ProjectionStats
from layersim.ingredients.numeric import numeric_interface_operator
from layersim.kernels.runtime import cuda_available, device_for
from layersim.operators.operator import Grid
from layersim.scene import Conductor, Dielectric

LAYERS = {
    "dielectric eta 1.5 alpha 0.1": (Dielectric(ior=1.5, alpha_u=0.1, alpha_v=0.1), 1.0),
    "gold alpha 0.1 under eta 1.5": (
        Conductor(ior=complex(0.143552, 3.98397), alpha_u=0.1, alpha_v=0.1), 1.5),
}


def error(op, ref) -> float:
    num = den = 0.0
    for name, blk in ref.blocks.items():
        if blk is None:
            continue
        for l in range(ref.m):
            d = (op.block(name, l) - blk[l])
            num += float(d.multiply(d).sum())
            den += float(blk[l].multiply(blk[l]).sum())
    return float(np.sqrt(num / den))


def timed(fn, repeat):
    """Best of ``repeat`` runs of ``fn(stats)``: (result, seconds, series seconds)."""
    best, out, series = np.inf, None, np.nan
    for _ in range(repeat):
        stats = ProjectionStats()
        t0 = time.perf_counter()
        out = fn(stats)
        sec = time.perf_counter() - t0
        if sec < best:
            best, series = sec, stats.series_seconds
    return out, best, series


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=196)
    ap.add_argument("--md", type=int, default=247)
    ap.add_argument("--devices", nargs="+", default=None)
    ap.add_argument("--samples", nargs="+", type=int, default=[128, 256, 512, 1024, 4096, 16384])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--json")
    args = ap.parse_args()
    devices = args.devices or (["cpu", "cuda"] if cuda_available() else ["cpu"])
    grid = Grid.make("gauss-lobatto", args.n)
    rows = []
    for label, (layer, eta_above) in LAYERS.items():
        ref_dev = "cuda" if "cuda" in devices else "cpu"
        ref = numeric_interface_operator(grid, args.md, layer, eta_above, device=ref_dev,
                                         max_samples=1 << 16, min_samples=1 << 14)
        interface_operator(grid, 8, layer, eta_above)          # warm-up (kernel compilation)
        op, sec, ser = timed(lambda st: interface_operator(grid, args.md, layer, eta_above, st),
                             args.repeat)
        rows.append({"layer": label, "path": "semi-analytic", "device": "cpu (host)",
                     "samples": None, "seconds": sec, "series_seconds": ser,
                     "error": error(op, ref)})
        print(f"{label:32s} semi-analytic  host        {sec:8.3f} s  (series {ser:7.3f} s)  "
              f"error {rows[-1]['error']:.2e}", flush=True)
        for dev in devices:
            # on CUDA both assemblies: on the device (the default there) and on the host
            variants = [True, False] if device_for(dev).is_cuda else [False]
            for on_device in variants:
                numeric_interface_operator(grid, 8, layer, eta_above, device=dev, max_samples=64,
                                           on_device=on_device)
                where = "device" if on_device else "host"
                for cap in args.samples:
                    op, sec, ser = timed(lambda st: numeric_interface_operator(
                        grid, args.md, layer, eta_above, st, device=dev, max_samples=cap,
                        on_device=on_device), args.repeat)
                    rows.append({"layer": label, "path": "numeric", "device": str(device_for(dev)),
                                 "assembly": where, "samples": cap, "seconds": sec,
                                 "series_seconds": ser, "error": error(op, ref)})
                    print(f"{label:32s} numeric {cap:6d} {dev:6s} {where:6s} {sec:8.3f} s  "
                          f"(series {ser:7.3f} s)  error {rows[-1]['error']:.2e}", flush=True)
    summary = []
    for label in LAYERS:
        semi = next(r for r in rows if r["layer"] == label and r["path"] == "semi-analytic")
        for dev in devices:
            where = "device" if device_for(dev).is_cuda else "host"
            ok = [r for r in rows if r["layer"] == label and r["path"] == "numeric"
                  and r["device"] == str(device_for(dev)) and r["assembly"] == where
                  and r["error"] <= semi["error"]]
            if ok:
                best = min(ok, key=lambda r: r["seconds"])
                summary.append(f"{label}: numeric on {best['device']} at equal error "
                               f"({best['error']:.1e} <= {semi['error']:.1e}, {best['samples']} "
                               f"samples) is {semi['seconds'] / best['seconds']:.1f}x the speed "
                               "of the host semi-analytic path end to end, "
                               f"{semi['series_seconds'] / best['series_seconds']:.1f}x on the "
                               "series alone (semi-analytic: thread-seconds, all cores; "
                               f"numeric: {where} assembly)")
            else:
                summary.append(f"{label}: numeric on {dev} never reached the semi-analytic "
                               f"error {semi['error']:.1e} within {max(args.samples)} samples")
    print("\n".join(summary))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"machine": {"cpu": platform.processor() or platform.machine(),
                                   "python": platform.python_version()},
                       "command": "python benchmarks/speed/projection_paths.py " + " ".join(
                           f"--{k} {v}" for k, v in vars(args).items() if v),
                       "n": args.n, "md": args.md, "rows": rows, "summary": summary}, fh,
                      indent=1)


if __name__ == "__main__":
    main()
