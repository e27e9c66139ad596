"""The ``layersim`` command line.

    layersim plan SCENE              print the discretisation plan (no heavy work)
    layersim solve SCENE [-o FILE]   solve, print plan, timings and albedos; save the BSDF
    layersim info FILE               reload a saved BSDF and print its summary and albedos
    layersim bench [--quick] [--stability] [--backend B ...] --out DIR
                                     solver vs Monte Carlo report and stability suite
    layersim export SRC [-o F.bsdf] [--version 1|2]
                                     write a tabulated Fourier BSDF file (v1: layerlab/Mitsuba
                                     0.6/pbrt-v3; v2, anisotropic: the Layer Laboratory)
    layersim eval SRC --wi X,Y,Z --wo X,Y,Z     print f(wi, wo) (per channel for RGB)
    layersim plot SRC (--wi THETA,PHI | --blocks) [-o F.png]   draw slices or operator blocks
    layersim subtract STACK KNOWN --side top|bottom [-o FILE] [--eps EPS] [--noise NOISE]
                                     recover the unknown layer of a solved two-layer stack

SRC is a scene (``.toml``, solved on the fly), a saved BSDF (``.lsim`` from ``solve -o``) or a
``.bsdf`` file.

Errors in the input print one line (``layersim: error: ...``) and exit with status 2.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from .bsdf import BSDF
from .bsdffile import FourierTable, export, read
from .config import settings
from .errors import FileFormatError, InfeasibleError, LayersimError
from .outofcore import memory
from .plan import make_plan
from .scene import Scene
from .solver import solve
from .subtract import subtract

EXIT_INPUT = 2


def _scene(path):
    return Scene.from_toml(path)


def cmd_plan(args) -> int:
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


def _print_notes(info: dict) -> None:
    """The diagnostics of the solve (``info["notes"]``), in the plan report's format."""
    for note in info.get("notes", ()):
        print(f"  note: {note}")


def cmd_solve(args) -> int:
    scene = _scene(args.scene)
    print(scene.describe())
    bsdf = solve(scene, verbose=True)
    info = bsdf.info
    _print_notes(info)
    print(f"stack: {info['nnz']} nonzero coefficients, {info['memory_bytes'] / 2**20:.1f} MiB")
    print("albedo (energy fractions):")
    print(_albedo_table(bsdf, [0.0, 30.0, 60.0, 80.0, 89.0]))
    out = Path(args.output) if args.output else Path(Path(args.scene).stem + ".lsim")
    bsdf.save(out)
    print(f"wrote {out} (reload with layersim.BSDF.load)")
    return 0


def cmd_info(args) -> int:
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
    _print_notes(info)
    print("albedo (energy fractions):")
    print(_albedo_table(bsdf, [0.0, 30.0, 60.0, 80.0, 89.0]))
    return 0


def cmd_bench(args) -> int:
    from . import bench      # imported when used: the benchmark report needs matplotlib
    results = bench.run(args.out, quick=args.quick, stability=args.stability,
                        backends=args.backend or ("auto",), scene_dir=args.scenes,
                        scenes=args.scene, command="layersim " + " ".join(args.argv))
    fails = [c["name"] for c in results["stability"] if c["outcome"] == "fail"]
    print(f"wrote {args.out}/results.json, report.md and plots")
    if fails:
        print(f"stability failures: {', '.join(fails)}", file=sys.stderr)
        return 1
    return 0


# ---- export / eval / plot ---------------------------------------------------------------

