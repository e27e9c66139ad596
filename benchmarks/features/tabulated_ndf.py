"""Tabulated NDFs and measured bases against their analytic counterparts (docs/method.md,
"Tabulated NDFs and measured bases"): solver eval error, albedos and solve time.

Usage: .venv/bin/python benchmarks/features/tabulated_ndf.py > benchmarks/features/tabulated_ndf.txt
"""

import os
import platform
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "tests"))

import layersim                                    # noqa: E402
from layersim.layers.merl import half_diff, read_merl, write_merl     # noqa: E402
from test_measured import analytic as glossy        # noqa: E402
from test_tabulated_ndf import beckmann, ggx        # noqa: E402
from layersim.ndf import sampled_table              # noqa: E402

RNG = np.random.default_rng(0)


def upper(n):
    v = RNG.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 0.05
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def rel_l2(fa, fb):
    big = np.abs(fa) > 0.01 * np.abs(fa).max()
    return np.linalg.norm((fa - fb)[big]) / np.linalg.norm(fa[big])


def main():
    print(f"# machine: shared 2-core CI VM ({platform.machine()}); "
          "command: .venv/bin/python benchmarks/features/tabulated_ndf.py")
    tmp = tempfile.mkdtemp()
    wi, wo = upper(4000), upper(4000)
    for name, fn in (("beckmann", beckmann), ("ggx", ggx)):
        tab = sampled_table(fn, 91, 180)
        path = os.path.join(tmp, f"{name}.npz")
        np.savez(path, theta=tab.theta, phi=tab.phi, D=tab.D)
        for coat, disc in ((False, {"n": 40, "md": 40}), (True, None)):
            layers = [{"kind": "dielectric", "ior": 1.5, "roughness": 0.2}] if coat else []
            scenes = [{"layer": layers + [{"kind": "conductor", "ior": [0.2, 3.0], **extra}]}
                      for extra in ({"roughness": [0.3, 0.15], "distribution": name},
                                    {"distribution": "tabulated", "ndf": path})]
            if disc:
                for s in scenes:
                    s["discretization"] = disc
            times, bsdfs = [], []
            for s in scenes:
                t0 = time.perf_counter()
                bsdfs.append(layersim.solve(s))
                times.append(time.perf_counter() - t0)
            plan = layersim.make_plan(scenes[1])
            w = np.array([np.sin(0.7), 0.0, np.cos(0.7)])
            print(f"{name} (0.3, 0.15) conductor{' under a 0.2 coat' if coat else ''}, "
                  f"n = {plan.n}, md = {plan.md}, ms = {plan.ms}: eval rel L2 "
                  f"{rel_l2(bsdfs[0].eval(wi, wo), bsdfs[1].eval(wi, wo)):.2e}, albedo(40 deg) "
                  f"{float(bsdfs[0].albedo(w)[0]):.5f} analytic {float(bsdfs[1].albedo(w)[0]):.5f} "
                  f"table; solve {times[0]:.1f} s analytic, {times[1]:.1f} s table")
    path = os.path.join(tmp, "glossy.binary")
    write_merl(path, glossy)
    wi, wo = upper(20000), upper(20000)
    ref = glossy(*half_diff(wi, wo))
    big = ref > 0.01 * ref.max(axis=-1, keepdims=True)
    within = big & (np.minimum(wi[:, 2], wo[:, 2]) >= np.cos(np.radians(85.0)))[None]

    def report(what, f, extra=""):
        rel = np.abs(f - ref) / ref
        print(f"  {what}: worst {rel[within].max():.2%} (both within 85 deg of the normal), "
              f"{rel[big].max():.2%} (all), RMS {np.sqrt(np.mean(rel[big] ** 2)):.2%}{extra}")

    print("MERL file of a glossy analytic BRDF (tests/test_measured.py), 20000 pairs, where "
          "f > 1 % of its peak:")
    report("table lookup", read_merl(path).eval(wi, wo))
    for n in (None, 96, 128):
        scene = {"layer": [{"kind": "measured", "file": path}]}
        if n:
            scene["discretization"] = {"n": n}
        t0 = time.perf_counter()
        b = layersim.solve(scene)
        dt = time.perf_counter() - t0
        report(f"solver n = {layersim.make_plan(scene).n}", np.moveaxis(b.eval(wi, wo), -1, 0),
               f"; solve {dt:.1f} s")


if __name__ == "__main__":
    main()
