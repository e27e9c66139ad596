"""A tabulated NDF against the analytic one it samples, in the solver and the walk: anisotropic
Beckmann (0.3, 0.15) gold alone and under a coat (alpha 0.2), albedos at 30 and 60 degrees (incident
azimuth 0.3 rad), the solver's and the walk's, and their difference. Where the table's offsets
from the walk equal the analytic lobe's, they are the plan's, not the table's.

Usage: python benchmarks/features/gpu_tabulated_vs_analytic.py PATHS BACKEND (e.g. 1e8 warp-cuda).
Output of a run on an NVIDIA H100: benchmarks/features/gpu_tabulated_vs_analytic.txt.
"""
import os
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "tests"))

import layersim                                    # noqa: E402
import layersim.montecarlo as mc                   # noqa: E402
from layersim.ndf.table import sampled_table       # noqa: E402
from test_tabulated_ndf import beckmann            # noqa: E402

GOLD = [0.143552, 3.98397]
tmp = tempfile.mkdtemp()
tab = sampled_table(beckmann)          # alpha (0.3, 0.15)
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