def _load(path):
    """A BSDF from a scene, a saved ``.lsim`` BSDF or a ``.bsdf`` file (a ``.bsdf`` file that
    layersim cannot convert, e.g. one on foreign nodes, stays a FourierTable, which evaluates
    as pbrt-v3 and the Layer Laboratory's plugin do)."""
    path = Path(path)
    with open(path, "rb") as fh:
        head = fh.read(8)
    if head[:7] == b"SCATFUN":
        table = read(path)
        try:
            return table.to_bsdf()
        except (FileFormatError, InfeasibleError) as exc:
            print(f"note: {path}: {exc}; evaluating the table as renderers do",
                  file=sys.stderr)
            return table
    if head[:2] == b"PK":                    # numpy .npz container of BSDF.save
        return BSDF.load(path)
    if path.suffix.lower() not in ("", ".toml"):
        raise ValueError(f"{path}: not a scene (.toml), a saved BSDF (.lsim) or a .bsdf file")
    return solve(_scene(path))


def _vector(text: str, name: str, n: int) -> np.ndarray:
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        v = np.zeros(0)
    if v.size != n or not np.all(np.isfinite(v)):
        what = "X,Y,Z" if n == 3 else "THETA,PHI"
        raise ValueError(f"{name} must be {n} comma-separated finite numbers {what}, got "
                         f"{text!r}")
    return v


def _unit(text: str, name: str) -> np.ndarray:
    v = _vector(text, name, 3)
    norm = float(np.linalg.norm(v))
    if norm == 0.0:
        raise ValueError(f"{name} must be a nonzero direction")
    return v / norm


def _format(f) -> str:
    vals = np.atleast_1d(np.asarray(f, float))
    return " ".join(f"{x:.6g}" for x in vals)


def cmd_export(args) -> int:
    if not 0.0 <= args.relerr < 1.0:          # before solving the scene
        raise ValueError(f"--relerr {args.relerr:g}: the relative truncation must be in [0, 1)")
    bsdf = _load(args.source)
    out = Path(args.output) if args.output else Path(Path(args.source).stem + ".bsdf")
    alpha = _vector(args.alpha, "--alpha", 2) if args.alpha else (0.0, 0.0)
    if isinstance(bsdf, FourierTable):
        if args.version not in (None, bsdf.version) or args.relerr:
            raise ValueError(f"{args.source}: layersim cannot convert this file, so it can only "
                             f"be copied as version {bsdf.version} (without --relerr)")
        table = bsdf
        table.write(out)
    else:
        table = export(bsdf, out, version=args.version, alpha=alpha, relerr=args.relerr)
    size = out.stat().st_size
    print(f"wrote {out}: SCATFUN v{table.version}, {table.n_nodes} nodes, max order "
          f"{table.max_order}{' (complex)' if table.is_complex else ''}, {table.channels} "
          f"channel(s) "
          f"({'Y, R, B' if table.channels == 3 else 'mono'}), {table.coef.size} coefficients, "
          f"eta = {table.eta:g}, {size} bytes ({size / 2**20:.2f} MiB)")
    return 0


def cmd_eval(args) -> int:
    wi, wo = _unit(args.wi, "--wi"), _unit(args.wo, "--wo")
    bsdf = _load(args.source)
    f = bsdf.eval(wi, wo)
    print(f"wi = ({wi[0]:.6g}, {wi[1]:.6g}, {wi[2]:.6g}), wo = ({wo[0]:.6g}, {wo[1]:.6g}, "
          f"{wo[2]:.6g})")
    label = "f (R G B)" if bsdf.channels == 3 else "f"
    print(f"{label} = {_format(f)} 1/sr")
    return 0


def cmd_plot(args) -> int:
    from . import plot       # imported when used: matplotlib is slow to import
    if (args.wi is None) == (not args.blocks):
        raise ValueError("plot needs exactly one of --wi THETA,PHI (hemispherical slices) and "
                         "--blocks (the operator's four blocks)")
    name = Path(args.source).stem
    if args.blocks:
        if args.order is not None and args.order < 0:
            raise ValueError(f"--order must be >= 0, got {args.order}")
        out = Path(args.output) if args.output else Path(name + "_blocks.png")
        plot.plot_blocks(_load(args.source), out, order=args.order,
                         phi_d=math.radians(args.phi_d), title=name)
    else:
        theta, phi = _vector(args.wi, "--wi", 2)
        if not 0.0 <= theta <= 180.0 or theta == 90.0:
            raise ValueError(f"--wi THETA must be in [0, 180] degrees and not 90 (the horizon), "
                             f"got {theta:g}")
        t, p = math.radians(theta), math.radians(phi)
        wi = np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])
        out = Path(args.output) if args.output else Path(name + "_slices.png")
        plot.plot_slices(_load(args.source), wi, out, log=args.log, title=name)
    print(f"wrote {out}")
    return 0


