"""Discrete energy balance of interface operators.

The quadrature that integrates a projected lobe over outgoing ordinates has an error of either
sign; where a lobe hugs the horizon (light leaving a dense medium just inside the critical angle,
grazing reflection) it can over-count, so that a column of the discrete operator reflects and
transmits slightly more than the incident energy (~1e-4 at n ~ 300 for a rough coating). Left
alone, such an operator could create energy between layers in the adding equations.

:func:`limit_energy` scales the BSDF at each ordinate pair by ``w_o w_i`` (one factor per ordinate
on each side of the interface, the same for every Fourier order), with ``w <= 1`` chosen so that
every incident ordinate's R + T is at most 1. In the flux-weighted basis
``g[o, i] = 2 pi f(o <- i) sqrt(fw_o fw_i) eta_i / eta_o``, which generalized reciprocity makes
symmetric, this is the symmetric scaling ``W g W``: reciprocity is kept exactly. Columns that
already conserve are touched only through their neighbours' factors (which are 1 unless a
neighbour over-counts).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from ..errors import InfeasibleError


def node_energy(op, w_top: np.ndarray, w_bot: np.ndarray):
    """R + T per incident ordinate from the top and from the bottom after scaling by the
    factors ``w_top``/``w_bot`` (ordinates above/below the interface) of the
    :class:`~layersim.operators.operator.IsoOperator` ``op``."""
    fw = op.grid.flux_weight
    rt = op.blocks["Rt"][0]
    top = w_top * ((rt.T @ (w_top * fw)) / fw)
    if op.opaque:
        return top, None
    top += w_top * ((op.blocks["Ttb"][0].T @ (w_bot * fw)) / fw)
    bot = w_bot * ((op.blocks["Rb"][0].T @ (w_bot * fw)) / fw
                   + (op.blocks["Tbt"][0].T @ (w_top * fw)) / fw)
    return top, bot


def limit_energy(op, tolerance: float = 1e-13, iterations: int = 200):
    """Scale the :class:`~layersim.operators.operator.IsoOperator` ``op`` (in place) so that no incident
    ordinate gains energy (:meth:`~layersim.operators.operator.IsoOperator.limit_energy`).

    Returns
    -------
    excess : float
        The largest ``R + T - 1`` before the correction (<= 0 when nothing was done).
    scaled : int
        Number of ordinates whose factor is below 1.
    """
    h = op.h
    w_top, w_bot = np.ones(h), np.ones(h)
    top, bot = node_energy(op, w_top, w_bot)
    excess = max(top.max(), bot.max() if bot is not None else -np.inf) - 1.0
    if excess <= tolerance:
        return excess, 0
    for _ in range(iterations):
        w_top = w_top / np.sqrt(np.maximum(top, 1.0))
        if bot is not None:
            w_bot = w_bot / np.sqrt(np.maximum(bot, 1.0))
        top, bot = node_energy(op, w_top, w_bot)
        worst = max(top.max(), bot.max() if bot is not None else -np.inf)
        if worst <= 1.0 + tolerance:
            break
    Wt, Wb = sps.diags(w_top), sps.diags(w_bot)
    pairs = {"Rt": (Wt, Wt), "Rb": (Wb, Wb), "Ttb": (Wb, Wt), "Tbt": (Wt, Wb)}
    for name, (left, right) in pairs.items():
        blk = op.blocks[name]
        if blk is not None:
            op.blocks[name] = [(left @ mat @ right).tocsr() for mat in blk]
    return excess, int(np.count_nonzero(w_top < 1.0) + np.count_nonzero(w_bot < 1.0))


#: Discrete energy excess (R + T - 1) beyond which an interface operator is refused as
#: under-resolved; smaller excesses (quadrature error at the horizon) are removed by
#: :func:`limit_energy`, which keeps reciprocity, and reported in the BSDF's ``info["notes"]``.
ENERGY_REFUSE = 1e-2


def check_operator_energy(op, i: int, layer, n: int) -> list[str]:
    """Refuse the operator of layer ``i`` if it grossly over-counts energy (its lobes are
    narrower than the spacing of ``n`` ordinates); remove small excesses where the
    representation can (:meth:`~layersim.operators.operator.Operator.limit_energy`), and return
    notes saying what was done or left (they go into the BSDF's ``info["notes"]``).

    Raises
    ------
    InfeasibleError
        Naming the layer, its roughness and ``n``.
    """
    alb = op.albedo()       # azimuthally uniform illumination
    worst = max(float((alb[r] + (alb[t] if t in alb else 0.0)).max())
                for r, t in (("Rt", "Ttb"), ("Rb", "Tbt")) if r in alb)
    if worst > 1.0 + ENERGY_REFUSE:
        raise InfeasibleError(
            f"layer {i} ({layer.kind}): with n = {n} ordinates the discrete operator "
            f"reflects and transmits {worst:.7g} times the incident energy: its lobes "
            f"(roughness {layer.alpha_u:g}" + (f", {layer.alpha_v:g}" if layer.anisotropic
                                               else "")
            + ") are narrower than the ordinate spacing; raise n in "
            "[discretization] (or remove the override and let the planner choose)")
    limited = op.limit_energy()
    if limited is None:
        if worst > 1.0 + 1e-6:
            return [f"layer {i}: the quadrature over-counts energy by {worst - 1:.2g} "
                    "(coupled-mode operator: not corrected; raise n to reduce it)"]
        return []
    excess, scaled = limited
    if scaled:
        return [f"layer {i}: the quadrature over-counted energy by up to {excess:.2g} at "
                f"{scaled} ordinate(s) (lobes at the horizon); scaled down symmetrically "
                "(reciprocity kept)"]
    return []
