"""How far a design's lobes in exact transport lie from its targets.

Exact lobes are those of :func:`layersim.statistical.verify.exact_lobes` (Bati et al. 2021's
definition ``R_k = R_{0,n+l} - R_{0,n}`` with exact solves of the stack cut below each lobe, at
normal incidence; the width the GGX roughness that fits the lobe best). The mismatch is the
largest relative error over lobes and channels, of the energy and of the roughness (a smooth
target lobe has no roughness error: the fitted width of a delta is the bins' own).
"""

from __future__ import annotations

import numpy as np

__all__ = ["lobe_mismatch"]


def lobe_mismatch(targets, exact) -> dict:
    """``{"energy": e, "roughness": r}``: the largest relative errors ``|x_exact - x_target| /
    x_target`` of the lobes ``exact`` (per target lobe, ``(energy, roughness)`` per channel)
    against ``targets`` (:class:`~layersim.statistical.targets.Targets`)."""
    energy, rough = 0.0, 0.0
    for t, (e, a) in zip(targets.lobes, exact):
        e_t = np.broadcast_to(t.energy, np.shape(e))
        energy = max(energy, float(np.max(np.abs(np.asarray(e) - e_t) / e_t)))
        if t.roughness > 0.0:
            rough = max(rough, float(np.max(np.abs(np.asarray(a) - t.roughness))
                                     / t.roughness))
    return {"energy": energy, "roughness": rough}
