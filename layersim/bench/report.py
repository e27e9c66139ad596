"""Write a benchmark run: ``results.json`` (raw numbers), ``report.md`` (tables) and PNG plots
(error against run time per scene, hemispherical slices solver vs Monte Carlo, throughput, and
with ``--render`` the rendered comparison of :mod:`.renderfigure`)."""

from __future__ import annotations

import json
import math
import os
import platform
import subprocess
import time
from pathlib import Path

import numpy as np
import scipy

from ..kernels.runtime import cuda_available
from . import renderfigure
from .statistical import markdown as statistical_markdown


def machine_info(command: str) -> dict:
    info = {"cpu": _cpu_name(), "cores": os.cpu_count(), "platform": platform.platform(),
            "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "command": command,
            "date": time.strftime("%Y-%m-%d %H:%M:%S")}
    try:            # warp and pyopencl are imported here only to describe the machine
        import warp
        info["warp"] = warp.config.version
        if cuda_available():
            info["gpu"] = [str(d) for d in warp.get_cuda_devices()]
    except Exception:  # pragma: no cover - warp is a dependency; keep the report robust
        pass
    from ..montecarlo.opencl_device import checked_devices
    info["opencl"] = [c.label + ("" if c.ok else f": cannot build ({c.reason})")
                      for c in checked_devices()]
    try:
        info["layersim_commit"] = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
            cwd=Path(__file__).resolve().parent, timeout=5).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        info["layersim_commit"] = None
    return info


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _public(entry: dict) -> dict:
    return {k: v for k, v in entry.items() if not k.startswith("_")}


def write(out: Path, machine: dict, scenes: list, stability: list, settings) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    results = {"machine": machine,
               "settings": {"angles": list(settings.angles), "n_mu": settings.n_mu,
                            "n_phi": settings.n_phi, "scales": list(settings.scales),
                            "reference_scale": settings.reference_scale,
                            "particles": list(settings.particles),
                            "check_particles": settings.check_particles,
                            "seed": settings.seed,
                            "render": _render_settings(settings)},
               "scenes": [_public(s) for s in scenes], "stability": stability}
    (out / "results.json").write_text(json.dumps(results, indent=1, default=_json_default))
    images = {}
    for s in scenes:
        images[s["name"]] = _plots(out, s, settings)
    throughput = _throughput_plot(out, scenes)
    (out / "report.md").write_text(_markdown(results, images, throughput))
    return results


def _render_settings(settings) -> dict | None:
    """The settings of the rendered comparison (None when ``--render`` is off)."""
    if not settings.render:
        return None
    return {"angles": settings.render_angles, "bins": list(settings.render_bins),
            "particles": settings.render_particles, "resolution": settings.render_resolution,
            "spp": settings.render_spp}


