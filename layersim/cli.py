"""The ``layersim`` command line.

    layersim plan SCENE              print the discretisation plan (no heavy work); a plan
                                     over the limits is printed with its refusal (status 2)
    layersim solve SCENE [-o FILE] [--like STACK.lsim]
                                     solve, print plan, timings and albedos; save the BSDF
    layersim info FILE               summary and albedos of a saved BSDF (.lsim) or .bsdf file
    layersim bench [--quick] [--stability] [--backend B ...] [--render] --out DIR
                                     solver vs Monte Carlo report and stability suite
    layersim export SRC [-o F.bsdf] [--version 1|2] [--format rgl [--resolution N]]
                                     write a tabulated Fourier BSDF file (v1: layerlab/Mitsuba
                                     0.6/pbrt-v3; v2, anisotropic: the Layer Laboratory) or an
                                     RGL material (Mitsuba 3 / pbrt-v4, reflection only)
    layersim eval SRC --wi X,Y,Z --wo X,Y,Z     print f(wi, wo) (per channel for RGB)
    layersim plot SRC (--wi THETA,PHI | --blocks) [-o F.png]   draw slices or operator blocks
    layersim subtract STACK KNOWN --side top|bottom [-o FILE] [--eps EPS] [--noise NOISE]
    layersim subtract STACK [KNOWN] --side top|bottom --model TEMPLATE [-o FILE]
                                     recover the unknown layer of a solved two-layer stack
    layersim fit TEMPLATE TARGET -o FITTED.toml [--plot F.png] [--quiet]
                                     fit a template's free values to a BSDF or measurements
    layersim mc SCENE --wi THETA,PHI [--paths N | --stderr E] -o OUT.npz
                                     Monte Carlo walks into a resumable result file
    layersim mc SWEEP.toml [--workers N | --cluster ADDR | --devices all] -o OUT.npz
                                     scenes x angles x channels, on a cluster or several GPUs
    layersim compare RESULT SOURCE [--plot PNG]
                                     a result file against a solve or another result file
    layersim render SRC [-o F.png] [--spp N] [--resolution W,H]
                                     render a sphere of the material with Mitsuba 3

SRC is a scene (``.toml``, solved on the fly), a saved BSDF (``.lsim`` from ``solve -o``) or a
``.bsdf`` file.

Errors in the input print one line (``layersim: error: ...``) and exit with status 2, before
any heavy work: options, output paths and the environment are checked first. Solves show a
progress bar per phase on a terminal (``--quiet`` or a redirected stderr: none).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import threading
import warnings
from pathlib import Path

import numpy as np

from .solved.bsdf import BSDF
from .bsdffile import FourierTable, export, read
from .config import settings
from .errors import FileFormatError, InfeasibleError, LayersimError
from .outofcore import memory
from .plan import make_plan
from .scene import Scene
from .solver import solve
from .stacking import determined
from .stacking.subtract import subtract

EXIT_INPUT = 2
#: Incident angles (degrees) of the albedo tables that solve, info and subtract print.
TABLE_ANGLES = [0.0, 30.0, 60.0, 80.0, 89.0]


class ProgressBars:
    """The ``progress`` callback of :func:`layersim.solve` drawn as tqdm bars on stderr, one
    per phase (projection of the layers, adding), when ``enabled``; otherwise silent. A step
    can take minutes (the coupled adding of a large stack), so a timer thread redraws the
    open bars every :attr:`interval` seconds: their elapsed time keeps counting."""

    interval = 0.5

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.bars: dict = {}
        self._stop = threading.Event()
        self._timer = None

    def __call__(self, phase: str, done: int, total: int, what: str) -> None:
        if not self.enabled or total <= 0:
            return
        from tqdm import tqdm
        bar = self.bars.get(phase)
        if bar is None:
            bar = self.bars[phase] = tqdm(total=total, desc=phase, unit="step", leave=False,
                                          file=sys.stderr, position=len(self.bars))
            if self._timer is None:
                self._timer = threading.Thread(target=self._redraw, daemon=True)
                self._timer.start()
        bar.set_postfix_str(what, refresh=False)
        bar.update(done - bar.n)
        if done >= total:
            bar.close()

    def _redraw(self) -> None:
        while not self._stop.wait(self.interval):
            for bar in list(self.bars.values()):
                if not bar.disable:
                    bar.refresh()

    def close(self) -> None:
        self._stop.set()
        if self._timer is not None:
            self._timer.join()
        for bar in self.bars.values():
            bar.close()
        self.bars.clear()


def _progress(args) -> ProgressBars:
    """Progress bars for the command's solves: on a terminal, unless ``--quiet``."""
    return ProgressBars(not getattr(args, "quiet", False) and sys.stderr.isatty())


def _cannot_write(folder: Path) -> str | None:
    """Why no file can be created in the existing ``folder`` (a phrase), or None. A probe file
    is created and removed: permission bits do not tell (root passes ``os.access``
    everywhere, and a read-only or virtual file system such as ``/proc`` refuses files that
    ``os.access`` allows)."""
    try:
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".layersim-probe-")
    except OSError as exc:
        return f"creating a file in {folder} fails ({exc.strerror or exc})"
    os.close(fd)
    os.unlink(probe)
    return None


def _output(path, option: str) -> Path:
    """``path`` of an output file given by ``option`` (or its default), checked before the
    work that produces it: its folder exists and takes new files, the file itself (if it
    exists) can be written, and it is not a folder."""
    path = Path(path)
    folder = path.parent
    if path.is_dir():
        raise ValueError(f"{option} {path}: is a folder; give a file name")
    if not folder.is_dir():
        what = "is a file, not a folder" if folder.exists() else "does not exist"
        raise ValueError(f"{option} {path}: the folder {folder} {what}")
    if path.exists():
        try:       # opened for appending, without blocking, and closed: nothing changes
            os.close(os.open(path, os.O_WRONLY | os.O_APPEND | os.O_NONBLOCK))
            why = None
        except OSError as exc:
            why = f"opening it for writing fails ({exc.strerror or exc})"
    else:
        why = _cannot_write(folder)
    if why:
        raise ValueError(f"{option} {path}: cannot write there: {why}")
    return path


def _output_folder(path, option: str) -> Path:
    """``path`` of an output folder given by ``option``, checked before the work: it is a
    folder that takes new files, or the nearest of its parents that exists does (the folder
    and its missing parents are created when written)."""
    path = Path(path)
    base = next(p for p in [path, *path.absolute().parents] if p.exists())
    if not base.is_dir():
        raise ValueError(f"{option} {path}: {base} is a file, not a folder")
    why = _cannot_write(base)
    if why:
        raise ValueError(f"{option} {path}: cannot write there: {why}")
    return path


def _image(path, option: str) -> Path:
    """An image file to write (:func:`_output`) in a format that matplotlib writes."""
    from matplotlib.backend_bases import FigureCanvasBase
    path = _output(path, option)
    formats = FigureCanvasBase.get_supported_filetypes()
    if path.suffix.lower().lstrip(".") not in formats:
        raise ValueError(f"{option} {path}: unknown image format {path.suffix or '(none)'}; "
                         f"use one of {', '.join('.' + f for f in sorted(formats))}")
    return path


def _scene(path):
    return Scene.from_toml(path)


