"""The energy-compensation term of a rough interface added to its operator.

The terms of :mod:`layersim.compensation.model` do not depend on the azimuth, so they enter
order 0 only: ``B_0[o, i] += 2 pi f_b(mu_i, mu_o) w_i mu_i`` (:mod:`layersim.operator`), with
``f_b`` interpolated at the ordinates from the same tables the random walk reads.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from ..compensation import layer_lobes
from ..operator import IsoOperator, order_weight


def compensate(op: IsoOperator, layer, eta_above: float) -> tuple[IsoOperator, str | None]:
    """``op`` with the compensation term of ``layer`` added to order 0 of its blocks, and a
    note for ``info["notes"]`` (None when ``layer`` has no compensation).

    Parameters
    ----------
    op : IsoOperator
        The projected single-scattering operator of ``layer``.
    layer : Dielectric or Conductor
        Validated isotropic rough interface.
    eta_above : float
        Absolute index of the medium above it.
    """
    lobes = layer_lobes(layer, eta_above)
    if lobes is None:
        return op, None
    grid = op.grid
    mu = grid.mu
    blocks = dict(op.blocks)
    added = {}
    for name, blk in op.blocks.items():
        if blk is None or name not in lobes.u:
            continue
        f = lobes.eval(name, mu[None, :], mu[:, None])        # [o, i]
        extra = order_weight(0) * f * grid.flux_weight[None, :]
        first = sps.csr_matrix(blk[0] + sps.csr_matrix(extra))
        blocks[name] = [first] + [blk[l] for l in range(1, len(blk))]
        added[name] = float(np.max(extra.T @ grid.flux_weight / grid.flux_weight))
    out = IsoOperator(grid, blocks, op.eta_top, op.eta_bottom, op.delta)
    text = ", ".join(f"{k} up to {v:.3g}" for k, v in added.items())
    return out, f"energy compensation ({lobes.mode}): albedo added {text}"
