"""The picture of a fit: the target against the fitted BSDF.

For a sampled BSDF target, slices in the plane of incidence (``f cos(theta_o)`` against the
signed outgoing elevation) at a few incident elevations; for point measurements, every
measured ``f cos(theta_o)`` against the fitted one, with the line of equality.
"""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..solved.bsdf import BSDF
from ..solver import solve
from .target import Target

__all__ = ["plot_fit"]

#: Incident elevations (degrees) of the slices.
SLICE_THETA = (0.0, 30.0, 60.0)


def _plane(theta_i: float, n: int = 181) -> tuple:
    """Pairs in the plane of incidence (phi_i = 0): outgoing elevation -89..89 degrees."""
    t = np.radians(np.linspace(-89.0, 89.0, n))
    ti = np.radians(theta_i)
    wi = np.tile([np.sin(ti), 0.0, np.cos(ti)], (n, 1))
    wo = np.stack([np.sin(t), np.zeros(n), np.cos(t)], axis=-1)
    return np.degrees(t), wi, wo


def _slices(ax, target_bsdf, fitted: BSDF) -> None:
    for k, th in enumerate(SLICE_THETA):
        t, wi, wo = _plane(th)
        for bsdf, style, who in ((target_bsdf, "-", "target"), (fitted, "--", "fit")):
            f = np.asarray(bsdf.eval(wi, wo)).reshape(len(t), -1)[:, 0] * wo[:, 2]
            ax.plot(t, f, style, color=f"C{k}", label=f"{who}, theta_i = {th:g}")
    ax.set_xlabel("theta_o (degrees, plane of incidence)")
    ax.set_ylabel("f cos theta_o (1/sr), channel 0")
    ax.legend(fontsize=7)


def _scatter(ax, target: Target, fitted: BSDF) -> None:
    f = np.asarray(fitted.eval(target.wi, target.wo)).reshape(len(target.wi), -1)
    cos = target.wo[:, 2:3]
    x, y = (target.f * cos).ravel(), (f * cos).ravel()
    ax.plot(y, x, ".", ms=2)
    top = float(max(x.max(), y.max()))
    ax.plot([0, top], [0, top], "k-", lw=0.8)
    ax.set_xlabel("fitted f cos theta_o (1/sr)")
    ax.set_ylabel("measured f cos theta_o (1/sr)")


def plot_fit(path, result, target: Target, target_bsdf=None) -> None:
    """Write the picture of ``result`` (a :class:`~layersim.fit.FitResult`) against ``target``
    to ``path`` (any format matplotlib writes); ``target_bsdf`` is the target when it is a
    solved BSDF or a tabulated file (:class:`~.tables.TableTarget`, NaN where it has no data)
    (slices), None for point measurements (scatter)."""
    fitted = solve(result.scene)
    fig = Figure(figsize=(7, 5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    if target_bsdf is not None:
        _slices(ax, target_bsdf, fitted)
    else:
        _scatter(ax, target, fitted)
    ax.set_title(f"fit: rms residual {result.residual:.3g} {result.unit}")
    fig.savefig(path, dpi=120)