def cmd_plan(args) -> int:
    scene = _scene(args.scene)
    print(scene.describe())
    plan = make_plan(scene, refuse=False)
    print(plan.report())
    if plan.refused:
        # the solve would refuse this plan: a script can test the status before solving
        print(f"layersim: error: {plan.refused}", file=sys.stderr)
        return EXIT_INPUT
    return 0


def cmd_import_pbrt(args) -> int:
    from .pbrtimport import pbrt_to_dict
    from .tomlwrite import dumps
    path = Path(args.file)
    data, notes = pbrt_to_dict(path.read_text(encoding="utf-8"), path.stem)
    scene = Scene.from_dict(data, source=str(path))       # refuse before writing anything
    out = Path(args.output or path.with_suffix(".toml").name)
    out.write_text(dumps(data, f"imported from {path.name} by layersim import-pbrt"),
                   encoding="utf-8")
    print(scene.describe())
    for note in notes:
        print(f"note: {note}")
    print(f"wrote {out}")
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


def _print_accuracy(info: dict) -> None:
    """The error estimate of the solve (``info["accuracy"]``), if it made one."""
    acc = info.get("accuracy")
    if acc is None:
        return
    tol = f" (tol {acc['tol']:g})" if "tol" in acc else ""
    comps = " and ".join(f"n = {c['n']}, md = {c['md']}" for c in acc["companions"])
    print(f"error estimate: {acc['estimate']:.2g}{tol}, relative L2 of bin energies "
          f"({acc['bins'][0]} x {acc['bins'][1]} per side, worst of "
          f"{', '.join(f'{a:g}' for a in acc['angles'])} deg), from companion solves at "
          f"{comps}")


def cmd_solve(args) -> int:
    out = _output(args.output if args.output else Path(args.scene).stem + ".lsim", "-o")
    scene = _scene(args.scene)
    like = BSDF.load(args.like) if args.like else None
    print(scene.describe())
    if like is not None:
        print(f"discretisation of {args.like}: n = {like.grid.n} ({like.grid.rule}), "
              f"md = {like.operators[0].m}")
    bars = _progress(args)
    try:
        bsdf = solve(scene, like=like, verbose=True, progress=bars, tol=args.tol,
                     error_estimate=args.estimate_error)
    finally:
        bars.close()
    info = bsdf.info
    _print_accuracy(info)
    if "nnz" in info:
        _print_notes(info)
        print(f"stack: {info['nnz']} nonzero coefficients, "
              f"{info['memory_bytes'] / 2**20:.1f} MiB")
    else:
        print(f"stack: specular paths ({repr(bsdf)})")
    print("albedo (energy fractions):")
    print(_albedo_table(bsdf, TABLE_ANGLES))
    bsdf.save(out)
    print(f"wrote {out} (reload with layersim.BSDF.load)")
    return 0


def _table_summary(table) -> str:
    """One line describing a ``.bsdf`` table (:class:`FourierTable`)."""
    return (f"SCATFUN v{table.version}, {table.n_nodes} nodes, max order {table.max_order}"
            f"{' (complex)' if table.is_complex else ''}, {table.channels} channel(s) "
            f"({'Y, R, B' if table.channels == 3 else 'mono'}), {table.coef.size} coefficients, "
            f"eta = {table.eta:g}")


def cmd_info(args) -> int:
    with open(args.file, "rb") as fh:
        head = fh.read(8)
    if head[:7] == b"SCATFUN":
        # a .bsdf table: its header, and the albedos where it converts to operators
        table = read(args.file)
        print(f"{args.file}: {_table_summary(table)}")
        try:
            bsdf = table.to_bsdf()
        except (FileFormatError, InfeasibleError) as exc:
            print(f"note: no albedos: {exc}")
            return 0
        print("albedo (energy fractions):")
        print(_albedo_table(bsdf, TABLE_ANGLES))
        return 0
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
    _print_accuracy(info)
    print("albedo (energy fractions):")
    print(_albedo_table(bsdf, TABLE_ANGLES))
    return 0


def cmd_bench(args) -> int:
    from . import bench      # imported when used: the benchmark report needs matplotlib
    from .montecarlo import BACKENDS, available_backends
    from .montecarlo.backends import why_unavailable
    backends = args.backend or ["auto"]
    unknown = [b for b in backends if b not in BACKENDS]
    if unknown:
        raise ValueError(f"--backend {unknown[0]}: unknown Monte Carlo backend; expected one "
                         f"of {', '.join(BACKENDS)}")
    here = available_backends()
    missing = [b for b in backends if b != "auto" and b not in here]
    if missing:
        reason = why_unavailable(missing[0]) or "not available"
        raise ValueError(f"--backend {missing[0]}: not available on this machine (available: "
                         f"{', '.join(here)}): {reason}")
    if args.render_paths is not None and args.render_paths < 1:
        raise ValueError(f"--render-paths {args.render_paths}: must be a whole number >= 1")
    if args.render_paths is not None and not args.render:
        raise ValueError("--render-paths is an option of --render; add --render")
    _output_folder(args.out, "--out")
    results = bench.run(args.out, quick=args.quick, stability=args.stability,
                        backends=backends, scene_dir=args.scenes,
                        scenes=args.scene, command="layersim " + " ".join(args.argv),
                        seed=args.seed, render=args.render, render_particles=args.render_paths)
    fails = [c["name"] for c in results["stability"] if c["outcome"] == "fail"]
    print(f"wrote {args.out}/results.json, report.md and plots")
    if fails:
        print(f"stability failures: {', '.join(fails)}", file=sys.stderr)
        return 1
    return 0


#: Paths per incident direction when `layersim design` verifies against Monte Carlo.
MC_VERIFY_PATHS = 1_000_000


def _design_options(args):
    """The checked options of ``layersim design``: the output path and image (or None)."""
    if args.plot and args.no_verify:
        raise ValueError("--plot draws the exact solve's lobes: drop --no-verify")
    if args.exact and args.no_verify:
        raise ValueError("--exact fits the design by exact solves: drop --no-verify")
    if args.candidates < 1:
        raise ValueError(f"--candidates must be >= 1, got {args.candidates}")
    out = _output(args.output, "-o") if args.output else None
    return out, _image(args.plot, "--plot") if args.plot else None


def _verify_design(targets, best, image):
    """Print the statistical design's verification (exact solve, else Monte Carlo)."""
    from .statistical import report
    from .statistical.verify import montecarlo_solve, verify
    reference = "exact"
    try:
        result = verify(best)
    except LayersimError as exc:
        print(f"exact solve refused ({exc}); verifying against Monte Carlo "
              f"({MC_VERIFY_PATHS:.0e} paths per direction)")
        result = verify(best, solve=montecarlo_solve(MC_VERIFY_PATHS, backend="auto"))
        reference = "Monte Carlo"
    print("verification of candidate 1 at normal incidence:")
    print("\n".join(report.verification_lines(targets, result, reference)))
    if image:
        report.plot_lobes(targets, best, result, image)
        print(f"wrote {image}")


