"""Opaque base with a measured isotropic BRDF (MERL layout, :mod:`layersim.layers.merl`): projected
into the cosine basis numerically.

For every ordinate pair of the ``Rt`` block the kernel
:func:`layersim.kernels.projection.measured_cosine_series` samples the same trilinear lookup as
the random walk (:func:`layersim.kernels.measured.measured_eval`) at uniform azimuths and a
DCT gives the cosine coefficients ``f_l``; the block of order ``l`` is
``B_l[o, i] = c_l f_l(mu_i, mu_o) w_i mu_i`` with ``c_0 = 2 pi``, ``c_l = pi`` (Jakob's layerlab
tutorial, sec. 3; the isotropic convention of :mod:`layersim.aniso.basis`). The BRDF is used as
measured, whatever the index of the medium above it (a measurement in air of a surface that is
coated in the scene is the user's approximation to make).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from ..kernels import projection as kproj
from ..operators.operator import DROP_TOLERANCE, Grid, IsoOperator
from .microfacet import block_pairs

#: Smallest number of azimuth intervals on [0, pi] per pair; at least 2 md are used.
HALF_MIN = 128


def measured_operator(grid: Grid, m: int, layer, eta_above: float,
                      device=None) -> IsoOperator:
    """``Rt`` operator (orders ``0 .. m-1``) of a measured base layer (``layer.data``, channel
    ``layer.channel``) lying in a medium of index ``eta_above``."""
    mu_i, mu_o, o, i = block_pairs(grid, "Rt", False)
    half = max(HALF_MIN, 2 * m)
    coef = kproj.measured_cosine_series(mu_i, mu_o, layer.data.packed(layer.channel, np.float64),
                                        half, m, device=device)
    fw = grid.flux_weight
    h = grid.h
    blocks = []
    for order in range(m):
        scale = 2.0 * np.pi if order == 0 else np.pi
        vals = coef[:, order] * scale * fw[i]
        peak = np.abs(vals).max(initial=0.0)
        keep = np.abs(vals) > DROP_TOLERANCE * max(peak, 1e-300)
        blocks.append(sps.csr_matrix((vals[keep], (o[keep], i[keep])), shape=(h, h)))
    return IsoOperator(grid, {"Rt": blocks}, eta_top=eta_above, eta_bottom=None)
