"""A tabulated NDF against the analytic one it samples, in the solver and the walk: anisotropic
Beckmann (0.3, 0.15) gold alone and under a coat (alpha 0.2), albedos at 30 and 60 degrees (incident
azimuth 0.3 rad), the solver's and the walk's, and their difference. Where the table's offsets
from the walk equal the analytic lobe's, they are the plan's, not the table's.

Usage: python benchmarks/gpu_tabulated_vs_analytic.py PATHS BACKEND (e.g. 1e8 warp-cuda).
Output of a run on an NVIDIA H100: benchmarks/gpu_tabulated_vs_analytic.txt.
"""
import os
import sys
import tempfile

import numpy as np

import layersim
import layersim.montecarlo as mc
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
coat = {"kind": "dielectric", "ior": 1.5, "roughness": 0.2}
paths = int(float(sys.argv[1]))
backend = sys.argv[2]
for label, layers in (("alone", []), ("coated", [coat])):
    for kind, base in (("analytic", {"kind": "conductor", "ior": GOLD, "roughness": [0.3, 0.15]}),
                       ("table", {"kind": "conductor", "ior": GOLD, "distribution": "tabulated",
                                  "ndf": os.path.join(tmp, "b.npz")})):
        sc = layersim.Scene.from_dict({"layer": layers + [base]})
        b = layersim.solve(sc)
        for th in (30.0, 60.0):
            t = np.radians(th)
            wi = np.array([np.sin(t) * np.cos(0.3), np.sin(t) * np.sin(0.3), np.cos(t)])
            R = float(b.albedo(wi)[0])
            res = mc.simulate(sc, wi, paths, backend=backend, seed=9)
            print(f"{label:7s} {kind:9s} {th:4.0f}: solver {R:.5f} (n {b.info['n']} md "
                  f"{b.info['md']} ms {b.info['ms']})  mc {res.reflectance:.5f} +- "
                  f"{res.reflectance_stderr:.1e}  diff {R - res.reflectance:+.1e}", flush=True)
