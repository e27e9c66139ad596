"""Tabulated NDFs (Wang et al. 2008): an interface whose normal distribution is a measured
``(theta, phi)`` table instead of an analytic roughness.

The table's equivalent roughness (:meth:`layersim.ndf.NDFTable.principal_axes`: the Beckmann
``alpha_u, alpha_v`` with the same median slopes along its principal axes) stands in for the lobe
everywhere the planner reads a roughness: the ordinates ``n`` (lobe width), the orders ``md``
(series lengths of that Beckmann lobe, :mod:`layersim.plan.orders`) and the coupling ``ms`` (its
roughness ratio, at least 1: a table may depend on azimuth whatever its median slopes say). The
table's grid bounds what it can hold: no feature of D is narrower than its elevation spacing, so
a lobe of equivalent width ``alpha`` is resolved by the table when the spacing is well below
``alpha``; the report line states both. The projection samples the table
(:mod:`layersim.ingredients.tabulated`), the walk samples it too (:mod:`layersim.kernels.
tabulated`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..aniso import plan as aplan
from ..ndf import table as ndf_table
from .base import LayerPlan
from .fields import Ctx

__all__ = ["parse_ndf", "equivalent_lobe", "plan"]


def parse_ndf(ctx: Ctx, raw: Mapping[str, Any], dist: str):
    """The NDF table of ``distribution = "tabulated"`` (None otherwise): ``ndf`` is the path
    of an ``.npz`` file (relative to the scene file) or an inline table ``{theta, phi, D}``
    with angles in degrees (:mod:`layersim.ndf.table`)."""
    if dist != "tabulated":
        if "ndf" in raw:
            raise ctx.error("ndf", 'is only used with distribution = "tabulated"')
        return None
    if "roughness" in raw:
        raise ctx.error("roughness", 'a tabulated NDF takes no roughness (the table is the '
                                     "distribution); remove it")
    value = raw.get("ndf")
    if value is None:
        raise ctx.error("ndf", 'is required with distribution = "tabulated": the path of an '
                               ".npz file (theta, phi, D) or an inline table {theta, phi, D}")
    if isinstance(value, str):
        path = Path(value)
        if not path.is_absolute() and ctx.source is not None:
            path = Path(ctx.source).parent / path
        return ndf_table.load_ndf(path, layer=ctx.layer, kind=ctx.kind)
    if isinstance(value, Mapping):
        unknown = set(value) - {"theta", "phi", "D"}
        if unknown or len(value) != 3:
            raise ctx.error("ndf", "an inline table has exactly the keys theta, phi (degrees) "
                                   "and D (1/sr, one row per theta)")
        return ndf_table.from_arrays(np.radians(_array(ctx, value["theta"])),
                                     np.radians(_array(ctx, value["phi"])),
                                     _array(ctx, value["D"]), source="inline table",
                                     layer=ctx.layer, kind=ctx.kind)
    raise ctx.error("ndf", f"must be a file path or an inline table, got {type(value).__name__}")


def _array(ctx: Ctx, value):
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ctx.error("ndf", "inline table values must be numbers (rows of equal length)") \
            from None


def equivalent_lobe(layer):
    """The analytic Beckmann interface with the table's equivalent roughness (what the
    series-length pre-pass measures)."""
    au, av, angle = layer.ndf.principal_axes()
    return replace(layer, distribution="beckmann", ndf=None, alpha_u=au, alpha_v=av,
                   rotation=layer.rotation + angle)


def plan(i: int, layer, eta_rel: complex, width: float) -> LayerPlan:
    """The plan line of a tabulated-NDF interface: coupled-mode projection with ``ms`` of its
    equivalent Beckmann lobe (at least 1), and the table's grid against that lobe's width."""
    table = layer.ndf
    ms = max(1, aplan.ms_for_layer(equivalent_lobe(layer)))
    d_theta = float(np.max(np.diff(table.theta)))
    d_phi = float(np.max(np.diff(np.append(table.phi, table.phi[0] + 2 * math.pi))))
    alpha = min(layer.alpha_u, layer.alpha_v)
    fine = ("resolves" if d_theta <= 0.25 * alpha else
            "coarsely resolves (D is bilinear between nodes)")
    rot = f", rotated {math.degrees(layer.rotation):g} deg" if layer.rotation else ""
    eta = (f"{eta_rel.real:.4g}" if eta_rel.imag == 0
           else f"{eta_rel.real:.4g}+{eta_rel.imag:.4g}i")
    return LayerPlan(
        i, layer.kind, "project (coupled modes)",
        f"{table.describe()}{rot}, relative index {eta}, sampled in (phi_d, phi_s); grid "
        f"spacing "
        f"{math.degrees(d_theta):.3g} x {math.degrees(d_phi):.3g} deg {fine} its equivalent "
        f"width {math.degrees(alpha):.3g} deg; n and md as for that Beckmann lobe, ms = {ms}",
        width=width, ms=ms)
