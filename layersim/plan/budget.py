"""Memory of a plan: estimated from the projection's pre-pass (coefficients actually stored)
and refused up front when it exceeds the limit (``layersim.config.settings().max_memory``,
``LAYERSIM_MAX_MEMORY``; default: half the available memory).
"""

from __future__ import annotations

import math

import numpy as np

from ..aniso import plan as aplan
from ..config import settings
from ..errors import InfeasibleError
from ..operator import Grid
from ..outofcore.memory import memory_limit
from ..scene import Discretization, Scene

#: Lower bound on the orders a lobe of roughness alpha needs: md >= this / alpha (half the
#: estimate for a Beckmann lobe at the plan's THETA_FULL), used to refuse before the pre-pass.
MD_LOWER_PER_INV_ALPHA = 10.0
#: Peak bytes of projecting an isotropic interface, per (order x h x h) entry: the series of
#: every block's pairs (~16) plus the dense per-block assembly and its temporaries (~24).
#: ``benchmarks/memory_phases.py`` compares the estimate with the measured peak.
PROJECTION_BYTES = 40


def lower_bound(disc: Discretization, mono: Scene, layers: list, grid: Grid,
                media_orders: int, ms_needed: int) -> tuple[int, int] | None:
    """``(md, bytes)``: a lower bound on the memory of a plan, known before the pre-pass that
    itself grows like ``n^2`` (``n^2 ms`` for coupled modes), and the ``md`` it assumes; None
    for stacks without a projected interface (media cost no pre-pass).

    ``md`` is the scene's ``[discretization] md`` where it gives one; otherwise a lower bound:
    a Beckmann lobe at 80 deg needs ~22.8 / alpha orders (``K ~ sqrt(2 B ln(1/eps))``,
    ``B = tan^2(theta) / (2 alpha^2)``), and half of that is safe. At that ``md`` the memory is
    bounded from below by the projection of one isotropic interface (:data:`PROJECTION_BYTES`
    per order and ordinate pair), or by the block-LU factors of the coupled adding equations
    (:func:`layersim.aniso.plan.factor_bytes`).
    """
    projected = [lp for lp in layers if lp.action.startswith("project")]
    if not projected:
        return None
    # rough interfaces only: a smooth one has no lobe whose orders the bound could count
    alphas = [min(mono.layers[lp.index].alpha_u, mono.layers[lp.index].alpha_v)
              for lp in projected]
    alphas = [a for a in alphas if a > 0]
    if disc.md is not None:
        md_lower = disc.md
    elif alphas:
        md_lower = max(media_orders, math.ceil(MD_LOWER_PER_INV_ALPHA / min(alphas)))
    else:
        md_lower = media_orders
    if ms_needed:
        return md_lower, aplan.factor_bytes(grid.h, md_lower, 2 * (disc.ms or ms_needed))
    return md_lower, PROJECTION_BYTES * md_lower * grid.h * grid.h


def refuse_below_lower_bound(disc: Discretization, mono: Scene, layers: list, grid: Grid,
                             media_orders: int, ms_needed: int) -> None:
    """Refuse a plan whose :func:`lower_bound` is over the limit, before the pre-pass.

    Raises
    ------
    InfeasibleError
        Naming the bound, the limit and what to change.
    """
    bound = lower_bound(disc, mono, layers, grid, media_orders, ms_needed)
    limit = memory_limit()
    if bound is None or bound[1] <= limit:
        return
    md, lower = bound
    what = f"n = {grid.n}, md {'=' if disc.md is not None else '>='} {md}" + (
        f", ms = {disc.ms or ms_needed}" if ms_needed else "")
    raise InfeasibleError(
        f"the plan ({what}) needs at least {lower / 2**30:.1f} GiB, over the limit of "
        f"{limit / 2**30:.2f} GiB (LAYERSIM_MAX_MEMORY); lower n or md"
        + (" or ms" if ms_needed else "") + " in [discretization], or increase the "
        "roughness of the smoothest interface" + (", or reduce the anisotropy"
                                                 if ms_needed else ""))


def estimate_bytes(layers: list, lengths: list, grid: Grid, md: int, media_orders: int,
                   channels: int, anisotropic: bool) -> int:
    """Estimated peak memory of the solve (bytes).

    Parameters
    ----------
    layers : list of LayerPlan
    lengths : list of (LayerPlan, ndarray)
        The pre-pass of the projected interfaces (:func:`layersim.plan.orders.interface_lengths`),
        with the coupled layers' final ``ms``.
    grid : Grid
    md, media_orders : int
        Fourier orders of the solve and of the media's phase functions.
    channels : int
        Colour channels (each solved with its own operators).
    anisotropic : bool
        Whether the stack is solved with coupled modes.
    """
    h = grid.h
    # coefficients of the isotropic interfaces (the coupled ones: layersim.aniso.plan)
    stored = sum(int(np.minimum(pair_lengths, md).sum())
                 for lp, pair_lengths in lengths if not lp.ms)
    media = sum(1 for lp in layers if lp.action == "adding-doubling")
    stored += media * (4 * media_orders * h * h + 4 * md * h)
    # the stack itself (assumed as dense as the densest ingredient, at most dense) plus the
    # adding's temporaries: per order per thread ~12 dense h x h arrays
    stored_bytes = int(12 * min(stored * 2, 4 * md * h * h)) + 12 * 8 * h * h * 8
    if anisotropic:
        entries = [aplan.operator_entries(pair_lengths, md, lp.ms)
                   for lp, pair_lengths in lengths if lp.ms]
        stored_bytes += aplan.solve_bytes(entries)
    else:
        # projecting an interface holds every block's per-pair series and then, per block,
        # the dense scatter of the operator's assembly with its temporaries
        stored_bytes += PROJECTION_BYTES * md * h * h
    return stored_bytes * max(1, channels)