def _json_default(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(type(x).__name__)


# ---- plots ---------------------------------------------------------------------------------

def _plt():
    """pyplot on the Agg backend, imported when a plot is drawn (matplotlib is slow to import)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def error_time_figure(s: dict):
    """Error against wall time of one scene entry ``s`` of results.json (pyplot figure; the
    caller saves and closes it): the solver's rungs (labelled n), the solves to a tolerance,
    the Monte Carlo ladder per backend and the statistical model, titled with the reference
    (:func:`reference_text`)."""
    plt = _plt()
    solver = [r for r in s.get("solver", []) if "error" in r]
    tols = [r for r in s.get("tolerance", []) if "error" in r]
    mc = [r for r in s.get("montecarlo", []) if "error" in r]
    fig, ax = plt.subplots(figsize=(5.5, 4.3))
    labels = []                          # (text, x, y, above): drawn once x is fixed
    if solver:
        ax.loglog([r["seconds"] for r in solver], [r["error"] for r in solver], "o-",
                  label="Fourier solver")
        labels += [(f"n={r['n']}", r["seconds"], r["error"], True) for r in solver]
    if tols:
        ax.loglog([r["seconds"] for r in tols], [r["error"] for r in tols], "D:",
                  label="solver to a tolerance (error; tol marked)")
        labels += [(f"tol {r['tol']:g}", r["seconds"], r["error"], False) for r in tols]
    for backend in sorted({r["backend"] for r in mc}):
        rows = [r for r in mc if r["backend"] == backend]
        ax.loglog([r["seconds"] for r in rows], [r["error"] for r in rows], "s--",
                  label=f"Monte Carlo ({backend})")
    stat = s.get("statistical", {})
    if "error" in stat:
        ax.loglog([stat["seconds"]], [stat["error"]], "D", label="statistical model")
    ax.margins(x=0.08, y=0.12)
    _annotate_inside(ax, labels)
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel("relative L2 error of bin energies")
    ax.set_title(f"{s['name']}\n{reference_text(s)}", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _plots(out: Path, s: dict, settings) -> list[str]:
    plt = _plt()
    names = []
    solver = [r for r in s.get("solver", []) if "error" in r]
    mc = [r for r in s.get("montecarlo", []) if "error" in r]
    if solver or mc:
        fig = error_time_figure(s)
        name = f"{s['name']}_error_time.png"
        fig.savefig(out / name, dpi=110)
        plt.close(fig)
        names.append(name)
    ref = s.get("_ref")
    mcb = s.get("_mc_bins")
    if ref is not None:
        panels = [("reference" if s["reference"].get("kind") == "solver" else "Monte Carlo "
                   "reference", ref[0])]
        if mcb is not None and s["reference"].get("kind") == "solver":
            panels.append((f"Monte Carlo ({mc[-1]['particles']:.0e} paths)", mcb))
        name = _slices(out, s["name"], panels, settings)
        names.append(name)
    if s.get("_render_images"):
        fig = renderfigure.figure(s["name"], s["render"], s["_render_images"])
        name = f"{s['name']}_render.png"
        fig.savefig(out / name, dpi=110)
        plt.close(fig)
        names.append(name)
    return names


def _annotate_inside(ax, labels) -> None:
    """Label points ``(text, x, y, above)`` on a log-log axis, each on the side of its point
    that faces the middle of the axis, so that labels of the rightmost points stay inside
    the figure."""
    lo, hi = ax.get_xlim()
    middle = math.sqrt(lo * hi)
    for text, x, y, above in labels:
        right = x <= middle
        ax.annotate(text, (x, y), fontsize=7, textcoords="offset points",
                    xytext=(4 if right else -4, 4 if above else -10),
                    ha="left" if right else "right")


def reference_text(s: dict) -> str:
    """What the errors of scene entry ``s`` are measured against, in one line: the solve it
    uses as reference and how much finer it is than the finest solver rung (errors of a rung
    close to the reference include the reference's own error), or the Monte Carlo run."""
    ref = s.get("reference", {})
    if ref.get("kind") == "solver":
        rungs = [r["n"] for r in s.get("solver", []) if "n" in r]
        finer = (f", {ref['n'] / max(rungs):.2g}x the finest rung's n" if rungs else "")
        return f"reference: solve at n = {ref['n']}, md = {ref['md']}{finer}"
    if ref.get("kind") == "montecarlo":
        return f"reference: Monte Carlo, {ref.get('particles', 0):.0e} paths"
    return "no reference"


#: Outgoing elevations (degrees) of the labelled rings of the polar slices.
RINGS = (30.0, 60.0, 80.0)


def _slices(out: Path, name: str, panels, settings) -> str:
    """Hemispherical slices on the projected unit disk: the BSDF averaged over each bin
    (E_b / integral of cos over the bin), for the first incidence angle, top side, first
    channel; solver and Monte Carlo side by side with a shared colour scale. Rings mark the
    outgoing elevations :data:`RINGS` (radius sin theta_o), spokes the outgoing azimuth."""
    plt = _plt()
    mu, phi = settings.mu_edges, settings.phi_edges
    proj = 0.5 * np.outer(np.diff(mu ** 2), np.diff(phi))
    fig, axes = plt.subplots(1, len(panels), subplot_kw={"projection": "polar"},
                             figsize=(4.6 * len(panels) + 1.0, 4.6), layout="constrained")
    axes = np.atleast_1d(axes)
    values = [np.asarray(b)[0, 0, 0] / proj for _, b in panels]
    vmax = max(float(np.percentile(v, 99.5)) for v in values) or 1.0
    r = np.sqrt(1.0 - mu ** 2)
    for ax, (title, _), v in zip(axes, panels, values):
        mesh = ax.pcolormesh(phi, r, v, vmin=0, vmax=vmax, shading="flat", cmap="inferno")
        ax.set_title(title, fontsize=9, pad=14)
        ax.set_rgrids(np.sin(np.radians(RINGS)), [rf"${t:g}^\circ$" for t in RINGS],
                      angle=112.5, fontsize=7, color="0.85")
        ax.set_thetagrids([0, 90, 180, 270], [r"$\phi_o = 0^\circ$", r"$90^\circ$",
                                              r"$180^\circ$", r"$270^\circ$"], fontsize=7)
        ax.tick_params(axis="x", pad=2)
        ax.set_ylim(0, 1)
        ax.grid(color="0.6", lw=0.5, alpha=0.6)
    fig.colorbar(mesh, ax=list(axes), shrink=0.8, label=r"$f$ [1/sr], bin average")
    fig.suptitle(f"{name}: reflection at incidence {settings.angles[0]:g} deg; projected unit "
                 "disk, rings: outgoing elevation $\\theta_o$", fontsize=9)
    file = f"{name}_slices.png"
    fig.savefig(out / file, dpi=110)
    plt.close(fig)
    return file


def _throughput_plot(out: Path, scenes: list):
    rows = [(s["name"], r["backend"], r["paths_per_second"]) for s in scenes
            for r in s.get("montecarlo", []) if "paths_per_second" in r]
    if not rows:
        return None
    best = {}
    for scene, backend, pps in rows:
        best[(scene, backend)] = max(best.get((scene, backend), 0.0), pps)
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.4, 0.9 + 0.45 * len(best)), layout="constrained")
    labels = [f"{s} ({b})" for s, b in best]
    values = np.array(list(best.values()))
    y = np.arange(len(best))[::-1]                # the first scene on top
    ax.hlines(y, 0, values, color="0.75", lw=1)
    ax.plot(values, y, "o", color="C0")
    for yy, v in zip(y, values):
        ax.annotate(f"{v:.3g}", (v, yy), textcoords="offset points", xytext=(5, -3),
                    fontsize=7)
    ax.set_yticks(y, labels, fontsize=7)
    ax.set_xlim(0, 1.18 * values.max())
    ax.set_ylim(-0.6, len(best) - 0.4)
    ax.set_xlabel("paths per second (best of the ladder)")
    ax.set_title("Monte Carlo throughput per scene and backend", fontsize=10)
    ax.grid(axis="x", alpha=0.3)
    fig.savefig(out / "throughput.png", dpi=110)
    plt.close(fig)
    return {"file": "throughput.png", "rows": best}


