"""Pictures of an NDF table (matplotlib, Agg, PNG): D and its shadowing S over the hemisphere.

:func:`plot_ndf` draws two panels over the disk of radius ``theta / 90 deg`` at azimuth ``phi``
(equidistant: the horizon, where S falls, keeps its width), viewed from above (``x`` right,
``y`` up): ``log10 D(theta_h, phi_h)`` of the microfacet normals
(1/sr, the table's bilinear values, floored at 1e-4 of the peak) and ``S(k)`` for directions
``k`` (Wang et al. 2008, eq. (5)). Anisotropy shows as an elongated lobe (along the axis of the
larger slope spread) and as an azimuth-dependent fall of S toward the rim.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .table import NDFTable, shadow_grid

__all__ = ["plot_ndf"]


def _disk(ax, theta, phi, values, label, **kw):
    """``values[i, j]`` at (theta_i, phi_j) on the equidistant disk, closed across 2 pi."""
    phi = np.append(phi, phi[0] + 2 * np.pi)
    values = np.concatenate([values, values[:, :1]], axis=1)
    r = (theta / (0.5 * np.pi))[:, None]
    x, y = r * np.cos(phi)[None, :], r * np.sin(phi)[None, :]
    mesh = ax.pcolormesh(x, y, values, shading="gouraud", **kw)
    ax.set_aspect("equal")
    ax.set_xlim(-1.02, 1.02)
    ax.set_ylim(-1.02, 1.02)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.figure.colorbar(mesh, ax=ax, label=label, shrink=0.8)


def plot_ndf(table: NDFTable, path, title: str | None = None) -> Path:
    """Write a PNG of ``log10 D`` and ``S`` of ``table`` to ``path`` and return the path."""
    fig = Figure(figsize=(9.0, 4.2), dpi=110)
    ax_d, ax_s = fig.subplots(1, 2)
    theta = np.linspace(0.0, 0.5 * np.pi, 181)
    phi = np.linspace(0.0, 2 * np.pi, 360, endpoint=False)
    D = table.eval(theta[:, None], phi[None, :])
    floor = 1e-4 * max(float(D.max()), 1e-300)
    _disk(ax_d, theta, phi, np.log10(np.maximum(D, floor)), r"$\log_{10} D$ (1/sr)",
          cmap="magma")
    ax_d.set_title("normal distribution D(h)")
    tg, pg = shadow_grid()
    _disk(ax_s, tg, pg, table.shadow, "S", cmap="viridis", vmin=0.0, vmax=1.0)
    ax_s.set_title("shadowing S(k), Wang et al. 2008 eq. (5)")
    fig.suptitle(title or table.describe(), fontsize=9)
    path = Path(path)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=fig.dpi)
    return path
