"""The energy-compensation term of a rough interface added to its operator.

The terms of :mod:`layersim.compensation.model` do not depend on the azimuth, so they enter
order 0 only: ``B_0[o, i] += 2 pi f_b(mu_i, mu_o) w_i mu_i`` (:mod:`layersim.operators.operator`).

A dielectric's term is built, as layerlab builds it (``Layer::setMicrofacet``), from the
operator's own albedos at the ordinates, with the ordinates' quadrature for the hemispherical
integrals: the compensated operator then reflects and transmits exactly the incident energy at
every ordinate (to rounding), whatever the discretisation error of its single-scattering part.
A conductor's term (Kulla & Conty's) needs the albedo ``E1`` of the Fresnel-free interface,
which the operator does not hold: the solver takes the table's ``E1`` plus the operator's
discretisation error of its own albedo (operator minus table, with the Fresnel factor), so that
a perfect mirror conserves energy at every ordinate too. The random walk builds the same terms
from the tables (:mod:`layersim.compensation.tables`); the two differ by the solver's
discretisation error of the single-scattering albedo, which the comparison with the walk
measures anyway.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from ..compensation import tables
from ..compensation.model import CONDUCTOR, DIELECTRIC
from ..operators.operator import IsoOperator, order_weight


def _discrete_lobes(op: IsoOperator, layer, eta: complex):
    """The compensation term of ``layer`` at the operator's ordinates (module docstring)."""
    alb = op.albedo_nodes()
    fw = op.grid.flux_weight
    integral = lambda v: float(2.0 * np.pi * np.dot(fw, v))
    mode = layer.energy_compensation
    if eta.imag == 0:
        return DIELECTRIC[mode](tables.Albedos(alb["Rt"], alb["Ttb"], alb["Rb"], alb["Tbt"]),
                                eta.real, integral)
    mu, args = op.grid.mu, (eta.real, eta.imag, layer.alpha, layer.distribution)
    sh = layer.shadowing
    e1 = (tables.interpolate(tables.albedos(*args, unit_fresnel=True, shadowing=sh).r_top, mu)
          + alb["Rt"] - tables.interpolate(tables.albedos(*args, shadowing=sh).r_top, mu))
    return CONDUCTOR[mode](e1, tables.fresnel_average(eta.real, eta.imag), integral)


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
    if layer.energy_compensation == "none" or layer.smooth:
        return op, None
    lobes = _discrete_lobes(op, layer, complex(layer.ior) / eta_above)
    grid = op.grid
    blocks = dict(op.blocks)
    added = {}
    for name, u in lobes.u.items():
        v = lobes.v[name]
        blk = op.blocks.get(name)
        if blk is None:
            continue
        extra = order_weight(0) * np.outer(v, u * grid.flux_weight)       # [o, i]
        blocks[name] = [sps.csr_matrix(blk[0] + sps.csr_matrix(extra))] + \
            [blk[l] for l in range(1, len(blk))]
        added[name] = float(np.max(extra.T @ grid.flux_weight / grid.flux_weight))
    out = IsoOperator(grid, blocks, op.eta_top, op.eta_bottom, op.delta)
    text = ", ".join(f"{k} up to {v:.3g}" for k, v in added.items())
    return out, f"energy compensation ({lobes.mode}): albedo added {text}"
