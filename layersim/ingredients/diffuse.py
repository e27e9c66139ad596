"""Opaque Lambertian base (Jakob's layerlab tutorial sec. 4.1)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from ..operators.operator import Grid, IsoOperator


def diffuse_operator(grid: Grid, albedo: float, eta: float) -> IsoOperator:
    """Lambertian reflector of reflectance ``albedo`` lying in a medium of index ``eta``.

    Only the zeroth order and the ``Rt`` block are nonzero (transmission blocks are left out:
    the layer is opaque). The BSDF ``albedo / pi`` is normalised with the grid's own
    hemispherical flux integral ``2 pi sum_j w_j mu_j`` (which full-range rules integrate only to
    O(1/n^2)), so that the discrete operator reflects exactly the fraction ``albedo`` of every
    incident beam; the pointwise value differs from ``albedo / pi`` by the same O(1/n^2).
    """
    fw = grid.flux_weight
    # B_0[o, i] = 2 pi f w_i mu_i with f = albedo / (2 pi sum(fw))
    block = np.outer(np.ones(grid.h), fw) * (albedo / fw.sum())
    return IsoOperator(grid, {"Rt": [sps.csr_matrix(block)]}, eta_top=eta, eta_bottom=None)
