"""The walk's newer paths on a GPU against the solver: energy compensation (both terms), a
tabulated NDF, a measured (MERL layout) base and a near-specular conductor under a coat.

For each stack, albedos at 30 and 60 degrees from the solver and from the ``warp-cuda`` walk
(``paths`` per direction), and their difference in standard errors.

Usage (on a machine with CUDA and Warp): python benchmarks/montecarlo/gpu_walk_paths.py [paths]
[backend] (default 1e8, warp-cuda). Output of a run on an NVIDIA H100:
benchmarks/montecarlo/gpu_walk_paths.txt.
"""
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "tests"))

import layersim                                    # noqa: E402
import layersim.montecarlo as mc                   # noqa: E402
from layersim.layers.merl import write_merl               # noqa: E402
from layersim.ndf.table import sampled_table       # noqa: E402
from test_measured import analytic as glossy       # noqa: E402
from test_tabulated_ndf import beckmann            # noqa: E402

GOLD = [0.143552, 3.98397]
tmp = tempfile.mkdtemp()
tab = sampled_table(beckmann)          # alpha (0.3, 0.15)
np.savez(os.path.join(tmp, "b.npz"), theta=tab.theta, phi=tab.phi, D=tab.D)
write_merl(os.path.join(tmp, "m.binary"), glossy)
coat = {"kind": "dielectric", "ior": 1.5, "roughness": 0.2}
scenes = {
    "8 rough glass/air, multiple-scattering": {
        "stack": {"energy_compensation": "multiple-scattering"},
        "layer": [{"kind": "dielectric", "ior": 1.5 if k % 2 == 0 else 1.0, "roughness": 0.3}
                  for k in range(8)]},
    "coat over gold 0.2, layerlab": {
        "stack": {"energy_compensation": "layerlab"},
        "layer": [coat, {"kind": "conductor", "ior": GOLD, "roughness": 0.2}]},
    "coat over tabulated gold (0.3, 0.15)": {
        "layer": [coat, {"kind": "conductor", "ior": GOLD, "distribution": "tabulated",
                         "ndf": os.path.join(tmp, "b.npz")}]},
    "coat over MERL base (channel 0)": {
        "layer": [coat, {"kind": "measured", "file": os.path.join(tmp, "m.binary")}]},
    "gold 0.005 under coat 0.1": {
        "layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.1},
                  {"kind": "conductor", "ior": GOLD, "roughness": 0.005}]},
}
paths = int(float(sys.argv[1])) if len(sys.argv) > 1 else 100_000_000
backend = sys.argv[2] if len(sys.argv) > 2 else "warp-cuda"
for name, sc in scenes.items():
    scene = layersim.Scene.from_dict(sc)
    t0 = time.perf_counter()
    b = layersim.solve(scene)
    ts = time.perf_counter() - t0
    for th in (30.0, 60.0):
        wi = np.array([np.sin(np.radians(th)), 0.0, np.cos(np.radians(th))])
        R, T = (np.atleast_1d(x)[0] for x in b.albedo(wi))
        mono = scene.channel(0) if scene.channels > 1 else scene
        t0 = time.perf_counter()
        res = mc.simulate(mono, wi, paths, backend=backend, seed=5)
        tm = time.perf_counter() - t0
        r, t = float(np.atleast_1d(res.reflectance)[0]), float(np.atleast_1d(res.transmittance)[0])
        sr = float(np.atleast_1d(res.reflectance_stderr)[0])
        st = float(np.atleast_1d(res.transmittance_stderr)[0])
        print(f"{name:40s} {th:4.0f} deg  solver R {R:.5f} T {T:.5f} | cuda R {r:.5f}+-{sr:.1e} "
              f"T {t:.5f}+-{st:.1e}  dR {(R - r) / max(sr, 1e-12):+.1f} se dT "
              f"{(T - t) / max(st, 1e-12):+.1f} se  (solve {ts:.1f} s, mc {tm:.1f} s)", flush=True)