def _refine_design(args, targets, best, image):
    """Print the exact refinement of ``best`` and return the refined design."""
    from .statistical import report
    from .statistical.refine import refine
    result = refine(best, targets, progress=False if args.quiet else None)
    print("exact refinement of candidate 1 (lobes at normal incidence, exact transport):")
    print("\n".join(report.refinement_lines(targets, result)))
    if image:
        report.plot_lobes(targets, result.refined, {"exact_solve": solve}, image)
        print(f"wrote {image}")
    return result.refined


def cmd_design(args) -> int:
    from .statistical import report
    from .statistical.design import designs
    from .statistical.targets import parse_targets
    targets = parse_targets(args.targets)
    out, image = _design_options(args)
    found = designs(args.targets)
    for i, d in enumerate(found[:args.candidates]):
        print(f"candidate {i + 1} of {len(found)} (class position {d.choice}):")
        print("\n".join(report.stack_lines(d)))
    best = found[0]
    for note in best.notes:
        print(f"note: {note}")
    if args.exact:
        best = _refine_design(args, targets, best, image)
    elif not args.no_verify:
        _verify_design(targets, best, image)
    if out:
        out.write_text(best.toml())
        print(f"wrote {out} (layersim solve {out})")
    return 0


# ---- export / eval / plot ---------------------------------------------------------------

def _load(path, args=None):
    """A BSDF from a scene, a saved ``.lsim`` BSDF or a ``.bsdf`` file (a ``.bsdf`` file that
    layersim cannot convert, e.g. one on foreign nodes, stays a FourierTable, which evaluates
    as pbrt-v3 and the Layer Laboratory's plugin do)."""
    path = Path(path)
    with open(path, "rb") as fh:
        head = fh.read(8)
    if not head:
        raise ValueError(f"{path}: the file is empty (expected a scene, a saved BSDF or a "
                         ".bsdf file)")
    if head[:7] == b"SCATFUN":
        table = read(path)
        try:
            return table.to_bsdf()
        except (FileFormatError, InfeasibleError) as exc:
            print(f"note: {path}: {exc}; evaluating the table as renderers do",
                  file=sys.stderr)
            return table
    if head == b"tensor_f":                                   # an RGL material file
        raise ValueError(f"{path}: an RGL material (tensor file, reflection only), which "
                         "layersim writes but does not take as a SOURCE; read it with "
                         "layersim.bsdffile.rgl.read")
    if head[:2] == b"PK" or path.suffix.lower() == ".lsim":   # numpy .npz of BSDF.save
        return BSDF.load(path)
    if path.suffix.lower() not in ("", ".toml"):
        raise ValueError(f"{path}: not a scene (.toml), a saved BSDF (.lsim) or a .bsdf file")
    bars = _progress(args)
    try:
        return solve(_scene(path), progress=bars)
    finally:
        bars.close()


def _vector(text: str, name: str, what: str) -> np.ndarray:
    """The comma-separated finite numbers of option ``name``, as many as the names in
    ``what`` (e.g. ``"X,Y,Z"``), which the error message shows."""
    n = what.count(",") + 1
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        v = np.zeros(0)
    if v.size != n or not np.all(np.isfinite(v)):
        raise ValueError(f"{name} must be {n} comma-separated finite numbers {what}, got "
                         f"{text!r}")
    return v


def _unit(text: str, name: str) -> np.ndarray:
    v = _vector(text, name, "X,Y,Z")
    scale = float(np.max(np.abs(v)))
    if scale == 0.0:
        raise ValueError(f"{name} must be a nonzero direction")
    v = v / scale                        # no overflow in the norm of huge components
    return v / np.linalg.norm(v)


def _format(f) -> str:
    vals = np.atleast_1d(np.asarray(f, float))
    return " ".join(f"{x:.6g}" for x in vals)


def _rgl_wavelengths(args):
    """Channel wavelengths (nm) for an RGL export: ``--wavelengths``, else the scene's
    ``[stack] wavelengths`` when SOURCE is a scene, else None."""
    if args.wavelengths:
        try:
            return [float(x) for x in args.wavelengths.split(",")]
        except ValueError:
            raise ValueError(f"--wavelengths {args.wavelengths!r}: give comma-separated "
                             "wavelengths in nm, one per channel") from None
    if Path(args.source).suffix.lower() == ".toml":
        return _scene(args.source).wavelengths
    return None


def cmd_export_rgl(args) -> int:
    """``layersim export --format rgl``: options checked, then solve, write and measure."""
    from .bsdffile import rgl
    if args.version is not None or args.relerr or args.alpha:
        raise ValueError("--version, --relerr and --alpha belong to --format bsdf")
    resolution = rgl.DEFAULT_RESOLUTION if args.resolution is None else args.resolution
    if not 4 <= resolution <= 256:                         # before solving
        raise ValueError(f"--resolution {resolution}: must be within [4, 256]")
    out = _output(args.output if args.output else Path(args.source).stem + ".rgl.bsdf", "-o")
    wavelengths = _rgl_wavelengths(args)
    if Path(args.source).suffix.lower() == ".toml":              # colour checked before solving
        rgl.colour_mode(_scene(args.source).channels, wavelengths, args.color)
    bsdf = _load(args.source, args)
    if isinstance(bsdf, FourierTable):
        raise ValueError(f"{args.source}: layersim cannot convert this .bsdf file into a "
                         "BSDF, so it cannot export it as RGL")
    rgl.colour_mode(bsdf.channels, wavelengths, args.color)    # before the heavy part
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")                        # printed below as notes
        res = export(bsdf, out, format="rgl", resolution=resolution, wavelengths=wavelengths,
                     color=args.color, name=Path(args.source).stem)
    for note in res.notes:
        print(f"note: {note}", file=sys.stderr)
    t = res.table
    colour = "rgb field" if t.wavelengths is None else f"{len(t.wavelengths)} wavelengths"
    print(f"wrote {out}: RGL material for Mitsuba 3 / pbrt-v4 'measured' "
          f"({'isotropic' if t.isotropic else 'anisotropic'}, {len(t.phi_i)} x "
          f"{len(t.theta_i)} incident directions, {t.spectra.shape[-1]} x "
          f"{t.spectra.shape[-1]} nodes each, {colour}), {res.bytes} bytes "
          f"({res.bytes / 2**20:.2f} MiB), in {res.seconds:.1f} s")
    print(f"reconstruction error: {res.error:.3g}, {res.error_to_80:.3g} for incidence "
          f"within 80 deg of the normal (relative L2 of f cos(theta_o) against the solved "
          f"BSDF, {rgl.ERROR_SAMPLES} direction pairs)")
    return 0


def cmd_export(args) -> int:
    if args.format == "rgl":
        return cmd_export_rgl(args)
    if args.resolution is not None or args.wavelengths or args.color != "spectral":
        raise ValueError("--resolution, --wavelengths and --color belong to --format rgl")
    if not 0.0 <= args.relerr < 1.0:          # before solving the scene
        raise ValueError(f"--relerr {args.relerr:g}: the relative truncation must be in [0, 1)")
    out = _output(args.output if args.output else Path(args.source).stem + ".bsdf", "-o")
    alpha = _vector(args.alpha, "--alpha", "A_TOP,A_BOTTOM") if args.alpha else (0.0, 0.0)
    if np.any(np.asarray(alpha) < 0.0):
        raise ValueError(f"--alpha {args.alpha}: roughness hints must be >= 0")
    bsdf = _load(args.source, args)
    if isinstance(bsdf, FourierTable):
        if args.version not in (None, bsdf.version) or args.relerr:
            raise ValueError(f"{args.source}: layersim cannot convert this file, so it can only "
                             f"be copied as version {bsdf.version} (without --relerr)")
        table = bsdf
        table.write(out)
    else:
        table = export(bsdf, out, version=args.version, alpha=alpha, relerr=args.relerr)
    size = out.stat().st_size
    print(f"wrote {out}: {_table_summary(table)}, {size} bytes ({size / 2**20:.2f} MiB)")
    return 0


