"""``layersim fit-ndf``: measurement files -> partial NDFs -> completion -> NDF table and plot.

The steps of Wang et al. 2008 sec. 5 for files: fit each view (sec. 5.1), complete the first from
the others (sec. 5.2) or from a symmetry the user states, write the table (sec. 5.4's k_s and
normalisation). Every step's outcome is returned as a line for the command to print.
"""

from __future__ import annotations

from .complete import apply_symmetry, complete_ndf
from .fit import fit_partial_ndf
from .halfgrid import HalfGrid
from .measurements import Measurements
from .ndffile import save_ndf


def parse_grid(text: str) -> HalfGrid:
    """'91x180' -> HalfGrid(91, 180), with a clear error otherwise."""
    try:
        nt, nph = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"--grid {text!r}: expected N_THETA x N_PHI, e.g. 91x180") from None
    return HalfGrid(nt, nph)


def fit_files(measurements, output, others=(), grid: HalfGrid | None = None,
              constrained: bool = True, symmetry: str | None = None, fill: bool | str = False,
              partial: bool = False, max_light_theta_deg: float = 80.0, plot=None) -> list:
    """Fit ``measurements`` (a file), complete it from ``others`` (files of rotated samples or
    other views) and/or a stated ``symmetry``, and write ``output`` (.npz).

    Returns
    -------
    list of str, one line per fact worth printing (residual, coverage, merges, what was filled,
    the specular coefficient per channel)
    """
    grid = grid or HalfGrid()
    all_meas = [Measurements.load(p) for p in [measurements, *others]]  # all errors up front
    parts = [fit_partial_ndf(m, grid, constrained, max_light_theta_deg) for m in all_meas]
    lines = [f"{m.source}: residual {p.residual:.2e}, covers {100 * p.coverage:.1f} % of the "
             "hemisphere" for m, p in zip(all_meas, parts)]
    part = complete_ndf(parts[0], parts[1:]) if len(parts) > 1 else parts[0]
    if symmetry:
        part = apply_symmetry(part, symmetry)
    lines += [n for n in part.notes if n.startswith("merged") or "left unmerged" in n
              or "symmetry" in n]
    out = save_ndf(output, part, fill=fill, partial=partial)
    lines.append(f"coverage {100 * part.coverage:.1f} %; " + (
        "partial table written (D = NaN where undetermined)" if partial else
        f"filled by interpolation: {100 * out['filled']:.1f} % of the solid angle, holding "
        f"{100 * out['filled_area']:.1f} % of the projected area" if out["filled"] else
        "complete"))
    if not partial:
        ks = ", ".join(f"{c} {v:.4g}" for c, v in zip(part.channels, out["ks"]))
        lines.append(f"specular coefficient k_s (F = 1): {ks}")
    if plot:
        from .fitplot import plot_fit
        plot_fit(plot, grid, out["D"], part.w, title=str(output))
        lines.append(f"plot: {plot}")
    lines.append(f"wrote {output} ({grid.n_theta} x {grid.n_phi} table)")
    return lines
