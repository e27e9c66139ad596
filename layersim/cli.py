"""The ``layersim`` command line.

    layersim plan SCENE              print the discretisation plan (no heavy work)
    layersim solve SCENE [-o FILE]   solve, print plan, timings and albedos; save the BSDF
    layersim info FILE               reload a saved BSDF and print its summary and albedos
    layersim bench [--quick] [--stability] [--backend B ...] --out DIR
                                     solver vs Monte Carlo report and stability suite

Errors in the input print one line (``layersim: error: ...``) and exit with status 2.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from .errors import LayersimError

EXIT_INPUT = 2


def _scene(path):
    from .scene import Scene
    return Scene.from_toml(path)


def cmd_plan(args) -> int:
    from .plan import make_plan
    scene = _scene(args.scene)
    print(scene.describe())
    print(make_plan(scene).report())
    return 0


def _albedo_table(bsdf, angles) -> str:
    rows = []
    th = np.radians(angles)
    wi = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], axis=-1)
    R, T = bsdf.albedo(wi)
    R, T = np.atleast_2d(R.T).T if R.ndim == 1 else R, np.atleast_2d(T.T).T if T.ndim == 1 else T
    head = "  theta_i   " + ("R          T" if bsdf.channels == 1 else
                             "R (r, g, b)                    T (r, g, b)")
    rows.append(head)
    for k, a in enumerate(angles):
        r = " ".join(f"{v:.5f}" for v in np.atleast_1d(R[k]))
        t = " ".join(f"{v:.5f}" for v in np.atleast_1d(T[k]))
        rows.append(f"  {a:5.1f}    {r}   {t}")
    return "\n".join(rows)


def cmd_solve(args) -> int:
    from .solver import solve
    scene = _scene(args.scene)
    print(scene.describe())
    bsdf = solve(scene, verbose=True)
    info = bsdf.info
    print(f"stack: {info['nnz']} nonzero coefficients, {info['memory_bytes'] / 2**20:.1f} MiB")
    print("albedo (energy fractions):")
    print(_albedo_table(bsdf, [0.0, 30.0, 60.0, 80.0, 89.0]))
    out = Path(args.output) if args.output else Path(Path(args.scene).stem + ".lsim")
    bsdf.save(out)
    print(f"wrote {out} (reload with layersim.BSDF.load)")
    return 0


def cmd_info(args) -> int:
    from .bsdf import BSDF
    bsdf = BSDF.load(args.file)
    info = bsdf.info
    op = bsdf.operators[0]
    print(f"{args.file}: scene '{info.get('scene', '?')}', {bsdf.channels} channel(s), "
          f"{'opaque' if bsdf.opaque else 'transmissive'}")
    print(f"discretisation: n = {op.grid.n} ({op.grid.rule}), md = {op.m}; "
          f"{sum(o.nnz() for o in bsdf.operators)} nonzero coefficients, "
          f"{sum(o.memory_bytes() for o in bsdf.operators) / 2**20:.1f} MiB")
    if "seconds" in info:
        print(f"solved in {info['seconds']['total']:.2f} s")
    print("albedo (energy fractions):")
    print(_albedo_table(bsdf, [0.0, 30.0, 60.0, 80.0, 89.0]))
    return 0


def cmd_bench(args) -> int:
    from . import bench
    results = bench.run(args.out, quick=args.quick, stability=args.stability,
                        backends=args.backend or ("auto",), scene_dir=args.scenes,
                        scenes=args.scene, command="layersim " + " ".join(args.argv))
    fails = [c["name"] for c in results["stability"] if c["outcome"] == "fail"]
    print(f"wrote {args.out}/results.json, report.md and plots")
    if fails:
        print(f"stability failures: {', '.join(fails)}", file=sys.stderr)
        return 1
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="layersim", description="Reflectance of layered materials")
    sub = p.add_subparsers(dest="command", required=True)
    sp = sub.add_parser("plan", help="print the discretisation plan of a scene")
    sp.add_argument("scene", help="scene file (TOML)")
    sp.set_defaults(func=cmd_plan)
    sp = sub.add_parser("solve", help="solve a scene with the adding equations")
    sp.add_argument("scene", help="scene file (TOML)")
    sp.add_argument("-o", "--output", help="where to save the solved BSDF (default: "
                                           "SCENE_STEM.lsim in the current directory)")
    sp.set_defaults(func=cmd_solve)
    sp = sub.add_parser("info", help="reload a saved BSDF (.lsim) and print its summary")
    sp.add_argument("file", help="file written by 'layersim solve'")
    sp.set_defaults(func=cmd_info)
    sp = sub.add_parser("bench", help="benchmark report: solver vs Monte Carlo, stability suite")
    sp.add_argument("--out", required=True, help="output folder")
    sp.add_argument("--quick", action="store_true", help="small version (< 2 min on 2 cores)")
    sp.add_argument("--stability", action="store_true", help="also run the stability suite")
    sp.add_argument("--backend", action="append", help="Monte Carlo backend(s) to time "
                    "(auto, warp-cpu, warp-cuda, opencl); repeatable")
    sp.add_argument("--scenes", help="folder of scene files (default benchmarks/scenes)")
    sp.add_argument("--scene", action="append", help="run only this scene (file stem); "
                    "repeatable")
    sp.set_defaults(func=cmd_bench)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(argv)
    args.argv = argv
    try:
        return args.func(args)
    except (LayersimError, ValueError, OSError) as exc:
        msg = str(exc).replace("\n", " ")
        print(f"layersim: error: {msg}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        print("layersim: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
