"""The Mitsuba 3 plug-in (layersim.mitsuba): cost per ray against Mitsuba's roughconductor, and
accuracy against roughconductor and roughdielectric.

Cost: wavefronts of 2^16 rays (``llvm_ad_rgb``; median of 5 calls after one warm-up) and single
rays (``scalar_rgb``; 2000 calls), per ray, of ``eval``, ``pdf`` and ``sample`` of rough gold
(eta 0.143552 + 3.98397 i, Beckmann alpha 0.3; the plug-in on the planner's discretisation)
and of Mitsuba's own ``roughconductor`` with the same parameters (``sample_visible`` on).

Accuracy: relative L2 difference of ``eval`` (f |cos theta_o|, radiance mode) over a 24 x 48
(theta_o 1-85 deg, phi_o) grid of each hemisphere, per incidence, for rough conductors (eta 0.2
+ 3i, alpha 0.3 and 0.2 x 0.4) and rough glass (eta 1.5, alpha 0.3) from above and from below,
Beckmann and GGX, at n = 100 / 140 and the planner's n. The last block is the white
furnace: the mean sample weight (luminance, 2^16 samples) against the solver's albedo.

Usage: python benchmarks/features/mitsuba_plugin.py   (needs mitsuba; LLVM >= 16 for the
llvm_ad_rgb rows, found through $DRJIT_LIBLLVM_PATH)
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import layersim

from layersim.mitsuba.llvm import point_drjit_to_llvm

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
from mitsuba_helpers import eval_pdf, grid, sample  # noqa: E402

point_drjit_to_llvm()
import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

import layersim.mitsuba as lsm  # noqa: E402

GOLD = [0.143552, 3.98397]
TMP = Path(tempfile.mkdtemp())


def stack(layers, n=None, name="x"):
    """Solve ``layers`` (at ``n`` ordinates, or the planner's) and save it; (bsdf, path)."""
    d = {"layer": layers} if n is None else {"layer": layers, "discretization": {"n": n}}
    bsdf = layersim.solve(layersim.Scene.from_dict(d))
    path = TMP / f"{name}.lsim"
    bsdf.save(path)
    return bsdf, path


def incident(theta_deg, side=1):
    t = np.radians(theta_deg)
    return np.array([np.sin(t), 0.0, side * np.cos(t)])


def timed(fn, repeat):
    fn()
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def wavefront_costs(bsdfs, n=2**16):
    """Seconds per ray of eval, pdf and sample on one wavefront of ``n`` rays (JIT variant)."""
    rng = np.random.default_rng(0)
    wi = grid(1, 64, 64)[rng.integers(0, 64 * 64, n)]
    wo = grid(1, 64, 64)[rng.integers(0, 64 * 64, n)]
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(np.ascontiguousarray(wi.T, np.float32))
    w = mi.Vector3f(np.ascontiguousarray(wo.T, np.float32))
    u1 = mi.Float(rng.random(n).astype(np.float32))
    u2 = mi.Point2f(rng.random((2, n)).astype(np.float32))
    ctx = mi.BSDFContext()
    rows = []
    for name, b in bsdfs:
        ops = {"eval": lambda: dr.eval(b.eval(ctx, si, w)),
               "pdf": lambda: dr.eval(b.pdf(ctx, si, w)),
               "sample": lambda: dr.eval(b.sample(ctx, si, u1, u2))}
        rows.append((name, {k: timed(f, 5) / n for k, f in ops.items()}))
    return rows


def scalar_costs(bsdfs, calls=2000):
    """Seconds per call of eval, pdf and sample with one ray per call (scalar variant)."""
    rng = np.random.default_rng(0)
    ctx = mi.BSDFContext()
    wi, wo = grid(1, 40, 50)[:calls], grid(1, 50, 40)[::-1][:calls]
    si = [dr.zeros(mi.SurfaceInteraction3f) for _ in range(calls)]
    for s, a in zip(si, wi):
        s.wi = mi.Vector3f(*map(float, a))
    ws = [mi.Vector3f(*map(float, b)) for b in wo]
    us = [(float(x), mi.Point2f(*map(float, y))) for x, y in zip(rng.random(calls),
                                                                 rng.random((calls, 2)))]
    rows = []
    for name, b in bsdfs:
        ops = {"eval": lambda: [b.eval(ctx, s, w) for s, w in zip(si, ws)],
               "pdf": lambda: [b.pdf(ctx, s, w) for s, w in zip(si, ws)],
               "sample": lambda: [b.sample(ctx, s, x, y) for s, (x, y) in zip(si, us)]}
        rows.append((name, {k: timed(f, 1) / calls for k, f in ops.items()}))
    return rows


def cost_report(variant, fn, what):
    mi.set_variant(variant)
    lsm.register()
    bsdf, path = stack([{"kind": "conductor", "ior": GOLD, "roughness": 0.3}], name="gold")
    ours = mi.load_dict({"type": "layersim", "filename": str(path)})
    ref = mi.load_dict({"type": "roughconductor", "distribution": "beckmann", "alpha": 0.3,
                        "eta": GOLD[0], "k": GOLD[1]})
    print(f"\n{variant}: rough gold (Beckmann 0.3), plug-in at the planner's n = "
          f"{bsdf.grid.n}, md = {bsdf.operators[0].m}; {what}")
    print(f"  {'BSDF':16s} {'eval':>12s} {'pdf':>12s} {'sample':>12s}   (nanoseconds per ray)")
    rows = fn([("layersim", ours), ("roughconductor", ref)])
    for name, c in rows:
        print(f"  {name:16s} " + " ".join(f"{c[k] * 1e9:12.1f}" for k in ("eval", "pdf", "sample")))
    ratio = {k: rows[0][1][k] / rows[1][1][k] for k in ("eval", "pdf", "sample")}
    print("  ratio            " + " ".join(f"{ratio[k]:12.0f}" for k in ("eval", "pdf", "sample")))


def rel_l2(ours, ref, wi, wo, mode):
    wis = np.repeat(wi[None], len(wo), 0)
    ctx = mi.BSDFContext(mode)
    a, b = eval_pdf(mi, ours, wis, wo, ctx)[0], eval_pdf(mi, ref, wis, wo, ctx)[0]
    nb = np.linalg.norm(b)
    return np.linalg.norm(a - b) / nb if nb > 0 else float("nan"), float(np.abs(b).max())


ACCURACY = [
    ("conductor 0.2+3i a=0.3", [{"kind": "conductor", "ior": [0.2, 3.0], "roughness": 0.3}],
     {"type": "roughconductor", "alpha": 0.3, "eta": 0.2, "k": 3.0}, (1,), (1,)),
    ("conductor 0.2+3i a=0.2x0.4", [{"kind": "conductor", "ior": [0.2, 3.0],
                                     "roughness": [0.2, 0.4]}],
     {"type": "roughconductor", "alpha_u": 0.2, "alpha_v": 0.4, "eta": 0.2, "k": 3.0}, (1,),
     (1,)),
    ("glass 1.5 a=0.3", [{"kind": "dielectric", "ior": 1.5, "roughness": 0.3}],
     {"type": "roughdielectric", "alpha": 0.3, "int_ior": 1.5, "ext_ior": 1.0}, (1, -1),
     (1, -1)),
]


def accuracy_report():
    print(f"\naccuracy ({mi.variant()}): relative L2 of eval (f |cos theta_o|, radiance mode) "
          "against Mitsuba over a 24 x 48 grid per hemisphere; R: same side, T: other side "
          "(max: Mitsuba's largest value there)")
    for dist in ("beckmann", "ggx"):
        for name, layers, ref, sides, _ in ACCURACY:
            layers = [dict(layers[0], distribution=dist)]
            rb = mi.load_dict(dict(ref, distribution=dist))
            for n in (100, 140, None):
                bsdf, path = stack(layers, n, "acc")
                ours = mi.load_dict({"type": "layersim", "filename": str(path)})
                print(f"{dist:8s} {name:28s} n = {bsdf.grid.n}")
                for side in sides:
                    for th in (0, 30, 60, 75):
                        cols = []
                        for out in sides:
                            e, m = rel_l2(ours, rb, incident(th, side), grid(side * out),
                                          mi.TransportMode.Radiance)
                            cols.append(f"{'RT'[out < 0]} {e * 100:7.3f} % (max {m:8.3g})")
                        print(f"    from {'above' if side > 0 else 'below'} {th:2d} deg: "
                              + "   ".join(cols))


def furnace_report():
    print(f"\nwhite furnace ({mi.variant()}, importance mode): mean luminance of 2^16 sample "
          "weights +- standard error against the solver's albedo R + T")
    cases = [("rough gold", [{"kind": "conductor", "ior": GOLD, "roughness": 0.3}]),
             ("smooth coat over rough gold (delta reflection)",
              [{"kind": "dielectric", "ior": 1.5, "roughness": 0.0},
               {"kind": "conductor", "ior": GOLD, "roughness": 0.3}]),
             ("near-specular coat 0.01 over rough gold",
              [{"kind": "dielectric", "ior": 1.5, "roughness": 0.01},
               {"kind": "conductor", "ior": GOLD, "roughness": 0.3}]),
             ("HG slab tau 0.5 (delta transmission)",
              [{"kind": "medium", "tau": 0.5, "albedo": 0.8, "g": 0.3}]),
             ("rough glass 0.3", [{"kind": "dielectric", "ior": 1.5, "roughness": 0.3}])]
    rng = np.random.default_rng(5)
    n = 2**16
    for name, layers in cases:
        bsdf, path = stack(layers, None, "furnace")
        ours = mi.load_dict({"type": "layersim", "filename": str(path)})
        for th in (10, 45, 75):
            wi = incident(th)
            s = sample(mi, ours, np.repeat(wi[None], n, 0), rng.random(n), rng.random((n, 2)),
                       mi.BSDFContext(mi.TransportMode.Importance))
            y = s["weight"] @ np.array([0.212671, 0.715160, 0.072169])
            R, T = (float(np.atleast_1d(x)[0]) for x in bsdf.albedo(wi))
            se = y.std() / np.sqrt(n)
            # Nearly constant weights (perfect importance sampling of the smooth part, deltas
            # in proportion to their energy) leave the difference between the interpolated
            # series' integral and the quadrature albedo, not Monte Carlo noise.
            spread = y.std() / abs(y.mean())
            sig = (f" (weights constant to {spread:.0e})" if spread < 1e-3
                   else f" ({(y.mean() - R - T) / se:+.2f} se)")
            print(f"  {name:48s} n = {bsdf.grid.n:3d} {th:2d} deg: mean {y.mean():.5f} +- "
                  f"{se:.5f}, R + T {R + T:.5f}, diff {y.mean() - R - T:+.5f}{sig}")


def main():
    print(f"mitsuba {mi.__version__}, drjit {dr.__version__}; DRJIT_LIBLLVM_PATH="
          f"{os.environ.get('DRJIT_LIBLLVM_PATH')}")
    cost_report("llvm_ad_rgb", wavefront_costs, "one wavefront of 2^16 rays per call, median "
                "of 5 calls")
    cost_report("scalar_rgb", scalar_costs, "one ray per call, 2000 calls")
    mi.set_variant("llvm_ad_rgb")
    lsm.register()
    accuracy_report()
    furnace_report()


if __name__ == "__main__":
    main()