# ---- markdown ------------------------------------------------------------------------------

def _fmt(x, spec=".3g"):
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return format(x, spec)


def _markdown(results: dict, images: dict, throughput) -> str:
    lines = _header_markdown(results["machine"])
    for s in results["scenes"]:
        lines += [f"## {s['name']}", "", f"Reference: {_reference_markdown(s)}.", ""]
        lines += _solver_markdown(s) + _tolerance_markdown(s) + _montecarlo_markdown(s)
        if s.get("statistical"):
            lines += statistical_markdown(s["statistical"], _fmt)
        if s.get("render"):
            lines += renderfigure.markdown(s["render"])
        for img in images.get(s["name"], []):
            lines += [f"![{img}]({img})", ""]
    if throughput:
        lines += _throughput_markdown(throughput)
    if results["stability"]:
        lines += _stability_markdown(results["stability"])
    return "\n".join(lines)


def _header_markdown(m: dict) -> list[str]:
    """Title, the machine ``m`` (results.json ``machine``) and how errors are measured."""
    return ["# layersim benchmark report", "",
            f"- machine: {m.get('cpu')} ({m.get('cores')} cores), {m.get('platform')}",
            f"- GPU: {', '.join(m['gpu']) if m.get('gpu') else 'none'}",
            f"- OpenCL: {'; '.join(m.get('opencl') or []) or 'none'}",
            f"- versions: python {m.get('python')}, numpy {m.get('numpy')}, scipy "
            f"{m.get('scipy')}, warp {m.get('warp')}, layersim commit "
            f"{m.get('layersim_commit')}",
            f"- command: `{m.get('command')}`", f"- date: {m.get('date')}", "",
            "Errors are relative L2 errors of the bin energies (both sides, all incidence "
            "angles) against the reference; `albedo err` is max |R - R_ref| + |T - T_ref|.",
            ""]