# --- subtracting equations (layersim.subtract) ---------------------------------------------

def cmd_subtract(args) -> int:
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

    src_help = "scene (.toml), saved BSDF (.lsim) or .bsdf file"
    sp = sub.add_parser("export", help="write a tabulated Fourier BSDF file (.bsdf) for "
                                       "layerlab, Mitsuba 0.6 and pbrt-v3")
    sp.add_argument("source", help=src_help)
    sp.add_argument("-o", "--output", help="output file (default: SOURCE_STEM.bsdf)")
    sp.add_argument("--version", type=int, choices=(1, 2), default=None,
                    help="1: isotropic format of layerlab/Mitsuba 0.6/pbrt-v3 (default for "
                         "isotropic sources); 2: the Layer Laboratory's anisotropic layout "
                         "(default for anisotropic sources)")
    sp.add_argument("--relerr", type=float, default=0.0,
                    help="version 2: drop each pair's coefficients below this fraction of its "
                         "largest (e.g. 1e-3 as the Layer Laboratory does; default 0 keeps all)")
    sp.add_argument("--alpha", help="A_TOP,A_BOTTOM: Beckmann-equivalent roughness hints for "
                                    "the header (default 0,0)")
    sp.set_defaults(func=cmd_export)
    sp = sub.add_parser("eval", help="print f(wi, wo) in 1/sr (per channel for RGB)")
    sp.add_argument("source", help=src_help)
    sp.add_argument("--wi", required=True, help="X,Y,Z toward the light (local frame; "
                                                "normalised)")
    sp.add_argument("--wo", required=True, help="X,Y,Z toward the viewer (local frame; "
                                                "normalised)")
    sp.set_defaults(func=cmd_eval)
    sp = sub.add_parser("plot", help="draw hemispherical slices (--wi) or the operator's "
                                     "blocks (--blocks) into a PNG")
    sp.add_argument("source", help=src_help)
    sp.add_argument("--wi", help="THETA,PHI of the light in degrees (theta from the normal)")
    sp.add_argument("--blocks", action="store_true", help="draw Tbt | Rt over Rb | Ttb")
    sp.add_argument("--order", type=int, help="with --blocks: Fourier order l to show "
                                              "(default: the BSDF at --phi-d)")
    sp.add_argument("--phi-d", type=float, default=0.0,
                    help="with --blocks: azimuth difference in degrees (0 = specular)")
    sp.add_argument("--log", action="store_true", help="with --wi: logarithmic colours")
    sp.add_argument("-o", "--output", help="PNG file (default: SOURCE_STEM_slices.png or "
                                           "_blocks.png)")
    sp.set_defaults(func=cmd_plot)
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


def _attach_negative_values(argv: list) -> list:
    """``--wo -0.5,0,0.87`` -> ``--wo=-0.5,0,0.87``: argparse would take a comma-separated value
    starting with a minus sign for an option."""
    out = []
    it = iter(range(len(argv)))
    for k in it:
        a = argv[k]
        if (a in ("--wi", "--wo", "--alpha") and k + 1 < len(argv)
                and argv[k + 1][:1] == "-" and argv[k + 1][1:2] in set("0123456789.")):
            out.append(f"{a}={argv[k + 1]}")
            next(it, None)
        else:
            out.append(a)
    return out


def main(argv=None) -> int:
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(_attach_negative_values(argv))
    args.argv = argv
    try:
        memory.cap_arenas(settings().malloc_arenas)     # the command owns its process
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
