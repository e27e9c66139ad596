"""Text and plots of a design and its verification (``layersim design``): the chosen stack,
per lobe the target, the statistical model's lobe and exact transport's, and the model's BSDF
error against the exact solve (:mod:`layersim.statistical.verify`)."""

from __future__ import annotations

import math

import numpy as np


def _rgb(x, fmt="{:.4f}") -> str:
    x = np.atleast_1d(np.asarray(x, dtype=float))
    return "/".join(fmt.format(v) for v in x)


def stack_lines(design) -> list[str]:
    """One line per layer of the designed scene."""
    return [design.scene.describe()]


def verification_lines(targets, result, reference: str = "exact") -> list[str]:
    """The table of one verification (``verify(...)``'s result) against ``targets``;
    ``reference`` names what stands for exact transport (the solve, or Monte Carlo)."""
    lines = ["lobe  target energy / alpha       statistical energy / alpha        "
             f"{reference} energy / alpha (fit)"]
    for k, (t, (me, ma), (ee, ea)) in enumerate(zip(targets.lobes, result["lobes"],
                                                   result["exact_lobes"]), start=1):
        lines.append(f"{k:>4}  {_rgb(t.energy)} / {t.roughness:.4f}   "
                     f"{_rgb(me)} / {_rgb(ma, '{:.3f}')}   {_rgb(ee)} / {_rgb(ea, '{:.3f}')}")
    lines.append(f"statistical BSDF vs {reference}, relative L2 over 18 x 36 bins (top side):")
    for theta, e in result["errors"].items():
        lines.append(f"  theta_i = {theta:4.0f} deg: L2 {e['l2']:.3f}   R model "
                     f"{_rgb(e['R_model'])}   R {reference} {_rgb(e['R_exact'])}")
    lines.append(f"times: statistical model {result['model_seconds']:.3f} s, {reference} "
                 f"{result['exact_seconds']:.2f} s")
    return lines


def exact_lobe_lines(targets, lobes) -> list[str]:
    """Per target lobe, the target and exact transport's lobe (``lobes``: per lobe
    ``(energy, roughness)`` per channel, :func:`~layersim.statistical.verify.exact_lobes`)."""
    lines = ["  lobe  target energy / alpha       exact energy / alpha (fit)"]
    for k, (t, (e, a)) in enumerate(zip(targets.lobes, lobes), start=1):
        lines.append(f"  {k:>4}  {_rgb(t.energy)} / {t.roughness:.4f}   {_rgb(e)} / "
                     f"{_rgb(a, '{:.3f}')}")
    return lines


def _percent(mismatch: dict) -> str:
    return f"energy {100 * mismatch['energy']:.1f} %, roughness {100 * mismatch['roughness']:.1f} %"


def refinement_lines(targets, refinement) -> list[str]:
    """The report of ``layersim design --exact``: both designs (layers, exact lobes against
    the targets), the largest relative errors of each, and the fits (solves, time, RMS
    residual, warnings) of a :class:`~layersim.statistical.refine.Refinement`."""
    lines = []
    for key in ("statistical", "refined"):
        d = getattr(refinement, key)
        lines.append(f"{key} design:")
        lines += ["  " + s for s in d.scene.describe().splitlines()[1:]]
        lines += exact_lobe_lines(targets, refinement.lobes[key])
    before, after = refinement.mismatch["statistical"], refinement.mismatch["refined"]
    lines.append(f"largest relative error of the exact lobes: statistical {_percent(before)}; "
                 f"refined {_percent(after)}")
    lines.append(f"refinement: {refinement.solves} exact solves in {refinement.seconds:.1f} s")
    for k, fit in refinement.fits:
        lines.append(f"  lobe {k + 1}: {len(fit.history)} solves, final plan n = "
                     f"{fit.plans[-1]['n']}, md = {fit.plans[-1]['md']}, RMS weighted residual "
                     f"{fit.residual:.3g} 1/sr")
        lines += [f"  lobe {k + 1}: warning: {w}" for w in fit.warnings]
    return lines


def plot_lobes(targets, design, result, path) -> None:
    """Target lobes (GGX of the target roughness and energy) against exact transport's lobes
    (the cut-stack differences of :func:`~layersim.statistical.verify.exact_lobes`) at normal
    incidence, drawn into a PNG at ``path`` (:func:`lobes_figure`)."""
    from .verify import exact_ring_energies
    rings = exact_ring_energies(design, result["exact_solve"])
    lobes_figure(targets, rings).savefig(path, dpi=110)


#: Line colours of the R, G and B channels (one channel: black).
CHANNEL_COLOURS = ("tab:red", "tab:green", "tab:blue")


def lobes_figure(targets, rings):
    """The figure of :func:`plot_lobes`: energy per degree of outgoing elevation at normal
    incidence, one panel per lobe, one colour per channel (:data:`CHANNEL_COLOURS`), exact
    transport solid and the target dashed; the legend names both the line styles and the
    channel colours.

    Parameters
    ----------
    targets : Targets
        The parsed targets (:func:`~layersim.statistical.targets.parse_targets`).
    rings : list of ndarray, each (90, channels)
        Exact energy per 1-degree ring of the outgoing elevation for each lobe, in the order
        of :data:`~layersim.statistical.verify.RING_EDGES` (increasing cos theta).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from .lobes import lobe_bins
    from .verify import RING_EDGES
    theta = 0.5 + np.arange(90)[::-1]          # ring centres, degrees (RING_EDGES increase in mu)
    n = len(targets.lobes)
    fig = Figure(figsize=(4.2 * n, 3.4), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, n, squeeze=False)
    wi, edges = np.array([0.0, 0.0, 1.0]), np.array([0.0, 2.0 * math.pi])
    for k, (ax, t) in enumerate(zip(axes[0], targets.lobes)):
        exact = rings[k]
        nch = exact.shape[1]
        colours = CHANNEL_COLOURS if nch == 3 else ("k",)
        for c in range(nch):
            ax.plot(theta, exact[:, c], color=colours[c], lw=1.5)
            e = float(np.broadcast_to(t.energy, (nch,))[c])
            if t.roughness > 0:
                ax.plot(theta, e * lobe_bins(wi, t.roughness, RING_EDGES, edges)[:, 0],
                        color=colours[c], ls="--", lw=1)
        # the legend explains the two line styles in neutral grey, then the channel colours
        handles = [Line2D([], [], color="0.3", lw=1.5, label="exact transport"),
                   Line2D([], [], color="0.3", lw=1, ls="--", label="target")]
        if nch == 3:
            handles += [Line2D([], [], color=col, lw=3, label=f"{name} channel")
                        for col, name in zip(colours, "RGB")]
        ax.set_xlim(0, min(90, 6 * max(t.roughness, 0.02) * 180 / math.pi + 5))
        ax.set_xlabel(r"$\theta_o$ (deg), normal incidence")
        ax.set_ylabel("energy per degree")
        ax.set_title(f"lobe {k + 1}")
        ax.legend(handles=handles, fontsize=7)
    return fig