def refuse_over_limit(memory: int, n: int, md: int, ms: int, anisotropic: bool) -> None:
    """Refuse a plan whose estimated ``memory`` (bytes) exceeds :func:`memory_limit`.

    Raises
    ------
    InfeasibleError
        Naming the plan, its estimate, the limit and what to lower.
    """
    limit = memory_limit()
    if memory > limit:
        raise InfeasibleError(
            f"the plan (n = {n}, md = {md}{f', ms = {ms}' if anisotropic else ''}) needs about "
            f"{memory / 2**30:.2f} GiB, over the limit of {limit / 2**30:.2f} GiB "
            "(LAYERSIM_MAX_MEMORY); lower n or md" + (" or ms" if anisotropic else "")
            + " in [discretization], or increase the roughness of the smoothest interface"
            + (" or reduce the anisotropy" if anisotropic else ""))


# --- time ------------------------------------------------------------------------------------
#
# A solve's time is modelled as three parts, each a count of work units times seconds per unit
# measured on the 2-core CI VM by ``python benchmarks/time_model.py`` (its output,
# benchmarks/time_model.txt, lists every calibration solve with its measured and estimated
# parts). The constants are the largest measured seconds per unit, so that the estimate is an
# upper bound on that machine; a faster machine finishes early.

#: Projection of a rough interface (numeric path, CPU), per stored Fourier coefficient
#: (``min(series length, md)`` summed over the pre-pass's ordinate pairs) plus
#: :data:`PAIR_UNITS` per ordinate pair.
SECONDS_PER_COEFFICIENT = 2.5e-7
PAIR_UNITS = 20
#: Adding-doubling of a medium, per ``orders x h^3 x (doublings + 7)`` (the initial slab's
#: matrix exponential costs about seven doublings).
SECONDS_PER_MEDIUM_UNIT = 1.1e-9
#: Adding equations, per ``orders x h^3`` per adding step (dense LU and products).
SECONDS_PER_ADDING_UNIT = 2.1e-9


def work_units(lengths: list, media: list, grid: Grid, md: int, steps: int,
               channels: int) -> dict:
    """The work of an isotropic solve, in the units of the time model.

    Parameters
    ----------
    lengths : list of (LayerPlan, ndarray)
        The projected interfaces' pre-pass (:func:`layersim.plan.orders.interface_lengths`).
    media : list of (int, float)
        ``(scattering orders, optical thickness)`` of every medium solved by adding-doubling.
    grid : Grid
    md : int
        Fourier orders of the solve.
    steps : int
        Adding steps (layers solved minus one).
    channels : int
        Colour channels (each solved with its own operators).

    Returns
    -------
    dict
        ``{"projection": ..., "media": ..., "adding": ...}`` work units.
    """
    h = grid.h
    projection = sum(float(np.minimum(pl, md).sum()) + PAIR_UNITS * pl.size for _, pl in lengths)
    medium = 0.0
    for orders, tau in media:
        doublings = max(0, math.ceil(math.log2(max(tau, 1e-300) / (0.5 * grid.mu[0]))))
        medium += min(orders, md) * float(h) ** 3 * (doublings + 7)
    adding = max(0, steps) * md * float(h) ** 3
    return {k: v * max(1, channels) for k, v in
            (("projection", projection), ("media", medium), ("adding", adding))}


def estimate_seconds(units: dict) -> dict:
    """Seconds of each part of a solve from its :func:`work_units`, and their ``"total"``."""
    out = {"projection": units["projection"] * SECONDS_PER_COEFFICIENT,
           "media": units["media"] * SECONDS_PER_MEDIUM_UNIT,
           "adding": units["adding"] * SECONDS_PER_ADDING_UNIT}
    out["total"] = sum(out.values())
    return out


def time_limit() -> float | None:
    """Seconds a solve may plan for: ``settings().max_seconds`` (``LAYERSIM_MAX_SECONDS``;
    None: no limit)."""
    return settings().max_seconds


#: What to lower for each part of the time model, for the refusal's message.
_TIME_ADVICE = {
    "projection": "increase the roughness of the smoothest interface, or lower n or md in "
                  "[discretization]",
    "media": "lower n in [discretization] (a strongly forward-scattering medium is delta-M "
             "scaled to the moments the grid holds), or the optical thickness",
    "adding": "lower n or md in [discretization], or increase the roughness of the smoothest "
              "interface",
}


def refuse_over_time(seconds: dict, n: int, md: int) -> None:
    """Refuse a plan whose estimated time exceeds :func:`time_limit`, naming the largest part.

    Raises
    ------
    InfeasibleError
        Naming the plan, its estimate by part, the limit and what to lower.
    """
    limit = time_limit()
    if limit is None or seconds["total"] <= limit:
        return
    parts = {k: v for k, v in seconds.items() if k != "total"}
    worst = max(parts, key=parts.get)
    raise InfeasibleError(
        f"the plan (n = {n}, md = {md}) needs about {seconds['total']:.0f} s ("
        + ", ".join(f"{k} {v:.0f} s" for k, v in parts.items())
        + f"), over the limit of {limit:g} s (LAYERSIM_MAX_SECONDS); the {worst} part is the "
        "largest: "
        + _TIME_ADVICE[worst])