def cmd_eval(args) -> int:
    wi, wo = _unit(args.wi, "--wi"), _unit(args.wo, "--wo")
    if wi[2] == 0.0 or wo[2] == 0.0:
        raise ValueError(f"{'--wi' if wi[2] == 0.0 else '--wo'} lies on the horizon (z = 0), "
                         "where f is not defined; tilt it above or below")
    bsdf = _load(args.source, args)
    if getattr(bsdf, "opaque", False) and (wi[2] < 0 or wo[2] < 0):
        side = "--wi" if wi[2] < 0 else "--wo"
        raise ValueError(f"{args.source} is opaque from below: {side} points below the "
                         "surface (z < 0), where no light arrives or leaves (f = 0); give "
                         f"{side} with z > 0")
    f = bsdf.eval(wi, wo)
    print(f"wi = ({wi[0]:.6g}, {wi[1]:.6g}, {wi[2]:.6g}), wo = ({wo[0]:.6g}, {wo[1]:.6g}, "
          f"{wo[2]:.6g})")
    label = "f (R G B)" if bsdf.channels == 3 else "f"
    print(f"{label} = {_format(f)} 1/sr")
    return 0


def cmd_plot(args) -> int:
    if (args.wi is None) == (not args.blocks):
        raise ValueError("plot needs exactly one of --wi THETA,PHI (hemispherical slices) and "
                         "--blocks (the operator's four blocks)")
    name = Path(args.source).stem
    if args.blocks:
        if args.order is not None and args.order < 0:
            raise ValueError(f"--order must be >= 0, got {args.order}")
        if not math.isfinite(args.phi_d):
            raise ValueError(f"--phi-d must be a finite angle in degrees, got {args.phi_d}")
        if not 0.0 < args.percentile <= 100.0:
            raise ValueError(f"--percentile must be in (0, 100], got {args.percentile:g}")
        out = _image(args.output if args.output else name + "_blocks.png", "-o")
        bsdf = _load(args.source, args)
        if args.order is not None:
            if not isinstance(bsdf, BSDF):
                raise ValueError(f"--order: {args.source} cannot be converted to layersim "
                                 "operators, so its Fourier orders are not available; "
                                 "leave out --order")
            md = bsdf.operators[0].m
            if args.order >= md:
                raise ValueError(f"--order {args.order}: {args.source} has Fourier orders "
                                 f"0 to {md - 1} (md = {md})")
        from .solved import plot   # imported when used: matplotlib is slow to import
        plot.plot_blocks(bsdf, out, order=args.order, phi_d=math.radians(args.phi_d),
                         title=name, percentile=args.percentile)
    else:
        theta, phi = _vector(args.wi, "--wi", "THETA,PHI")
        if not 0.0 <= theta <= 180.0 or theta == 90.0:
            raise ValueError(f"--wi THETA must be in [0, 180] degrees and not 90 (the horizon), "
                             f"got {theta:g}")
        t, p = math.radians(theta), math.radians(phi)
        wi = np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])
        out = _image(args.output if args.output else name + "_slices.png", "-o")
        bsdf = _load(args.source, args)
        if getattr(bsdf, "opaque", False) and wi[2] < 0:
            raise ValueError(f"{args.source} is opaque from below: --wi THETA > 90 lights it "
                             "from below, where no light enters; give THETA < 90")
        from .solved import plot   # imported when used: matplotlib is slow to import
        plot.plot_slices(bsdf, wi, out, log=args.log, title=name)
    print(f"wrote {out}")
    return 0


# --- subtracting equations (layersim.subtract) ---------------------------------------------

def cmd_subtract(args) -> int:
    if args.model:
        return _subtract_model(args)
    if args.known is None:
        raise ValueError("subtract: KNOWN (the solved known layer) is required without --model")
    out = _output(args.output if args.output else
                  f"{Path(args.stack).stem}-minus-{Path(args.known).stem}.lsim", "-o")
    stack = BSDF.load(args.stack)
    known = BSDF.load(args.known)
    result = subtract(stack, known, side=args.side, eps=args.eps, noise=args.noise)
    _print_plain(result)
    print("albedo of the recovered layer (energy fractions):")
    print(_albedo_table(result, TABLE_ANGLES))
    infos = result.info["subtract"]
    _warn_energy(result, infos if isinstance(infos, list) else [infos])
    _warn_hidden(known, args.side)
    result.save(out)
    print(f"wrote {out} (reload with layersim.BSDF.load)")
    return 0


def _print_plain(result: BSDF, prefix: str = "") -> None:
    """What the plain subtraction chose and what the stack determines, per channel."""
    infos = result.info["subtract"]
    for c, info in enumerate(infos if isinstance(infos, list) else [infos]):
        tag = prefix + (f"channel {c}: " if isinstance(infos, list) else "")
        print(f"{tag}eps = {info['eps']:.3g} ({info['method']}); noise level "
              f"{info['noise']:.3g} ({info['noise_source']}); re-adding residual "
              f"{info['residual']:.3g}; visible {100 * info['visible']:.0f} % of the angular "
              f"components; largest R + T {info['energy_max']:.4f}")
        print(f"{tag}{determined.describe(info['determined'])}")


def _subtract_model(args) -> int:
    """``layersim subtract STACK [KNOWN] --model TEMPLATE``: layersim.subtract_model."""
    from .fit import Template, subtract_model
    stem = Path(args.known).stem if args.known else Path(args.model).stem
    out = _output(args.output if args.output else
                  f"{Path(args.stack).stem}-minus-{stem}.lsim", "-o")
    if args.eps is not None or args.noise is not None:
        if args.known is None:
            raise ValueError("subtract: --eps and --noise set the plain subtraction, which "
                             "--model runs only beside KNOWN")
    stack = BSDF.load(args.stack)
    known = BSDF.load(args.known) if args.known else None
    res = subtract_model(stack, Template(args.model), side=args.side, known=known,
                         progress=None if not args.quiet else False)
    layers = ", ".join(map(str, res.layers))
    print(f"model-based subtraction: layers {layers} of {args.model} fitted to {args.stack}")
    print(res.fit.summary())
    print(f"model: re-adding residual {res.residual:.3g} (relative L2 of the known layers added "
          "to the fitted base against the stack, energy basis)")
    if res.plain is not None:
        print("plain subtraction of KNOWN, for comparison:")
        _print_plain(res.plain, "  plain: ")
        infos = res.plain.info["subtract"]
        worst = max(i["residual_filled"] for i in (infos if isinstance(infos, list) else
                                                   [infos]))
        print(f"  plain: re-adding residual of the filled result {worst:.3g}")
    print("albedo of the fitted base (energy fractions):")
    print(_albedo_table(res.base, TABLE_ANGLES))
    res.base.save(out)
    print(f"wrote {out} (reload with layersim.BSDF.load)")
    return 0


