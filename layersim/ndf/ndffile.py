"""Writing fitted NDFs in the tabulated-NDF layout (``docs/conventions.md``).

A complete table holds ``theta`` (radians, increasing, 0 .. pi/2), ``phi`` (radians, increasing,
covering [0, 2 pi)) and ``D`` of shape (len(theta), len(phi)) in 1/sr, normalised so that the
projected area int (h . n) D dw_h is 1, plus what the fit knows besides: ``ks`` per channel (the
projected area before normalisation times each channel's scale: the specular coefficient of Wang
et al. 2008 sec. 5.4, with F = 1), ``channels``, ``W`` (the confidence, 0 where filled),
``filled`` (solid-angle fraction interpolated rather than measured), ``filled_area`` (the
fraction of the projected area that lies there: how much of the normalisation is interpolated)
and ``notes``.

A partial table (``partial=True``) keeps ``D`` = NaN where W = 0; it is not a layer's NDF.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InfeasibleError
from .complete import fill_uncovered
from .fit import PartialNDF


def save_ndf(path, part: PartialNDF, fill: bool | str = False, partial: bool = False) -> dict:
    """Write ``part`` to ``path`` (.npz) and return what was written.

    Parameters
    ----------
    part : PartialNDF, fitted and possibly completed
    fill : interpolate the undetermined region (push-pull, :func:`fill_uncovered`) and report
        it; True or "flat" / "zero" (the condition at the horizon)
    partial : write the partial table as it is (D = NaN where undetermined)

    Raises
    ------
    InfeasibleError
        when the table is incomplete and neither ``fill`` nor ``partial`` is given: a tabulated
        NDF must cover the hemisphere, and nothing is filled unless asked for.
    """
    g = part.grid
    out = {"theta": g.theta, "phi": g.phi, "W": part.w, "channels": np.array(part.channels),
           "notes": np.array(part.notes), "residual": part.residual}
    if partial:
        out.update(D=np.where(part.w > 0, part.d, np.nan), partial=True, filled=0.0)
    else:
        if not part.complete and not fill:
            raise InfeasibleError(
                f"the NDF is determined over {100 * part.coverage:.1f} % of the hemisphere only; "
                "add partial NDFs of rotated samples or other views (--complete), state a "
                "symmetry (--symmetry), fill the rest by interpolation (--fill), or write the "
                "partial table (--partial)")
        horizon = fill if isinstance(fill, str) else "flat"
        d, filled = fill_uncovered(part, horizon) if not part.complete else (part.d, 0.0)
        d = np.maximum(d, 0.0)
        area = g.projected_area(d)
        if not area > 0:
            raise InfeasibleError("the fitted NDF has no positive values: cannot normalise it")
        out.update(D=d / area, ks=area * np.asarray(part.channel_scale, float), partial=False,
                   filled=filled, filled_area=g.projected_area(d * ~(part.w > 0)) / area)
    np.savez(Path(path), **out)
    return out
