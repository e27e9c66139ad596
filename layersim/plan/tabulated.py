"""Planning a tabulated-NDF interface (Wang et al. 2008): it is sized as its equivalent
Beckmann lobe, and the report says what the table's grid implies.

The table's equivalent roughness (:meth:`layersim.ndf.NDFTable.principal_axes`: the Beckmann
``alpha_u, alpha_v`` with the same median slopes along its principal axes) stands in for the lobe everywhere the planner
reads a roughness: the ordinates ``n`` (lobe width), the orders ``md`` (series lengths of that
Beckmann lobe, :mod:`.orders`) and the coupling ``ms`` (its roughness ratio, at least 1: a table
may depend on azimuth whatever its median slopes say). The table's grid bounds what it can
hold: no feature of D is narrower than its elevation spacing, so a lobe of equivalent width
``alpha`` is resolved by the table when the spacing is well below ``alpha``; the report line
states both.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..aniso import plan as aplan
from ..scene import Conductor, Measured
from .model import LayerPlan


def equivalent_lobe(layer):
    """The analytic Beckmann layer with the table's equivalent roughness (what the series-length
    pre-pass measures): for a tabulated NDF its own interface, for a measured base a conductor
    (an index with the Fresnel factor of a metal: its value does not change the series lengths
    much) with the lobe width as roughness; other layers unchanged."""
    if isinstance(layer, Measured):
        return Conductor(ior=complex(1.0, 3.0), alpha_u=layer.alpha, alpha_v=layer.alpha)
    if getattr(layer, "ndf", None) is None:
        return layer
    au, av, angle = layer.ndf.principal_axes()
    return replace(layer, distribution="beckmann", ndf=None, alpha_u=au, alpha_v=av,
                   rotation=layer.rotation + angle)


def measured_plan(i: int, layer) -> LayerPlan:
    """The plan line of a measured base: projected numerically (cosine series, isotropic),
    sized as a Beckmann lobe as wide as its specular peak."""
    return LayerPlan(
        i, layer.kind, "project (measured, sampled)",
        f"{layer.data.source}: MERL layout 90 x 90 x 180 (theta_h, theta_d, phi_d), lobe "
        f"width {math.degrees(layer.alpha):.3g} deg; n and md as for a Beckmann lobe of that "
        "roughness", width=layer.alpha)


def tabulated_plan(i: int, layer, eta_rel: complex, width: float) -> LayerPlan:
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
