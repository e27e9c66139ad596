"""The ``layersim`` command line.

    layersim plan SCENE              print the discretisation plan (no heavy work)
    layersim solve SCENE [-o FILE]   solve, print plan, timings and albedos; save the BSDF
    layersim subtract STACK KNOWN --side top|bottom [-o FILE] [--eps EPS] [--noise NOISE]
                                     recover the unknown layer of a solved two-layer stack

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


# --- subtracting equations (layersim.subtract) ---------------------------------------------

def cmd_subtract(args) -> int:
    from .bsdf import BSDF
    from .subtract import subtract
    stack = BSDF.load(args.stack)
    known = BSDF.load(args.known)
    result = subtract(stack, known, side=args.side, eps=args.eps, noise=args.noise)
    infos = result.info["subtract"]
    for c, info in enumerate(infos if isinstance(infos, list) else [infos]):
        tag = f"channel {c}: " if isinstance(infos, list) else ""
        print(f"{tag}eps = {info['eps']:.3g} ({info['method']}); noise level "
              f"{info['noise']:.3g} ({info['noise_source']}); re-adding residual "
              f"{info['residual']:.3g}; visible {100 * info['visible']:.0f} % of the angular "
              f"components; largest R + T {info['energy_max']:.4f}")
    print("albedo of the recovered layer (energy fractions):")
    print(_albedo_table(result, [0.0, 30.0, 60.0, 80.0, 89.0]))
    out = Path(args.output) if args.output else Path(
        f"{Path(args.stack).stem}-minus-{Path(args.known).stem}.lsim")
    result.save(out)
    print(f"wrote {out} (reload with layersim.BSDF.load)")
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
    sp = sub.add_parser("subtract", help="recover the unknown layer of a solved stack "
                                         "(subtracting equations)")
    sp.add_argument("stack", help="solved stack (.lsim written by 'layersim solve')")
    sp.add_argument("known", help="solved known layer, same discretisation (solve it with "
                                  "layersim.solve(scene, like=stack))")
    sp.add_argument("--side", choices=("top", "bottom"), required=True,
                    help="where the known layer sits in the stack")
    sp.add_argument("-o", "--output", help="where to save the recovered layer (default: "
                                           "STACK-minus-KNOWN.lsim)")
    sp.add_argument("--eps", type=float, help="Tikhonov parameter (default: automatic, "
                                              "discrepancy principle)")
    sp.add_argument("--noise", type=float, help="relative noise level of the stack (default: "
                                                "estimated from its reciprocity defect)")
    sp.set_defaults(func=cmd_subtract)
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
