"""RGL tensor export (Mitsuba 3 / pbrt-v4 ``measured``): reconstruction error against
resolution, file size and export time, for four stacks: gold under a rough lacquer (one
channel, examples/coated_gold.toml), an RGB gold under a rough lacquer written as spectra
(the sRGB basis of layersim.bsdffile.rgl_color), a rough lacquer over a scattering medium
over a diffuse base, and an anisotropic rotated gold under a rough lacquer.

The error is :func:`layersim.bsdffile.rgl.reconstruction_error`: relative L2 of
``f cos(theta_o)`` of the file (evaluated as Mitsuba 3 and pbrt-v4 evaluate it; the tests check
that against Mitsuba's own ``eval``) against the solved BSDF, over direction pairs with ``wi``
cosine-distributed and ``wo`` half from the BSDF's sampler, half uniform; two seeds of 8192
pairs each show how much the estimate itself scatters (a few grazing pairs dominate it);
"to 80 deg" is the same estimate with ``wi`` within 80 degrees of the normal.
The time is the export's (NDF, warp, tabulation, writing), not the error estimate's.

Choice of the default resolution (32, :data:`layersim.bsdffile.rgl.DEFAULT_RESOLUTION`),
from rgl_export.txt (2-core VM): going from 16 to 32 the error falls 1.5-2x (coated gold 7.5
-> 5.0 %, 3.6 % for incidence within 80 degrees; the coated diffuse base 41 -> 24 %, 11 %
within 80 degrees; anisotropic 14 -> 10 %), from 32 to 48 only 1.1-1.7x while the file grows
3.4x (isotropic; ``n^3``) and the export takes 3-4x as long; anisotropic files grow as
``n^4`` (7.5 MiB and about 2 minutes at 32 on the VM, most of it the solved BSDF's own
evaluation). At 32 an isotropic one-channel file is 0.44 MiB (1.1 MiB RGB as spectra).
The last block compares the design choices (incident-elevation spacing, the NDF's floor,
the least-squares fit) at 32, one at a time.

Usage: python benchmarks/features/rgl_export.py [--quick]
"""

from __future__ import annotations

import datetime
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parents[1])]
from headline import commit, machine  # noqa: E402

import layersim  # noqa: E402
from layersim.bsdffile import rgl  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
GOLD_RGB = [[0.143552, 3.98397], [0.377438, 2.38495], [1.43825, 1.60434]]
STACKS = {
    "coated gold (1 channel)": (ROOT / "examples/coated_gold.toml", (8, 16, 24, 32, 48, 64)),
    "coated gold, RGB as spectra": ({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.1},
        {"kind": "conductor", "ior": GOLD_RGB, "roughness": 0.1}]}, (8, 16, 32, 48)),
    "lacquer (0.1) over HG (tau 1, albedo 0.9, g 0.5) over diffuse (0.5)": ({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.1},
        {"kind": "medium", "tau": 1.0, "albedo": 0.9, "g": 0.5},
        {"kind": "diffuse", "albedo": 0.5}]}, (8, 16, 32, 48)),
    "anisotropic gold (0.1, 0.3; 30 deg) under lacquer (0.15)": ({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.15},
        {"kind": "conductor", "ior": [0.2, 3.9], "roughness": [0.1, 0.3], "rotation": 30}]},
        (8, 16, 32)),
}


def header(argv: str) -> None:
    """The command, machine, date and commit of this output (``benchmarks/headline.py``)."""
    device = os.environ.get("LAYERSIM_DEVICE", "cpu")
    print(f"# python benchmarks/features/rgl_export.py {argv}".rstrip())
    print(f"# machine: {machine(device != 'cpu')}")
    print(f"# date: {datetime.date.today().isoformat()}; commit: {commit()}; "
          f"LAYERSIM_DEVICE={device}")


def study(label: str, scene, resolutions, folder: Path) -> None:
    t0 = time.perf_counter()
    bsdf = layersim.solve(scene)
    print(f"{label}: solved in {time.perf_counter() - t0:.1f} s "
          f"(n = {bsdf.plan.n}, md = {bsdf.plan.md}, {bsdf.channels} channel(s))")
    print("  resolution  error (seed 0, seed 1)  error to 80 deg   file size     export time")
    for n in resolutions:
        res = rgl.export(bsdf, folder / f"x{n}.bsdf", resolution=n)
        err1 = rgl.reconstruction_error(bsdf, res.table, seed=1)
        err80 = rgl.reconstruction_error(bsdf, res.table, max_theta_i=np.radians(80.0))
        print(f"  {n:10d}  {res.error:8.4f}  {err1:8.4f}      {err80:8.4f}"
              f"     {res.bytes / 2**20:8.2f} MiB"
              f"   {res.seconds:8.1f} s", flush=True)


#: Design choices compared at resolution 32, one changed at a time from the defaults.
CHOICES = [("defaults (grazing spacing, floor 1e-3, fit 2 x 2 per cell)", {}),
           ("incident elevations uniform", {"theta_spacing": "uniform"}),
           ("incident elevations uniform in cosine", {"theta_spacing": "cosine"}),
           ("NDF floor 0", {"ndf_floor": 0.0}),
           ("NDF floor 1e-2", {"ndf_floor": 1e-2}),
           ("node values, no fit", {"per_cell": 0}),
           ("fit 1 x 1 per cell", {"per_cell": 1}),
           ("fit 3 x 3 per cell", {"per_cell": 3})]


def choices(labels) -> None:
    """The error of each design choice (:data:`CHOICES`) for the stacks ``labels``."""
    for label in labels:
        bsdf = layersim.solve(STACKS[label][0])
        print(f"{label}, resolution 32: error (seed 0, seed 1, to 80 deg), build time")
        for name, kw in CHOICES:
            t0 = time.perf_counter()
            table = rgl.build(bsdf, 32, **kw)
            dt = time.perf_counter() - t0
            errs = [rgl.reconstruction_error(bsdf, table, seed=s) for s in (0, 1)]
            err80 = rgl.reconstruction_error(bsdf, table, max_theta_i=np.radians(80.0))
            print(f"  {name:58s} {errs[0]:.4f} {errs[1]:.4f} {err80:.4f}  {dt:6.1f} s",
                  flush=True)


def main() -> None:
    quick = "--quick" in sys.argv[1:]
    header(" ".join(sys.argv[1:]))
    with tempfile.TemporaryDirectory() as tmp:
        for label, (scene, resolutions) in STACKS.items():
            study(label, scene, resolutions[:2] if quick else resolutions, Path(tmp))
    if not quick:
        choices([k for k in STACKS if "1 channel" in k or "HG" in k])


if __name__ == "__main__":
    main()