def _warn_hidden(known: BSDF, side: str) -> None:
    """Warn on stderr when the known layer hides directions of the recovered one: seen through
    an interface into a denser medium, directions beyond its critical angle in that medium are
    reached by no light of the stack (total internal reflection), so the stack says nothing
    about the recovered layer there and its values at those angles are not recovered."""
    op = known.operators[0]
    if op.eta_bottom is None:
        return
    shared, outer = ((op.eta_bottom, op.eta_top) if side == "top"
                     else (op.eta_top, op.eta_bottom))
    if shared <= outer:
        return
    critical = math.degrees(math.asin(outer / shared))
    where = "from above" if side == "top" else "from below"
    print(f"warning: the recovered layer is seen through the known one from a medium of index "
          f"{outer:g}: in its medium of index {shared:g}, directions beyond the critical angle "
          f"{critical:.1f} deg (lit {where}) receive no light of the stack, so the result there "
          "is not recovered (its albedos at those angles are not measurements)",
          file=sys.stderr)


#: R + T above 1 by more than this (rounding and quadrature) makes subtract warn.
ENERGY_WARN = 1e-3


def _warn_energy(result: BSDF, infos: list) -> None:
    """Warn on stderr where the recovered layer reflects and transmits more than it receives:
    no passive layer does, so there the subtraction has amplified errors of the stack (noise,
    discretisation) beyond the regularisation, and the result is not to be trusted."""
    worst = max(info["energy_max"] for info in infos)
    if worst <= 1.0 + ENERGY_WARN:
        return
    theta = np.arange(0.0, 90.0, 1.0)
    wi = np.stack([np.sin(np.radians(theta)), 0 * theta, np.cos(np.radians(theta))], axis=-1)
    sides = [("from above", wi)] + ([] if result.opaque else [("from below", wi * [1, 1, -1])])
    where = []
    for label, w in sides:
        R, T = result.albedo(w)
        total = np.asarray(R + T).reshape(theta.size, -1).max(axis=1)
        bad = theta[total > 1.0 + ENERGY_WARN]
        if bad.size:
            where.append(f"{label} at {bad.min():g}-{bad.max():g} deg")
    print(f"warning: the recovered layer creates energy (R + T up to {worst:.4f} > 1"
          + (f"; {', '.join(where)}" if where else "") + "). No physical layer does: the "
          "subtraction has amplified errors of the stack there, and those angles of the "
          "result are unreliable; a larger --eps smooths them, a stack solved with more "
          "ordinates (n) or with less noise reduces them", file=sys.stderr)


EXAMPLES = {
    "plan": """examples:
  layersim plan examples/coated_gold.toml
  LAYERSIM_MAX_MEMORY=4e9 layersim plan examples/brushed_metal.toml

Prints the scene, the ordinates, Fourier orders and memory the solve would use and what it
leaves out. A plan over the memory limit is printed with the reason ("refused: ...") and the
command exits with status 2, as 'layersim solve' would refuse it.""",
    "solve": """examples:
  layersim solve examples/coated_gold.toml                 # writes coated_gold.lsim
  layersim solve examples/coated_gold.toml -o gold.lsim --quiet
  layersim solve lacquer.toml --like coated_gold.lsim      # on coated_gold's discretisation,
                                                           # ready for 'layersim subtract'""",
    "info": """examples:
  layersim info coated_gold.lsim
  layersim info coated_gold.bsdf""",
    "design": """examples:
  layersim design targets.toml -o stack.toml       # prints stacks and verification
  layersim design targets.toml --no-verify         # statistical model only
  layersim design targets.toml --plot lobes.png
  layersim design targets.toml --exact -o stack.toml  # refined by exact fits""",
    "bench": """examples:
  layersim bench --out bench-quick --quick
  layersim bench --out bench --stability --backend warp-cuda --backend opencl
  layersim bench --out bench --scene coated_gold
  layersim bench --out bench-render --quick --render --scene coated_gold""",
    "export": """examples:
  layersim export examples/coated_gold.toml -o coated_gold.bsdf
  layersim export brushed.lsim -o brushed.bsdf --version 2 --relerr 1e-3
  layersim export examples/coated_gold.toml --format rgl -o coated_gold.rgl.bsdf
  layersim export paint.lsim --format rgl --color rgb --resolution 48 -o paint_rgb.bsdf""",
    "eval": """examples:
  layersim eval coated_gold.lsim --wi 0.5,0,0.866 --wo -0.5,0,0.866     # specular
  layersim eval examples/coated_gold.toml --wi 0,0,1 --wo 0.3,0.2,0.93""",
    "plot": """examples:
  layersim plot coated_gold.lsim --wi 30,0 -o slices.png --log
  layersim plot coated_gold.lsim --blocks -o blocks.png
  layersim plot coated_gold.lsim --blocks --order 2 -o order2.png""",
    "fit": """examples:
  layersim fit template.toml stack.lsim -o fitted.toml --plot fit.png
  layersim fit template.toml samples.npz -o fitted.toml   # arrays wi (N,3), wo (N,3), f (N[,C])
  layersim fit template.toml samples.csv -o fitted.toml   # rows wi_x..wi_z, wo_x..wo_z, f...""",
    "fit-ndf": """examples:
  layersim fit-ndf view.npz -o ndf.npz --complete rot1.npz rot2.npz rot3.npz --fill
  layersim fit-ndf view.csv -o partial.npz --partial --plot partial.png
  layersim fit-ndf view.npz -o ndf.npz --symmetry point --fill

MEASUREMENTS holds one view, many light directions and the specular BRDF per channel (.npz:
view, lights, values[, channels]; .csv: light_x,light_y,light_z,view_x,view_y,view_z,CHANNEL...;
see docs/conventions.md). A single view determines D only over part of the hemisphere: the
table is written only when it is complete, when --fill is given (the rest is interpolated and
reported) or with --partial.""",
    "mc": """examples:
  layersim mc examples/coated_gold.toml --wi 30,0 --wi 60,0 --paths 1e6 -o gold.npz
  layersim mc examples/coated_gold.toml --wi 30,0 --stderr 1e-4 --paths 1e8 -o gold.npz
  layersim mc sweep.toml --workers 8 -o truth.npz          (a [sweep] file: docs/conventions.md)
  layersim mc sweep.toml --devices cuda:0,cuda:1 -o truth.npz
  layersim mc sweep.toml --cluster tls://head:8786 --tls-ca-file ca.pem --tls-cert me.pem -o t.npz
  (Ctrl-C stops after a checkpoint; the same command again continues bit for bit, on any
  executor)""",
    "compare": """examples:
  layersim compare gold.npz examples/coated_gold.toml --plot z.png
  layersim compare gold.npz coated_gold.lsim
  layersim compare gold.npz gold_seed1.npz""",
    "import-pbrt": """examples:
  layersim import-pbrt coated.pbrt -o coated.toml
  layersim solve coated.toml

FILE holds one pbrt-v4 Material or MakeNamedMaterial (coatedconductor, coateddiffuse, conductor,
dielectric, diffuse) with numeric parameters; the scene is GGX with pbrt-v4's height-correlated
Smith term (docs/pbrt.md).""",
    "render": """examples:
  layersim render examples/rgb_coated_gold.toml -o gold.png
  layersim render coated_gold.lsim -o sphere.png --spp 64 --resolution 256,256

A unit sphere under a generated sky (gradient and sun) and a point light, rendered with the
layersim plug-in of Mitsuba 3 (pip install mitsuba): llvm_ad_rgb where LLVM >= 16 is found,
else scalar_rgb (much slower). See docs/renderers.md.""",
    "subtract": """examples:
  layersim solve stack.toml                                # stack.lsim
  layersim solve lacquer.toml --like stack.lsim            # lacquer.lsim, same discretisation
  layersim subtract stack.lsim lacquer.lsim --side top -o base.lsim
  layersim subtract stack.lsim --side top --model template.toml -o base.lsim
  layersim subtract stack.lsim lacquer.lsim --side top --model template.toml  # both ways

--model: template.toml is the whole stack with the known layers fixed and the unknown layer's
fields free ({ fit = [lo, hi] }); the known layers are those above the first free layer (--side
top) or below the last one (--side bottom), the rest is fitted and solved alone.""",
}


