"""The delta (specular and straight-through) parts of operators under the adding equations.

A delta in direction sits on the diagonal of a block with the same value in every Fourier order
(``phi = 0`` is the mirror or straight-through direction of the propagation directions, see
:mod:`layersim.operators.operator`). Products of diagonals are diagonal, and a product with a smooth
(integrable) kernel is smooth, so the delta part of a stack follows the adding equations
(Jakob's layerlab tutorial eq. (3)) with elementwise algebra, per node::

    D   = 1 / (1 - dRb1 dRt2)
    Rt  = dRt1 + dTbt1 dRt2 dTtb1 D        Ttb = dTtb2 dTtb1 D
    Rb  = dRb2 + dTtb2 dRb1 dTbt2 D        Tbt = dTbt1 dTbt2 D

A block without a delta counts as 0. Operators record their deltas in ``op.delta`` (``{block:
(h,)}``, the energy fraction that the delta carries from node ``i`` to node ``i``) so that the BSDF
can evaluate the smooth part without them and report them separately.
"""

from __future__ import annotations

import numpy as np


def add_deltas(top: dict, bottom: dict, opaque: bool) -> dict:
    """The deltas of ``top`` stacked on ``bottom`` (``{block: (h,)}`` each; ``opaque``: the
    bottom is opaque and only ``Rt`` is formed). Blocks whose delta is zero are left out."""
    zero = 0.0
    get1 = lambda k: top.get(k, zero)
    get2 = lambda k: bottom.get(k, zero)
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = 1.0 - get1("Rb") * get2("Rt")
        D = np.where(denom > 0.0, 1.0 / np.where(denom > 0.0, denom, 1.0), 0.0)
    out = {"Rt": get1("Rt") + get1("Tbt") * get2("Rt") * get1("Ttb") * D}
    if not opaque:
        out["Rb"] = get2("Rb") + get2("Ttb") * get1("Rb") * get2("Tbt") * D
        out["Ttb"] = get2("Ttb") * get1("Ttb") * D
        out["Tbt"] = get1("Tbt") * get2("Tbt") * D
    return {k: np.asarray(v, float) for k, v in out.items()
            if np.ndim(v) and np.any(np.asarray(v) != 0.0)}


def specular(op, wi: np.ndarray) -> dict:
    """The delta parts of ``op`` for a beam from ``wi`` (Q, 3) (public convention, not on the
    horizon): ``{"top": (energy (Q,), wo (Q, 3)), "bottom": ...}``, the energy fraction that
    leaves through each side in the mirror (same side: ``wo = (-x, -y, z)``) or straight-through
    (other side: ``wo = -wi``) direction, interpolated linearly in the incident elevation between
    the ordinates (as :meth:`layersim.solved.bsdf.BSDF.albedo`)."""
    from .interpolation import hat_weights
    mu = wi[:, 2]
    idx, w = hat_weights(op.grid.mu, np.abs(mu))
    mirror = wi * np.array([-1.0, -1.0, 1.0])
    out = {"top": (np.zeros(mu.size), np.where(mu[:, None] > 0, mirror, -wi)),
           "bottom": (np.zeros(mu.size), np.where(mu[:, None] > 0, -wi, mirror))}
    for side, down, up in (("top", "Rt", "Tbt"), ("bottom", "Ttb", "Rb")):
        energy = out[side][0]
        for sel, name in ((mu > 0, down), (mu < 0, up)):
            d = op.delta.get(name)
            if d is not None and sel.any():
                energy[sel] = np.sum(w[sel] * d[idx[sel]], axis=1)
    return out
