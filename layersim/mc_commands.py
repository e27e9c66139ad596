"""The bodies of ``layersim mc`` (Monte Carlo ground truth into a result file) and ``layersim
compare`` (a result file against a solve or another result file).

:mod:`layersim.cli` parses the options and checks the output paths; these functions check the
rest of the input (each error names its option, before any walk) and print the reports. The
run loop is :mod:`layersim.montecarlo.campaign`, the file :mod:`layersim.montecarlo.resultfile`.
"""

from __future__ import annotations

import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from . import mc_scaleout
from .montecarlo import compare, resultfile
from .montecarlo.backends import available_backends, resolve_backend, why_unavailable
from .montecarlo.campaign import Stopped, run_walks, walks_of
from .montecarlo.checks import check_int, check_wi
from .montecarlo.driver import DEFAULT_BATCH, MAX_BATCH
from .montecarlo.sweep import is_sweep_file, read_sweep
from .scene import Scene

__all__ = ["run_mc", "run_compare", "direction", "parse_count", "parse_bins", "EXIT_STOPPED"]

#: Exit status after Ctrl-C (128 + SIGINT), as a shell reports an interrupted command.
EXIT_STOPPED = 130


def direction(text: str, option: str = "--wi") -> np.ndarray:
    """``"THETA,PHI"`` in degrees (theta from the +z normal, 0-180 but not 90) -> unit vector."""
    try:
        theta, phi = (float(x) for x in text.split(","))
    except ValueError:
        raise ValueError(f"{option} must be THETA,PHI in degrees, got {text!r}") from None
    if not (math.isfinite(theta) and math.isfinite(phi)) or not 0.0 <= theta <= 180.0 \
            or theta == 90.0:
        raise ValueError(f"{option} {text}: THETA must be in [0, 180] degrees and not 90 (the "
                         "horizon), PHI finite")
    t, p = math.radians(theta), math.radians(phi)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def parse_count(text: str, option: str, hi: int | None = None) -> int:
    """A positive integer written as ``1000000`` or ``1e6``."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value != int(value) or value < 1 or (hi and value > hi):
        raise ValueError(f"{option} must be a whole number >= 1" + (f" and <= {hi}" if hi
                                                                     else "")
                         + f" (e.g. 1e6), got {text!r}")
    return int(value)


def parse_bins(text: str) -> tuple:
    """``"N_MU,N_PHI"`` -> equal-width edges in ``|cos theta_o|`` and ``phi_o`` (radians)."""
    parts = text.split(",")
    if len(parts) != 2:
        raise ValueError(f"--bins must be N_MU,N_PHI (numbers of bins), got {text!r}")
    n_mu, n_phi = (parse_count(p, "--bins", 10_000) for p in parts)
    return np.linspace(0.0, 1.0, n_mu + 1), np.linspace(0.0, 2 * math.pi, n_phi + 1)


def _incident(text: str, scene: Scene) -> np.ndarray:
    """``--wi THETA,PHI`` as a direction that lights ``scene`` (the error names the option)."""
    try:
        return check_wi(direction(text), scene)
    except ValueError as exc:
        message = str(exc)
        raise ValueError(message if message.startswith("--wi") else f"--wi {text}: {message}") \
            from None


def _backend(name: str) -> str:
    resolved = resolve_backend(name)
    if resolved not in available_backends():
        raise ValueError(f"--backend {name}: not available on this machine (available: "
                         f"{', '.join(available_backends())}): "
                         f"{why_unavailable(resolved) or 'no device'}")
    return resolved


def _stderr(value) -> float | None:
    if value is None:
        return None
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"--stderr must be a positive number, got {value:g}")
    return float(value)


#: ``layersim mc`` options that a sweep file sets itself, and their defaults for one scene.
SCENE_OPTIONS = {"wi": None, "paths": "1e6", "stderr": None, "bins": "18,36", "backend": "auto",
                 "seed": 0, "max_steps": 100_000}


def _scene_run(args) -> dict:
    """The walks of ``layersim mc SCENE --wi ...`` (backend not yet resolved) and their record."""
    for name, default in SCENE_OPTIONS.items():
        if getattr(args, name) is None:
            setattr(args, name, default)
    if not args.wi:
        raise ValueError("--wi THETA,PHI is required for a scene (a sweep file lists angles)")
    scene = Scene.from_toml(args.scene)
    wis = [_incident(w, scene) for w in args.wi]
    mu_edges, phi_edges = parse_bins(args.bins)
    seed = check_int("--seed", args.seed, 0, (1 << 64) - 1)
    return dict(walks=walks_of(scene, wis, mu_edges, phi_edges, seed, args.max_steps,
                               args.backend),
                paths=parse_count(args.paths, "--paths"), target=_stderr(args.stderr),
                backend=args.backend, scene_texts=[Path(args.scene).read_text(encoding="utf-8")],
                scene_names=[scene.name], walk_scene=None,
                walk_channel=[c for _ in wis for c in range(scene.channels)])


def _sweep_run(args) -> dict:
    """The walks of ``layersim mc SWEEP.toml`` (backend not yet resolved) and their record."""
    given = [n for n in SCENE_OPTIONS if getattr(args, n) is not None]
    if given:
        option = "--" + given[0].replace("_", "-")
        raise ValueError(f"{option}: the sweep file {args.scene} sets it ([sweep] "
                         f"{'angles' if given[0] == 'wi' else given[0]}); drop {option}")
    walks, texts, o = read_sweep(args.scene, resolve=lambda name: name)
    return dict(walks=walks, paths=o["paths"], target=o["stderr"], backend=o["backend"],
                scene_texts=list(texts.values()), scene_names=o["scene_names"],
                walk_scene=o["walk_scene"], walk_channel=o["walk_channel"])


def run_mc(args, out: Path, image: Path | None, progress: bool) -> int:
    """``layersim mc``: the walks of SCENE from each ``--wi`` (or of a sweep file) into ``out``
    (resuming it), on the executor the options ask for; a summary per walk, and the bin
    picture ``image``. Returns the exit status."""
    mc_scaleout.check_options(args)
    run = _sweep_run(args) if is_sweep_file(args.scene) else _scene_run(args)
    batch = parse_count(args.batch, "--batch", MAX_BATCH) if args.batch else None
    executor, backend = mc_scaleout.make_executor(args, run["backend"], _backend)
    try:
        walks = [replace(w, backend=backend) for w in run["walks"]]
        run_walks(walks, run["paths"], batch=batch or DEFAULT_BATCH[backend],
                  target_stderr=run["target"], executor=executor, out=out,
                  scene_texts=run["scene_texts"], scene_names=run["scene_names"],
                  walk_scene=run["walk_scene"], walk_channel=run["walk_channel"],
                  restart=args.restart, progress=progress)
    except Stopped as stop:
        print(f"stopped at {stop.paths:,} paths; rerun the same command to continue",
              file=sys.stderr)
        return EXIT_STOPPED
    finally:
        if executor is not None:
            executor.close()
    f = resultfile.load(out)
    print(summary(f))
    print(f"wrote {out}")
    if image is not None:
        from .montecarlo import plots     # matplotlib is slow to import
        print(f"wrote {plots.plot_bins(f, image)}")
    return 0


def summary(f) -> str:
    """Per walk of result file ``f``: paths, R, T, A with standard errors."""
    lines = [f"Monte Carlo ({f.backend}, {f.device}): seed {int(f.seed)}, "
             f"{int(f.particles.sum()):,} paths in {float(f.seconds):.2f} s"]
    for i in range(f.n_walks):
        est = "; ".join(f"{k} = {f.data[key][i]:.6f} +- {f.data[key + '_stderr'][i]:.1e}"
                       for k, key in (("R", "reflectance"), ("T", "transmittance"),
                                      ("A", "absorbed")))
        met = ", stderr target met" if f.target_met[i] else ""
        lines.append(f"  {f.label(i)}: {int(f.particles[i]):,} paths{met}; {est}")
        if f.truncated[i]:
            lines.append(f"    {int(f.truncated[i])} walks reached max steps {int(f.max_steps)}"
                         " (their energy counts as absorbed)")
    return "\n".join(lines)


def is_result_file(path) -> bool:
    """Whether ``path`` is a ``layersim mc`` result file (a numpy archive with its format)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return "format" in z.files and str(z["format"]) == resultfile.FORMAT
    except (OSError, ValueError, EOFError):
        return False