class _Parser(argparse.ArgumentParser):
    """argparse with its errors on one line, as every other input error of the command."""

    def error(self, message):
        self.exit(EXIT_INPUT, f"layersim: error: {message} (see '{self.prog} --help')\n")


def _subparser(sub, name: str, help: str, parents=()) -> argparse.ArgumentParser:
    return sub.add_parser(name, help=help, description=help[:1].upper() + help[1:] + ".",
                          epilog=EXAMPLES[name], parents=list(parents),
                          formatter_class=argparse.RawDescriptionHelpFormatter)


def build_parser() -> argparse.ArgumentParser:
    from . import __version__
    p = _Parser(
        prog="layersim", description="Reflectance of layered materials: solve a stack of "
        "layers into a BSDF;\nevaluate, plot, export and subtract it; compare it with "
        "Monte Carlo.",
        epilog="examples:\n  layersim solve examples/coated_gold.toml\n"
               "  layersim plot coated_gold.lsim --wi 30,0 -o slices.png\n"
               "  layersim COMMAND --help      (examples of each command)",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--version", action="version", version=f"layersim {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    quiet = _Parser(add_help=False)
    quiet.add_argument("-q", "--quiet", action="store_true",
                       help="no progress bars (they are drawn only on a terminal anyway)")

    sp = _subparser(sub, "plan", "print the discretisation plan of a scene (no heavy work)")
    sp.add_argument("scene", help="scene file (TOML)")
    sp.set_defaults(func=cmd_plan)
    sp = _subparser(sub, "import-pbrt", "write the scene of a pbrt-v4 material as TOML")
    sp.add_argument("file", help="pbrt-v4 scene text with one material")
    sp.add_argument("-o", "--output", help="scene file to write (default: FILE_STEM.toml in "
                                           "the current directory)")
    sp.set_defaults(func=cmd_import_pbrt)
    sp = _subparser(sub, "solve", "solve a scene with the adding equations", [quiet])
    sp.add_argument("scene", help="scene file (TOML)")
    sp.add_argument("-o", "--output", help="where to save the solved BSDF (default: "
                                           "SCENE_STEM.lsim in the current directory)")
    sp.add_argument("--like", metavar="STACK.lsim",
                    help="solve on the discretisation (n, md, rule) of this saved BSDF, so "
                         "that the two can be added or subtracted")
    sp.add_argument("--tol", type=float, metavar="T",
                    help="solve to this relative error of bin energies (e.g. 1e-3): n and md "
                         "are chosen by a ladder of solves, and the error estimate printed")
    sp.add_argument("--estimate-error", action="store_true",
                    help="estimate the discretisation error from companion solves at n and "
                         "md over sqrt 2 and over 2 (about half as much time again)")
    sp.set_defaults(func=cmd_solve)
    sp = _subparser(sub, "info", "print the summary and albedos of a saved BSDF (.lsim) or a "
                                 ".bsdf file")
    sp.add_argument("file", help="file written by 'layersim solve' or 'layersim export'")
    sp.set_defaults(func=cmd_info)
    sp = _subparser(sub, "bench", "benchmark report: solver vs Monte Carlo, stability suite")
    sp.add_argument("--out", required=True, help="output folder")
    sp.add_argument("--quick", action="store_true", help="small version (< 2 min on 2 cores)")
    sp.add_argument("--stability", action="store_true", help="also run the stability suite")
    sp.add_argument("--backend", action="append", help="Monte Carlo backend(s) to time "
                    "(auto, warp-cpu, warp-cuda, opencl); repeatable")
    sp.add_argument("--scenes", help="folder of scene files (default benchmarks/scenes)")
    sp.add_argument("--scene", action="append", help="run only this scene (file stem); "
                    "repeatable")
    sp.add_argument("--seed", type=int, default=1, help="seed of the Monte Carlo runs "
                    "(default 1)")
    sp.add_argument("--render", action="store_true", help="also render each isotropic scene "
                    "from the solver's and the walk's bins, with their difference "
                    "(SCENE_render.png)")
    sp.add_argument("--render-paths", type=int, help="Monte Carlo paths per incidence angle "
                    "of --render (default 1e6, 2e5 with --quick)")
    sp.set_defaults(func=cmd_bench)

    sp = _subparser(sub, "design", "inverse design (Bati et al. 2021): stacks whose "
                                   "lobes at normal incidence match target lobes", [quiet])
    sp.add_argument("targets", help="targets file (TOML: [[lobe]] energy, roughness, layers, "
                                    "base)")
    sp.add_argument("-o", "--output", help="write the preferred stack as a scene file (TOML)")
    sp.add_argument("--plot", help="image of the target lobes against the exact solve's")
    sp.add_argument("--candidates", type=int, default=3, help="how many candidate stacks to "
                                                             "print (default 3)")
    sp.add_argument("--no-verify", action="store_true", help="skip the exact solve")
    sp.add_argument("--exact", action="store_true", help="refine the design by exact fits to "
                    "the target lobes, report both designs (-o writes the refined one)")
    sp.set_defaults(func=cmd_design)

    src_help = "scene (.toml, solved on the fly), saved BSDF (.lsim) or .bsdf file"
    sp = _subparser(sub, "export", "write a BSDF file for renderers: a tabulated Fourier "
                                   "BSDF (.bsdf) for layerlab, Mitsuba 0.6, pbrt-v3 or the "
                                   "Layer Laboratory, or (--format rgl) an RGL material for "
                                   "Mitsuba 3 and pbrt-v4 (reflection only)",
                    [quiet])
    sp.add_argument("source", help=src_help)
    sp.add_argument("-o", "--output", help="output file (default: SOURCE_STEM.bsdf, with "
                                           "--format rgl SOURCE_STEM.rgl.bsdf)")
    sp.add_argument("--format", choices=("bsdf", "rgl"), default="bsdf",
                    help="bsdf: tabulated Fourier series (default); rgl: the RGL tensor "
                         "format of Mitsuba 3's and pbrt-v4's 'measured' material, top-side "
                         "REFLECTION ONLY (a stack's transmission is dropped, with a note)")
    sp.add_argument("--resolution", type=int, default=None,
                    help="rgl: side of each incident direction's sample square (4-256; "
                         "default 32); prints the measured reconstruction error")
    sp.add_argument("--color", choices=("spectral", "rgb"), default="spectral",
                    help="rgl: 'spectral' (Mitsuba 3 spectral variants, pbrt-v4; RGB "
                         "channels become spectra with those sRGB values) or 'rgb' (Mitsuba 3 "
                         "RGB variants only)")
    sp.add_argument("--wavelengths", metavar="W1[,W2,W3]",
                    help="rgl: channel wavelengths in nm (default: the scene's [stack] "
                         "wavelengths)")
    sp.add_argument("--version", type=int, choices=(1, 2), default=None,
                    help="1: isotropic format of layerlab/Mitsuba 0.6/pbrt-v3 (default for "
                         "isotropic sources); 2: the Layer Laboratory's anisotropic layout "
                         "(default for anisotropic sources)")
    sp.add_argument("--relerr", type=float, default=0.0,
                    help="version 2: drop each pair's coefficients below this fraction of its "
                         "largest (e.g. 1e-3 as the Layer Laboratory does; default 0 keeps all)")
    sp.add_argument("--alpha", metavar="A_TOP,A_BOTTOM",
                    help="Beckmann-equivalent roughness (>= 0) of the top and bottom surface, "
                         "a hint for renderers written into the header (default 0,0)")
    sp.set_defaults(func=cmd_export)
    sp = _subparser(sub, "eval", "print f(wi, wo) in 1/sr (per channel for RGB)", [quiet])
    sp.add_argument("source", help=src_help)
    sp.add_argument("--wi", required=True, help="X,Y,Z toward the light (local frame, z = "
                                                "normal; normalised)")
    sp.add_argument("--wo", required=True, help="X,Y,Z toward the viewer (local frame; "
                                                "normalised)")
    sp.set_defaults(func=cmd_eval)
    sp = _subparser(sub, "plot", "draw hemispherical slices (--wi) or the operator's blocks "
                                 "(--blocks) into a PNG", [quiet])
    sp.add_argument("source", help=src_help)
    sp.add_argument("--wi", help="THETA,PHI of the light in degrees (theta from the normal)")
    sp.add_argument("--blocks", action="store_true", help="draw the blocks Rb | Ttb over Tbt | Rt (Rt only when opaque)")
    sp.add_argument("--order", type=int, help="with --blocks: Fourier order l to show "
                                              "(default: the BSDF at --phi-d)")
    sp.add_argument("--phi-d", type=float, default=0.0,
                    help="with --blocks: azimuth difference in degrees (0 = specular)")
    sp.add_argument("--percentile", type=float, default=99.0, metavar="P",
                    help="with --blocks: each panel's colour scale ends at this percentile of "
                         "its values (default 99, as layerlab; brighter values saturate and "
                         "the colour bar says so); 100 shows the full range")
    sp.add_argument("--log", action="store_true", help="with --wi: logarithmic colours")
    sp.add_argument("-o", "--output", help="PNG file (default: SOURCE_STEM_slices.png or "
                                           "_blocks.png)")
    sp.set_defaults(func=cmd_plot)
    sp = _subparser(sub, "subtract", "recover the unknown layer of a solved stack "
                                     "(subtracting equations, or a fit with --model)",
                    parents=[quiet])
    sp.add_argument("stack", help="solved stack (.lsim written by 'layersim solve')")
    sp.add_argument("known", nargs="?", help="solved known layer on the stack's discretisation "
                    "('layersim solve KNOWN.toml --like STACK.lsim'); optional with --model, "
                    "where it is checked against the template and subtracted plainly too")
    sp.add_argument("--side", choices=("top", "bottom"), required=True,
                    help="where the known layer sits in the stack")
    sp.add_argument("--model", metavar="TEMPLATE",
                    help="fit this template of the whole stack (known layers fixed, the "
                         "unknown one's fields { fit = [lo, hi] }) and solve its unknown part")
    sp.add_argument("-o", "--output", help="where to save the recovered layer (default: "
                                           "STACK-minus-KNOWN.lsim)")
    sp.add_argument("--eps", type=float, help="Tikhonov parameter (default: automatic, "
                                              "discrepancy principle)")
    sp.add_argument("--noise", type=float, help="relative noise level of the stack (default: "
                                                "estimated from its reciprocity defect)")
    sp.set_defaults(func=cmd_subtract)
    _add_fit(sub, quiet)
    _add_fit_ndf(sub)
    _add_mc(sub, quiet)
    _add_render(sub, src_help, quiet)
    return p


def _add_mc(sub, quiet) -> None:
    sp = _subparser(sub, "mc", "Monte Carlo ground truth: walks of a scene from given "
                               "directions (or of a sweep file) into a resumable result file "
                               "(.npz)", [quiet])
    sp.add_argument("scene", help="scene file (TOML), or a sweep file (TOML with a [sweep] "
                                  "table: scenes x angles x channels, docs/conventions.md)")
    sp.add_argument("--wi", action="append", metavar="THETA,PHI",
                    help="direction of the light in degrees (theta from the normal, 0-180, "
                         "not 90); repeatable: one walk per direction and channel")
    sp.add_argument("--paths", metavar="N",
                    help="paths per walk (default 1e6); with --stderr the cap")
    sp.add_argument("--stderr", type=float, metavar="E",
                    help="stop each walk once the standard errors of R, T and A are <= E")
    sp.add_argument("--bins", metavar="N_MU,N_PHI",
                    help="equal bins in |cos theta_o| and phi_o per side (default 18,36)")
    sp.add_argument("--backend", help="auto (default), warp-cpu, warp-cuda, opencl")
    sp.add_argument("--seed", type=int, help="seed (default 0)")
    sp.add_argument("--batch", metavar="N", help="paths per range, the unit of work and of "
                                                 "the stopping test (default: the backend's)")
    sp.add_argument("--max-steps", type=int,
                    help="cap on the interactions of one path (default 100000)")
    sp.add_argument("-o", "--output", required=True, metavar="OUT",
                    help="result file (.npz); an existing one of the same run is continued")
    sp.add_argument("--restart", action="store_true",
                    help="overwrite OUT instead of continuing it")
    sp.add_argument("--plot", metavar="PNG", help="picture of the bins (default: OUT with "
                                                  ".png)")
    sp.add_argument("--no-plot", action="store_true", help="no picture")
    from . import mc_scaleout
    mc_scaleout.add_options(sp)
    sp.set_defaults(func=cmd_mc)
    sp = _subparser(sub, "compare", "compare a Monte Carlo result file with a solve or "
                                    "another result file, walk by walk", [quiet])
    sp.add_argument("result", help="result file of 'layersim mc'")
    sp.add_argument("source", help="scene (.toml, solved with the default plan), saved BSDF "
                                   "(.lsim), .bsdf file or another result file")
    sp.add_argument("--plot", metavar="PNG", help="z-score maps per walk and side")
    sp.set_defaults(func=cmd_compare)


def cmd_mc(args) -> int:
    from . import mc_commands
    out = _output(args.output, "-o")
    image = None if args.no_plot else _image(args.plot or out.with_suffix(".png"), "--plot")
    return mc_commands.run_mc(args, out, image, not args.quiet and sys.stderr.isatty())


def cmd_compare(args) -> int:
    from . import mc_commands
    image = _image(args.plot, "--plot") if args.plot else None
    return mc_commands.run_compare(args, lambda path: _load(path, args), image)


def _add_render(sub, src_help: str, quiet) -> None:
    sp = _subparser(sub, "render", "render a sphere of the material with Mitsuba 3 (the "
                                   "layersim plug-in)", [quiet])
    sp.add_argument("source", help=src_help.replace(" or .bsdf file", ""))
    sp.add_argument("-o", "--output", help="PNG file (default: SOURCE_STEM_render.png)")
    sp.add_argument("--spp", type=int, default=16, help="samples per pixel (default 16)")
    sp.add_argument("--resolution", default="128,128", metavar="W,H",
                    help="image width and height in pixels (default 128,128)")
    sp.set_defaults(func=cmd_render)


#: Largest --spp and image side that ``layersim render`` takes.
RENDER_MAX_SPP, RENDER_MAX_SIDE = 4096, 4096


def cmd_render(args) -> int:
    if not 1 <= args.spp <= RENDER_MAX_SPP:
        raise ValueError(f"--spp {args.spp}: samples per pixel must be in 1..{RENDER_MAX_SPP}")
    size = _vector(args.resolution, "--resolution", "W,H")
    if np.any(size != np.round(size)) or not np.all((1 <= size) & (size <= RENDER_MAX_SIDE)):
        raise ValueError(f"--resolution {args.resolution}: width and height must be whole "
                         f"numbers in 1..{RENDER_MAX_SIDE}")
    out = _output(args.output or Path(args.source).stem + "_render.png", "-o")
    if out.suffix.lower() != ".png":
        raise ValueError(f"-o {out}: the image is written as PNG; give a .png name")
    try:
        import mitsuba  # noqa: F401
    except ImportError as exc:
        raise LayersimError(f"render needs Mitsuba 3 ({exc}): pip install mitsuba") from None
    from .mitsuba.render import render
    bsdf = _load(args.source, args)
    if not isinstance(bsdf, BSDF):
        raise ValueError(f"{args.source}: a .bsdf table cannot be rendered; give the scene "
                         "or the saved BSDF (.lsim)")
    with tempfile.TemporaryDirectory() as tmp:
        lsim = bsdf.save(Path(tmp) / "stack.lsim")
        variant = render(lsim, out, (int(size[0]), int(size[1])), args.spp)
    print(f"wrote {out} ({int(size[0])} x {int(size[1])}, {args.spp} spp, Mitsuba {variant})")
    return 0


def _add_fit(sub, quiet) -> None:
    sp = _subparser(sub, "fit", "fit the free values of a template ({ fit = [lo, hi] }) to a "
                                "solved or tabulated BSDF or point measurements by exact "
                                "transport",
                    parents=[quiet])
    sp.add_argument("template", help="scene file (.toml) with free values")
    sp.add_argument("target", help="saved BSDF (.lsim), tabulated BSDF (.bsdf: Fourier or "
                                   "RGL), MERL file (.binary) or point measurements (.npz or "
                                   ".csv; layouts in docs/conventions.md)")
    sp.add_argument("-o", "--output", required=True, help="fitted scene to write (.toml)")
    sp.add_argument("--plot", metavar="PNG", help="also draw the target against the fit")
    sp.set_defaults(func=cmd_fit)


def cmd_fit(args) -> int:
    from .fit import Template, as_target, fit
    from .fit.files import read_target
    from .fit.plot import plot_fit
    from .tomlwrite import dumps
    out = _output(args.output, "-o")
    plot = _image(args.plot, "--plot") if args.plot else None
    template = Template(args.template)
    raw = read_target(args.target, template.scene(template.start).wavelengths)
    target = as_target(raw)
    result = fit(template, target, progress=None if not args.quiet else False)
    out.write_text(dumps(result.scene.to_dict(), f"fitted by layersim fit to {args.target}"),
                   encoding="utf-8")
    print(result.summary())
    print(f"wrote {out}")
    if plot:
        plot_fit(plot, result, target, None if isinstance(raw, tuple) else raw)
        print(f"wrote {plot}")
    return 0


def _add_fit_ndf(sub) -> None:
    from .ndf.halfgrid import SYMMETRIES
    sp = _subparser(sub, "fit-ndf", "fit a tabulated NDF to single-view measurements (Wang et "
                                    "al. 2008): partial NDF, completion, table")
    sp.add_argument("measurements", help="measurement file (.npz or .csv), one view")
    sp.add_argument("-o", "--output", required=True, help="NDF table to write (.npz)")
    sp.add_argument("--complete", nargs="+", default=(), metavar="OTHER",
                    help="measurement files of rotated samples or other views to complete from")
    sp.add_argument("--symmetry", choices=SYMMETRIES, help="a symmetry of the surface to use "
                                                           "for completion (stated, not tested)")
    sp.add_argument("--fill", nargs="?", const="flat", choices=("flat", "zero"), default=False,
                    help="interpolate what stays undetermined; at the horizon flat (default, "
                         "GGX-like tails) or zero (fast-falling tails, e.g. Beckmann)")
    sp.add_argument("--partial", action="store_true", help="write the partial table as is")
    sp.add_argument("--unconstrained", action="store_true",
                    help="shadowing from the partial NDF alone (biased; for comparison)")
    sp.add_argument("--grid", default="91x180", help="N_THETA x N_PHI of the table")
    sp.add_argument("--max-light-theta", type=float, default=80.0,
                    help="exclude lights farther than this from the normal (degrees)")
    sp.add_argument("--plot", metavar="PNG", help="also draw the NDF and its confidence")
    sp.set_defaults(func=cmd_fit_ndf)


def cmd_fit_ndf(args) -> int:
    from .ndf.workflow import fit_files, parse_grid
    # np.savez adds .npz to a name without it
    out = Path(args.output)
    _output(out if out.suffix == ".npz" else out.with_name(out.name + ".npz"), "-o")
    if args.plot:
        _image(args.plot, "--plot")
    for line in fit_files(args.measurements, args.output, args.complete, parse_grid(args.grid),
                          not args.unconstrained, args.symmetry, args.fill, args.partial,
                          args.max_light_theta, args.plot):
        print(line)
    return 0


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


def _check_device(name: str) -> None:
    """Refuse an unusable ``LAYERSIM_DEVICE`` before the command runs, on one line: bench and
    design fall back to Monte Carlo when a solve is refused, and would otherwise go on (and
    print the refusal among their output) instead of stopping; commands that solve nothing
    are refused too, so that the variable is checked the same way everywhere."""
    if name != "cpu":
        from .kernels.runtime import device_for
        device_for()


def main(argv=None) -> int:
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(_attach_negative_values(argv))
    args.argv = argv
    try:
        config = settings()             # a bad LAYERSIM_* value: one line, before any work
        memory.cap_arenas(config.malloc_arenas)         # the command owns its process
        _check_device(config.device)
        return args.func(args)
    except (LayersimError, ValueError, OSError) as exc:
        if isinstance(exc, OSError) and exc.strerror and exc.filename:
            msg = f"{exc.filename}: {exc.strerror}"
        else:
            msg = str(exc).replace("\n", " ")
        print(f"layersim: error: {msg}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        print("layersim: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
