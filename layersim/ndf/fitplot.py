"""Pictures of fitted and completed NDFs (matplotlib object API, Agg canvas, PNG).

Each panel is the orthographic projection of the hemisphere of normals, (h_x, h_y) = sin(theta)
(cos(phi), sin(phi)), as in Wang et al. 2008 Fig. 5: D (linear or logarithmic), the confidence W,
and, when given, a reference NDF and the relative difference. Undetermined nodes (NaN in D, W = 0) are grey.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .halfgrid import HalfGrid


def _panel(fig, ax, grid: HalfGrid, values, title, cmap="viridis", vmin=None, vmax=None):
    # cell edges: theta midpoints (clipped to [0, pi/2]) and phi midpoints (periodic)
    t = grid.theta
    te = np.concatenate([[0.0], 0.5 * (t[1:] + t[:-1]), [t[-1]]])
    pe = np.concatenate([grid.phi, [2 * np.pi]]) - np.pi / grid.n_phi
    tt, pp = np.meshgrid(te, pe, indexing="ij")
    x, y = np.sin(tt) * np.cos(pp), np.sin(tt) * np.sin(pp)
    vals = np.ma.masked_invalid(values)
    ax.set_facecolor("0.8")
    m = ax.pcolormesh(x, y, vals, cmap=cmap, vmin=vmin, vmax=vmax, shading="flat")
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ticks = [-1.0, -0.5, 0.0, 0.5, 1.0]
    ax.set_xticks(ticks, [f"{t:g}" for t in ticks], fontsize=7)
    ax.set_yticks(ticks, [f"{t:g}" for t in ticks], fontsize=7)
    ax.set_xlabel(r"$h_x = \sin\theta_h \cos\phi_h$", fontsize=8)
    ax.set_ylabel(r"$h_y = \sin\theta_h \sin\phi_h$", fontsize=8)
    fig.colorbar(m, ax=ax, shrink=0.8)


def plot_fit(path, grid: HalfGrid, d, w=None, reference=None, log: bool = False,
             title: str = "") -> Path:
    """Draw D (and W, the reference and the relative error when given) into a PNG at
    ``path``; the arguments are those of :func:`fit_figure`."""
    path = Path(path)
    fit_figure(grid, d, w, reference, log, title).savefig(path, dpi=110)
    return path


def fit_figure(grid: HalfGrid, d, w=None, reference=None, log: bool = False,
               title: str = "") -> Figure:
    """The figure of :func:`plot_fit`: one panel per table on the projected hemisphere of
    normals, with labelled ``h_x``, ``h_y`` axes and a colour bar each.

    Parameters
    ----------
    grid : HalfGrid of the tables
    d : array (n_theta, n_phi), the NDF in 1/sr (NaN where undetermined; a filled table shows
        its filled part, which W marks with 0)
    w : array (n_theta, n_phi) or None, the confidence of eq. (12)
    reference : array (n_theta, n_phi) or None, e.g. the analytic NDF of synthetic data
    log : draw log10 D
    """
    d = np.asarray(d, float)
    show = (lambda a: np.log10(np.maximum(a, 1e-6))) if log else (lambda a: a)
    panels = [(show(d), "log10 D [1/sr]" if log else "D [1/sr]", "viridis", None, None)]
    if w is not None:
        panels.append((np.where(np.asarray(w) > 0, w, np.nan), "confidence W", "magma", 0, 1))
    if reference is not None:
        ref = np.asarray(reference, float)
        panels.append((show(ref), "reference", "viridis", None, None))
        rel = (d - ref) / np.nanmax(ref)
        lim = max(float(np.nanmax(np.abs(rel))), 1e-6) if np.isfinite(rel).any() else 1.0
        panels.append((rel, "(D - ref) / max ref", "RdBu_r", -lim, lim))
    fig = Figure(figsize=(3.6 * len(panels), 3.4), layout="constrained")
    FigureCanvasAgg(fig)
    for k, (vals, name, cmap, lo, hi) in enumerate(panels):
        _panel(fig, fig.add_subplot(1, len(panels), k + 1), grid, vals, name, cmap, lo, hi)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig
