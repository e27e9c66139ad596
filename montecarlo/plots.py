"""Pictures of Monte Carlo result files (matplotlib's object API, Agg canvas, as
:mod:`layersim.solved.plot`): per walk and side, a polar map over the outgoing direction, radius the
polar angle ``theta_o`` from the side's normal (0 to 90 deg) and angle the azimuth ``phi_o``.

:func:`plot_bins` draws the energy per solid angle ``E_b / Omega_b`` (1/sr, ``Omega_b =
(mu_hi - mu_lo)(phi_hi - phi_lo)``) of each bin, which for a fine binning tends to
``f(wi, wo) |cos theta_o|``; :func:`plot_z` draws signed distances in standard errors
(:mod:`.compare`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = ["plot_bins", "plot_z", "per_solid_angle"]

#: Walks drawn at most (the first ones): a sweep's file may hold hundreds.
MAX_ROWS = 12
#: Colour range of the z-score maps, in standard errors.
Z_RANGE = 5.0


def per_solid_angle(energies: np.ndarray, mu_edges, phi_edges) -> np.ndarray:
    """Bin energies (n_mu, n_phi) divided by their bins' solid angles, in 1/sr."""
    omega = np.outer(np.diff(mu_edges), np.diff(phi_edges))
    return np.asarray(energies, float) / omega


def _polar(ax, values, mu_edges, phi_edges, **kwargs):
    """``values`` (n_mu, n_phi) on polar axes: radius theta_o in degrees (from |cos theta_o|,
    so rows are drawn from the normal outward), angle phi_o."""
    theta = np.degrees(np.arccos(np.clip(np.asarray(mu_edges, float)[::-1], 0.0, 1.0)))
    mesh = ax.pcolormesh(np.asarray(phi_edges, float), theta, np.asarray(values)[::-1],
                         shading="flat", **kwargs)
    ax.set_ylim(0.0, 90.0)
    ax.set_yticks([30, 60, 90])
    ax.set_yticklabels(["30", "60", "90"], fontsize=6)
    ax.tick_params(axis="x", labelsize=6)
    return mesh


def _grid(rows: int, cols: int) -> Figure:
    fig = Figure(figsize=(3.2 * cols, 2.9 * rows), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _sides(f) -> tuple:
    """The sides to draw: the bottom only where some walk sends energy there."""
    bottom = np.nansum(f.bins_bottom[:MAX_ROWS]) > 0
    return ("top", "bottom") if bottom else ("top",)


def plot_bins(f, path) -> Path:
    """Energy per solid angle of every walk of result file ``f`` (:class:`.resultfile.MCFile`),
    one row per walk (the first :data:`MAX_ROWS`), one column per side; written to ``path``."""
    rows, sides = min(f.n_walks, MAX_ROWS), _sides(f)
    fig = _grid(rows, len(sides))
    for i in range(rows):
        for k, side in enumerate(sides):
            ax = fig.add_subplot(rows, len(sides), i * len(sides) + k + 1, projection="polar")
            vals = per_solid_angle(f.data[f"bins_{side}"][i], f.mu_edges, f.phi_edges)
            mesh = _polar(ax, vals, f.mu_edges, f.phi_edges, cmap="inferno", vmin=0.0)
            ax.set_title(f"{f.label(i)}, {side}", fontsize=7)
            fig.colorbar(mesh, ax=ax, shrink=0.8).set_label("energy per sr (1/sr)", fontsize=6)
    fig.savefig(path)
    return Path(path)


def plot_z(maps: list, labels: list, mu_edges, phi_edges, path) -> Path:
    """Signed z-score maps, ``maps[i]`` = ``{"top" | "bottom": (n_mu, n_phi)}`` (NaN: not
    populated, left blank), one row per walk titled ``labels[i]``; colours clipped at
    +-:data:`Z_RANGE`."""
    rows = min(len(maps), MAX_ROWS)
    sides = [s for s in ("top", "bottom") if any(np.any(np.isfinite(m[s])) for m in maps)]
    sides = sides or ["top"]
    fig = _grid(rows, len(sides))
    for i in range(rows):
        for k, side in enumerate(sides):
            ax = fig.add_subplot(rows, len(sides), i * len(sides) + k + 1, projection="polar")
            vals = np.ma.masked_invalid(maps[i][side])
            mesh = _polar(ax, vals, mu_edges, phi_edges, cmap="RdBu_r", vmin=-Z_RANGE,
                          vmax=Z_RANGE)
            ax.set_title(f"{labels[i]}, {side}", fontsize=7)
            fig.colorbar(mesh, ax=ax, shrink=0.8, extend="both").set_label(
                "(other - MC) / sigma", fontsize=6)
    fig.savefig(path)
    return Path(path)