def _reference_markdown(s: dict) -> str:
    """What the errors of scene entry ``s`` are measured against, with the Monte Carlo check
    of a solver reference."""
    ref = s.get("reference", {})
    if ref.get("kind") == "solver":
        rungs = [r["n"] for r in s.get("solver", []) if "n" in r]
        desc = f"solver at n = {ref['n']}, md = {ref['md']}"
        if rungs:
            desc += (f" ({ref['n'] / max(rungs):.2g}x the n of the finest solver rung below; "
                     "each rung's error includes the reference's own, so a rung close to "
                     "it can show the reference's error rather than its own)")
        chk = ref.get("montecarlo_check")
        if chk:
            desc += (f"; checked against {chk['particles']:.0e} Monte Carlo paths "
                     f"({chk['backend']}): {100 * chk['within_3sigma']:.1f}% of bins within "
                     f"3 sigma, albedos within {chk['albedo_sigma']:.1f} sigma")
        return desc
    if ref.get("kind") == "montecarlo":
        return (f"Monte Carlo, {ref.get('particles', 0):.0e} paths (the solver refused: "
                f"{ref.get('solver_refused')})")
    return ref.get("note", "none")


def _solver_markdown(s: dict) -> list[str]:
    """The table of the solver's rungs of scene entry ``s`` (none: no lines)."""
    if not s.get("solver"):
        return []
    lines = ["| solver n | md | ms | seconds | error | albedo err |",
             "|---:|---:|---:|---:|---:|---:|"]
    for r in s["solver"]:
        if "refused" in r:
            lines.append(f"| refused at scale {r['scale']} | | | | | {r['refused']} |")
            continue
        lines.append(f"| {r['n']} | {r['md']} | {r.get('ms', 0)} | "
                     f"{r['seconds']:.2f} | {_fmt(r['error'])} | "
                     f"{_fmt(r['albedo_error'])} |")
    return lines + [""]


def _tolerance_markdown(s: dict) -> list[str]:
    """The table of the solves to a tolerance of scene entry ``s`` (none: no lines)."""
    if not s.get("tolerance"):
        return []
    lines = ["| tol | n | md | seconds | estimate | error |",
             "|---:|---:|---:|---:|---:|---:|"]
    for r in s["tolerance"]:
        if "refused" in r:
            lines.append(f"| {r['tol']:g} | refused | | | | {r['refused']} |")
            continue
        lines.append(f"| {r['tol']:g} | {r['n']} | {r['md']} | {r['seconds']:.2f} | "
                     f"{_fmt(r['estimate'])} | {_fmt(r['error'])} |")
    return lines + [""]


def _montecarlo_markdown(s: dict) -> list[str]:
    """The table of the Monte Carlo runs of scene entry ``s`` (none: no lines)."""
    if not s.get("montecarlo"):
        return []
    lines = ["| MC backend | paths | seconds | paths/s | error | stderr | in 3 sigma |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for r in s["montecarlo"]:
        if "refused" in r:
            lines.append(f"| {r['backend']} | {r['particles']:.0e} | refused: "
                         f"{r['refused']} | | | | |")
            continue
        lines.append(f"| {r['backend']} | {r['particles']:.0e} | {r['seconds']:.2f} | "
                     f"{r['paths_per_second']:.3g} | {_fmt(r['error'])} | "
                     f"{_fmt(r['stderr'])} | {100 * r['within_3sigma']:.1f}% |")
    return lines + [""]


def _throughput_markdown(throughput: dict) -> list[str]:
    """The best Monte Carlo throughput per scene and backend (:func:`_throughput_plot`)."""
    lines = ["## Throughput", "", "| scene | backend | paths/s |", "|---|---|---:|"]
    for (scene, backend), pps in throughput["rows"].items():
        lines.append(f"| {scene} | {backend} | {pps:.3g} |")
    return lines + ["", f"![throughput]({throughput['file']})", ""]


def _stability_markdown(cases: list) -> list[str]:
    """The outcomes of the stability suite (:mod:`layersim.bench.stability`)."""
    counts = {k: sum(1 for c in cases if c["outcome"] == k) for k in ("pass", "refused", "fail")}
    lines = ["## Stability suite", "",
             f"{counts['pass']} pass, {counts['refused']} refused, {counts['fail']} fail. "
             "Checks: finite; R, T >= 0; R + T <= 1 + 1e-6 (= 1 within 1e-6 when "
             "nothing absorbs); reciprocity within 1e-6 of the largest value; albedos "
             "within 4 standard errors of Monte Carlo where it runs.", "",
             "| case | what | outcome | seconds | detail |", "|---|---|---|---:|---|"]
    for c in cases:
        detail = c["detail"].replace("|", "/")
        lines.append(f"| {c['name']} | {c.get('what', '')} | **{c['outcome']}** | "
                     f"{c.get('seconds', 0):.1f} | {detail} |")
    return lines + [""]
