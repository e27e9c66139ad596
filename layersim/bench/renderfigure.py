"""The figure and report text of a bench scene's rendered comparison
(:mod:`layersim.bench.rendercompare`): the solver's and the walk's binned renders side by side,
their signed difference on a diverging scale, and the solver's continuous BSDF rendered by
Mitsuba 3."""

from __future__ import annotations

import numpy as np

#: Grey of the background of the sphere images.
BACKGROUND = 0.15


def display(rgb) -> np.ndarray:
    """Linear RGB (H, W, 3), NaN off the sphere, to display sRGB in [0, 1] (radiance 1 is
    white; brighter values clip, as in a PNG written by Mitsuba)."""
    x = np.clip(np.nan_to_num(np.asarray(rgb, float), nan=BACKGROUND), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def figure(name: str, row: dict, img: dict):
    """The comparison figure of scene ``name`` (pyplot figure; the caller saves and closes
    it): ``row`` and ``img`` from :func:`layersim.bench.rendercompare.run`."""
    import matplotlib
    matplotlib.use("Agg")        # files only, never a window
    import matplotlib.pyplot as plt
    panels = [("solver, binned", img["solver"])]
    if "montecarlo" in img:
        panels.append((f"Monte Carlo, binned\n{row['particles']:.0e} paths per angle",
                       img["montecarlo"]))
    mitsuba = img.get("mitsuba")
    count = len(panels) + ("difference" in img) + (mitsuba is not None)
    fig, axes = plt.subplots(1, count, figsize=(3.1 * count + 0.6, 4.0), layout="constrained")
    axes = list(np.atleast_1d(axes))
    for ax, (title, rgb) in zip(axes, panels):
        ax.imshow(display(rgb))
        ax.set_title(title, fontsize=8)
    k = len(panels)
    if "difference" in img:
        _difference_panel(fig, axes[k], row, img)
        k += 1
    if mitsuba is not None:
        rgb = np.where(np.isnan(img["solver"]), np.nan, mitsuba)
        axes[k].imshow(display(rgb))
        axes[k].set_title(f"Mitsuba 3 ({row['mitsuba']}), {row['spp']} spp:\nthe "
                          "continuous BSDF, not binned", fontsize=8)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    n_mu, n_phi = row["bins"]
    fig.suptitle(f"{name}: reflection under the sky of 'layersim render' (orthographic); "
                 f"binned renders from {n_mu} x {n_phi} bins at {row['angles']} incidence "
                 "angles, 0-85 deg", fontsize=8)
    return fig


def _difference_panel(fig, ax, row: dict, img: dict) -> None:
    """Solver minus walk, luminance, on a symmetric diverging scale with its colour bar."""
    diff = img["difference"]
    vmax = float(np.nanpercentile(np.abs(diff), 99.5)) or 1e-12
    cmap = _cmap()
    mesh = ax.imshow(diff, cmap=cmap, vmin=-vmax, vmax=vmax)
    ax.set_title(f"solver - Monte Carlo (luminance)\nrelative RMS "
                 f"{row['relative_difference']:.2g}; walk's sigma RMS {row['sigma_rms']:.2g};\n"
                 f"{100 * row['within_3sigma']:.0f}% of pixels within 3 sigma", fontsize=8)
    fig.colorbar(mesh, ax=ax, shrink=0.8, label="radiance (sky units)")


def _cmap():
    """A diverging colour map whose zero is white, with NaN (off the sphere) grey."""
    import matplotlib
    return matplotlib.colormaps["RdBu_r"].with_extremes(bad=(BACKGROUND,) * 3)


def markdown(row: dict) -> list[str]:
    """The report's lines on the rendered comparison of one scene (``row``: results.json
    ``render``)."""
    if "skipped" in row:
        return [f"Rendered comparison: skipped ({row['skipped']}).", ""]
    n_mu, n_phi = row["bins"]
    text = (f"Rendered comparison (`--render`): the solver's and the walk's bin energies "
            f"({n_mu} x {n_phi} bins of the top side at {row['angles']} incidence angles, "
            f"0-85 deg; the walk {row['particles']:.0e} paths per angle) rendered by the same "
            "binned renderer (layersim/bench/binrender.py) on a sphere under the sky of "
            "`layersim render`, reflection only; the difference shows the two tables' "
            "difference, the walk's noise included")
    if "relative_difference" not in row:
        text += " (no Monte Carlo backend installed: the solver's render alone)"
    else:
        text += (f" (relative RMS {row['relative_difference']:.2g}; the walk's standard error "
                 f"propagated to the image, RMS {row['sigma_rms']:.2g} in radiance; "
                 f"{100 * row['within_3sigma']:.0f}% of pixels within 3 of it)")
    if row.get("mitsuba"):
        text += (f". Right: the solver's continuous BSDF rendered by Mitsuba 3 "
                 f"({row['mitsuba']}) from the same view")
    else:
        text += f". No Mitsuba render: {row.get('mitsuba_note')}"
    return [text + ".", ""]
