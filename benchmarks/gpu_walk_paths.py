"""The walk's newer paths on a GPU against the solver: energy compensation (both terms), a
tabulated NDF, a measured (MERL layout) base and a near-specular conductor under a coat.

For each stack, albedos at 30 and 60 degrees from the solver and from the ``warp-cuda`` walk
(``paths`` per direction), and their difference in standard errors.

Usage (on a machine with CUDA and Warp): python benchmarks/gpu_walk_paths.py [paths] [backend]
(default 1e8, warp-cuda). Output of a run on an NVIDIA H100: benchmarks/gpu_walk_paths.txt.
"""
import os
import sys
import tempfile
import time

import numpy as np

import layersim
import layersim.montecarlo as mc
from layersim.merl import write_merl
from layersim.ndf.table import sampled_table

GOLD = [0.143552, 3.98397]
tmp = tempfile.mkdtemp()


def beck(th, ph, au=0.3, av=0.15):
    """Anisotropic Beckmann NDF (1/sr) at (theta_h, phi_h)."""
    t2 = np.tan(th) ** 2
    return (np.exp(-t2 * (np.cos(ph) ** 2 / au**2 + np.sin(ph) ** 2 / av**2))
            / (np.pi * au * av * np.cos(th) ** 4))


tab = sampled_table(beck)
np.savez(os.path.join(tmp, "b.npz"), theta=tab.theta, phi=tab.phi, D=tab.D)
ALPHA = 0.3


def analytic(th, td, pd):
    """A glossy isotropic BRDF in half/difference angles (1/sr), three channels (as
    tests/test_measured.py)."""
    th, td, pd = np.broadcast_arrays(th, td, pd)
    d = np.exp(-np.tan(th) ** 2 / ALPHA ** 2) / (np.pi * ALPHA ** 2 * np.cos(th) ** 4)
    spec = 0.2 * d * (1.0 + 0.5 * (1.0 - np.cos(td)) ** 5)
    return (np.array([0.1, 0.2, 0.3])[:, None] / np.pi
            + np.array([1.0, 0.8, 0.6])[:, None] * spec.reshape(1, -1)).reshape(3, *th.shape)


write_merl(os.path.join(tmp, "m.binary"), analytic)
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