def _against_bsdf(f, bsdf, source) -> list:
    if not hasattr(bsdf, "bin_energies"):
        raise ValueError(f"{source}: layersim cannot convert this .bsdf file to operators, so "
                         "its bin energies are not available")
    out = []
    for i in range(f.n_walks):
        c = int(f.walk_channel[i])
        channels = int(f.walk_channel[f.walk_scene == f.walk_scene[i]].max()) + 1
        if channels != bsdf.channels:
            raise ValueError(f"{source} has {bsdf.channels} channel(s), but the scene of walk "
                             f"{i} ({f.label(i)}) in {f.path} has {channels}")
        pick = (lambda v: np.asarray(v)[..., c]) if bsdf.channels > 1 else np.asarray
        R, T = (float(pick(v)) for v in bsdf.albedo(f.wi[i]))
        bins = {s: pick(v) for s, v in bsdf.bin_energies(f.wi[i], f.mu_edges,
                                                          f.phi_edges).items()}
        out.append(compare.against_values(f.result(i), R, T, bins))
    return out


def _against_file(f, g) -> list:
    same = (f.n_walks == g.n_walks and np.array_equal(f.wi, g.wi)
            and np.array_equal(f.walk_channel, g.walk_channel)
            and np.array_equal(f.mu_edges, g.mu_edges) and np.array_equal(f.phi_edges, g.phi_edges))
    if not same:
        raise ValueError(f"{g.path} does not hold the same walks as {f.path} (incident "
                         "directions, channels and bins must match)")
    return [compare.against_walk(f.result(i), g.result(i)) for i in range(f.n_walks)]


