"""The Fourier orders ``md``: from the lobes themselves, through the projection's pre-pass.

The pre-pass (:func:`layersim.ingredients.microfacet.series_lengths`, and
:func:`layersim.ingredients.aniso_microfacet.series_lengths` for coupled modes) returns the
length of every significant ordinate pair's series; the plan keeps every order needed by pairs
whose incident and outgoing elevations are both within :data:`THETA_FULL` of the normal. A lobe
at elevation theta is ~alpha cos(theta) wide in azimuth, so pairs closer to the horizon would
need ~1/(alpha mu) orders (thousands at the most grazing ordinates); they are truncated and
tapered with the Jackson kernel (:func:`layersim.operators.fourier.taper_factors`: a non-negative
kernel, so that they blur instead of ringing negative). Truncating
orders never changes energy (only order 0 carries energy). Media add the reach of their phase
function.
"""

from __future__ import annotations

import math

import numpy as np

from ..aniso import plan as aplan
from ..errors import InfeasibleError
from ..ingredients import aniso_microfacet, microfacet
from ..layers import kind_of
from ..operators.operator import Grid
from ..scene import MAX_ORDERS, Discretization, Scene

#: Lobes with both elevations within this angle (degrees) of the normal keep all their
#: Fourier orders.
THETA_FULL = 80.0
#: Fourier orders a solve may use (the scene validator's limit on ``md``).
MD_MAX = MAX_ORDERS


def interface_lengths(grid: Grid, mono: Scene, layers: list,
                      theta_full: float = THETA_FULL, own_reflections: dict | None = None
                      ) -> list:
    """The pre-pass of every projected interface of ``mono`` (one channel): a list of
    ``(LayerPlan, lengths)``, with each layer plan's ``orders`` set to the longest series of
    its pairs within ``theta_full`` degrees of the normal (:data:`THETA_FULL`, or the scene's
    ``[discretization] theta_full``). Coupled layers (``ms > 0``) are measured at their ``ms``
    and :data:`layersim.aniso.plan.COUPLED_RELERR`; a layer plan's ``blocks`` limits the
    pairs to those blocks. ``own_reflections`` ``{index: record}``
    adds the pairs of a reflection from above projected apart, at the record's roughness
    (:mod:`layersim.layers.near_specular_inner`), to that layer's."""
    own_reflections = own_reflections or {}
    mu_full = math.cos(math.radians(theta_full))
    out = []
    for lp in layers:
        if not lp.action.startswith("project"):
            continue
        layer = mono.layers[lp.index]
        layer, eta_above = kind_of(layer).equivalent_lobe(layer), mono.ior_above(lp.index)
        if lp.ms:
            lengths, mu_min = aniso_microfacet.series_lengths(grid, layer, eta_above, lp.ms,
                                                              aplan.COUPLED_RELERR, lp.blocks)
        else:
            lengths, mu_min = microfacet.series_lengths(grid, layer, eta_above,
                                                        blocks=lp.blocks)
        if lp.index in own_reflections:
            own = microfacet.series_lengths(grid, own_reflections[lp.index], eta_above,
                                            blocks=("Rt",))
            lengths, mu_min = np.concatenate([lengths, own[0]]), np.concatenate([mu_min, own[1]])
        full = mu_min >= mu_full
        lp.orders = int(lengths[full].max()) if full.any() else 1
        out.append((lp, lengths))
    return out


def needed_orders(lengths: list, media_orders: int, inner_mirrors: dict | None) -> int:
    """The orders the stack needs: the media's and the longest series of every projected
    interface (``lengths``: :func:`interface_lengths`) except the split inner interfaces
    (``inner_mirrors["layers"]``, :mod:`layersim.layers.near_specular_inner`). The adding
    equations hold order by order, so what such an interface reflects reaches the outside at
    order ``l`` only through the rough interface above at order ``l``: orders beyond that
    interface's own carry nothing out, and its pairs keep ``md`` orders, tapered (energy
    unaffected). Measured (``near_specular_anywhere.py``, 1e7 paths): keeping them all
    (md 539 instead of 171 for ``inner_under_rough``) changes no albedo gap or bin beyond
    0.01 of the tolerance and doubles the time."""
    behind = (inner_mirrors or {}).get("layers", {})
    return max([media_orders] + [lp.orders for lp, _ in lengths if lp.index not in behind])


def choose_md(disc: Discretization, md_needed: int, notes: list, overridden: dict) -> int:
    """``md``: the scene's override (with a note if below ``md_needed``) or ``md_needed``.

    Raises
    ------
    InfeasibleError
        Above :data:`MD_MAX` orders.
    """
    if disc.md is not None:
        md = disc.md
        overridden["md"] = md
        if md < md_needed:
            notes.append(f"md = {md} from the scene is below the {md_needed} orders the lobes "
                         "need: lobes are truncated in azimuth (blurred)")
    else:
        md = max(1, md_needed)
    if md > MD_MAX:
        raise InfeasibleError(f"the stack needs {md} Fourier orders (limit {MD_MAX}); increase "
                              "the roughness of the smoothest interface or use layersim.montecarlo")
    return md


def truncation_notes(lengths: list, md: int, notes: list,
                     theta_full: float = THETA_FULL, behind=()) -> None:
    """A note per interface whose pairs (beyond ``theta_full`` degrees; at any elevation for
    the split inner interfaces ``behind``, :func:`needed_orders`) need more than ``md``
    orders (``lengths``: the ``(LayerPlan, lengths)`` of :func:`interface_lengths`)."""
    for lp, pair_lengths in lengths:
        trunc = int(np.count_nonzero(pair_lengths > md))
        if not trunc:
            continue
        where = (f"beyond {theta_full:g} deg" if lp.index not in behind else
                 "(a split inner interface, seen only through the orders of the interface "
                 "above)")
        notes.append(f"layer {lp.index}: {trunc} ordinate pairs {where} would need up to "
                     f"{int(pair_lengths.max())} orders; they keep {md} (tapered; energy "
                     "unaffected)")
