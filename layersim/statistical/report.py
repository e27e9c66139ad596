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


def plot_lobes(targets, design, result, path) -> None:
    """Target lobes (GGX of the target roughness and energy) against exact transport's lobes
    (the cut-stack differences of :func:`~layersim.statistical.verify.exact_lobes`) at normal
    incidence: energy per degree of outgoing elevation, one panel per lobe, one line per
    channel."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from .lobes import lobe_bins
    from .verify import RING_EDGES, exact_ring_energies
    theta = 0.5 + np.arange(90)[::-1]          # ring centres, degrees (RING_EDGES increase in mu)
    rings = exact_ring_energies(design, result["exact_solve"])
    n = len(targets.lobes)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.4), squeeze=False)
    colours = ["tab:red", "tab:green", "tab:blue"]
    wi, edges = np.array([0.0, 0.0, 1.0]), np.array([0.0, 2.0 * math.pi])
    for k, (ax, t) in enumerate(zip(axes[0], targets.lobes)):
        exact = rings[k]
        for c in range(exact.shape[1]):
            col = colours[c] if exact.shape[1] == 3 else "k"
            ax.plot(theta, exact[:, c], color=col, lw=1.5,
                    label="exact" if c == 0 else None)
            e = float(np.broadcast_to(t.energy, (exact.shape[1],))[c])
            if t.roughness > 0:
                ax.plot(theta, e * lobe_bins(wi, t.roughness, RING_EDGES, edges)[:, 0],
                        color=col, ls="--", lw=1, label="target" if c == 0 else None)
        ax.set_xlim(0, min(90, 6 * max(t.roughness, 0.02) * 180 / math.pi + 5))
        ax.set_xlabel("theta_o (deg), normal incidence")
        ax.set_ylabel("energy per degree")
        ax.set_title(f"lobe {k + 1}")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