def _describe(f, i: int, cmp) -> list:
    def albedo(key):
        est, err, other = cmp.albedo[key]
        return f"{key}: MC {est:.7f} +- {err:.1e}, other {other:.7f} ({cmp.albedo_z[key]:+.2f} sigma)"
    z, side, a, b = cmp.largest()
    mu, ph = f.mu_edges, np.degrees(f.phi_edges)
    th = np.degrees(np.arccos([mu[a + 1], mu[a]]))
    n = cmp.populated().size
    transmits = max(cmp.albedo["T"][0], cmp.albedo["T"][2]) > 0     # else opaque: no T line
    return [f"  {f.label(i)}: {albedo('R')}" + (f"; {albedo('T')}" if transmits else ""),
            f"    bins within 3 sigma: {100 * cmp.within(3.0):.1f} % of {n} populated; largest "
            f"|z| {z:.2f} ({side}, theta_o {th[0]:.1f}-{th[1]:.1f} deg, phi_o {ph[b]:.0f}-"
            f"{ph[b + 1]:.0f} deg)"]


def run_compare(args, load_source, image: Path | None) -> int:
    """``layersim compare``: each walk of RESULT against SOURCE (``load_source(path)`` gives a
    BSDF of a scene, ``.lsim`` or ``.bsdf`` file) or another result file."""
    f = resultfile.load(args.result)
    if is_result_file(args.source):
        comparisons = _against_file(f, resultfile.load(args.source))
        print(f"{args.result} against the walks of {args.source} (both standard errors)")
    else:
        if Path(args.source).suffix.lower() == ".toml":
            print(f"solving {args.source} with the default plan")
        comparisons = _against_bsdf(f, load_source(args.source), args.source)
        print(f"{args.result} against the solve of {args.source}")
    for i, cmp in enumerate(comparisons):
        print("\n".join(_describe(f, i, cmp)))
    if image is not None:
        from .montecarlo import plots     # matplotlib is slow to import
        plots.plot_z([c.z for c in comparisons], [f.label(i) for i in range(f.n_walks)],
                     f.mu_edges, f.phi_edges, image)
        print(f"wrote {image}")
    return 0
