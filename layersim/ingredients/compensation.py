"""The energy-compensation term of a rough interface added to its operator.

The terms of :mod:`layersim.compensation.model` do not depend on the azimuth, so they enter
order 0 only: ``B_0[o, i] += 2 pi f_b(mu_i, mu_o) w_i mu_i`` (:mod:`layersim.operator`).

A dielectric's term is built, as layerlab builds it (``Layer::setMicrofacet``), from the
operator's own albedos at the ordinates, with the ordinates' quadrature for the hemispherical
integrals: the compensated operator then reflects and transmits exactly the incident energy at
every ordinate (to rounding), whatever the discretisation error of its single-scattering part.
The random walk builds the same term from the albedo tables (:mod:`layersim.compensation.tables`);
the two differ by the solver's discretisation error of the single-scattering albedo, which the
comparison with the walk measures anyway. A conductor's term (Kulla & Conty's, with the albedo
``E1`` of the Fresnel-free interface) takes ``E1`` from the tables, interpolated at the
ordinates, in both.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from ..compensation import layer_lobes
from ..compensation.model import DIELECTRIC
from ..compensation.tables import Albedos, interpolate
from ..operator import IsoOperator, order_weight


def _discrete_dielectric(op: IsoOperator, mode: str, eta: float):
    """``(u, v)`` of a dielectric's term at the ordinates, from the operator's albedos."""
    alb = op.albedo_nodes()
    fw = op.grid.flux_weight
    integral = lambda v: float(2.0 * np.pi * np.dot(fw, v))
    lobes = DIELECTRIC[mode](Albedos(alb["Rt"], alb["Ttb"], alb["Rb"], alb["Tbt"]), eta,
                             integral)
    return lobes.mode, {name: (lobes.u[name], lobes.v[name]) for name in lobes.u}


def _tabulated(lobes, mu):
    return lobes.mode, {name: (interpolate(lobes.u[name], mu),
                               interpolate(lobes.v[name], mu)) for name in lobes.u}


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
    eta = complex(layer.ior) / eta_above
    if eta.imag > 0:
        mode, terms = _tabulated(layer_lobes(layer, eta_above), op.grid.mu)
    else:
        mode, terms = _discrete_dielectric(op, layer.energy_compensation, eta.real)
    grid = op.grid
    blocks = dict(op.blocks)
    added = {}
    for name, (u, v) in terms.items():
        blk = op.blocks.get(name)
        if blk is None:
            continue
        extra = order_weight(0) * np.outer(v, u * grid.flux_weight)       # [o, i]
        blocks[name] = [sps.csr_matrix(blk[0] + sps.csr_matrix(extra))] + \
            [blk[l] for l in range(1, len(blk))]
        added[name] = float(np.max(extra.T @ grid.flux_weight / grid.flux_weight))
    out = IsoOperator(grid, blocks, op.eta_top, op.eta_bottom, op.delta)
    text = ", ".join(f"{k} up to {v:.3g}" for k, v in added.items())
    return out, f"energy compensation ({mode}): albedo added {text}"
