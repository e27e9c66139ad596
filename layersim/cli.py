"""The ``layersim`` command line.

    layersim plan SCENE              print the discretisation plan (no heavy work)
    layersim solve SCENE [-o FILE]   solve, print plan, timings and albedos; save the BSDF
    layersim info FILE               reload a saved BSDF and print its summary and albedos

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
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
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
