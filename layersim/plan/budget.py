"""Memory and time of a plan, estimated by :mod:`layersim.plan.cost` from the projection's
pre-pass, and refused up front when they exceed the limits
(``layersim.config.settings().max_memory``, ``LAYERSIM_MAX_MEMORY``, default: half the
available memory; ``max_seconds``, ``LAYERSIM_MAX_SECONDS``, default 600 s).
"""

from __future__ import annotations

import math

from ..config import settings
from ..errors import InfeasibleError
from ..operators.operator import Grid
from ..outofcore.memory import memory_limit
from ..outofcore.parking import park_directory
from ..scene import Discretization, Scene
from . import cost

#: Lower bound on the orders a lobe of roughness alpha needs: md >= this / alpha (half the
#: estimate for a Beckmann lobe at the plan's THETA_FULL), used to refuse before the pre-pass.
MD_LOWER_PER_INV_ALPHA = 10.0


def lower_bound(disc: Discretization, mono: Scene, layers: list, grid: Grid,
                media_orders: int, ms_needed: int) -> tuple[int, int] | None:
    """``(md, bytes)``: a lower bound on the memory of a plan, known before the pre-pass that
    itself grows like ``n^2`` (``n^2 ms`` for coupled modes), and the ``md`` it assumes; None
    for stacks without a projected interface (media cost no pre-pass).

    ``md`` is the scene's ``[discretization] md`` where it gives one; otherwise a lower bound:
    a Beckmann lobe at 80 deg needs ~22.8 / alpha orders (``K ~ sqrt(2 B ln(1/eps))``,
    ``B = tan^2(theta) / (2 alpha^2)``), and half of that is safe. At that ``md`` the memory is
    bounded from below by the projection of one interface with the fewest pairs its roughness
    allows, or by building one medium (:func:`layersim.plan.cost.lower_bytes`).
    """
    projected = [lp for lp in layers if lp.action.startswith("project")]
    if not projected:
        return None
    # rough interfaces only: a smooth one has no lobe whose orders the bound could count
    rough = []
    for lp in projected:
        layer = mono.layers[lp.index]
        alpha = min(layer.alpha_u, layer.alpha_v)
        if alpha > 0:
            blocks = 1 if layer.opaque else 4
            ms = (disc.ms or lp.ms) if lp.ms else 0
            rough.append((alpha, blocks, ms))
    if disc.md is not None:
        md_lower = disc.md
    elif rough:
        md_lower = max(media_orders,
                       math.ceil(MD_LOWER_PER_INV_ALPHA / min(a for a, _, _ in rough)))
    else:
        md_lower = media_orders
    media = sum(1 for lp in layers if lp.action == "adding-doubling")
    return md_lower, cost.lower_bytes(rough, media, grid, md_lower)


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


def estimate_bytes(ings: list, grid: Grid, md: int, channels: int, anisotropic: bool) -> int:
    """Estimated peak memory of the solve (bytes above the process's own), by
    :func:`layersim.plan.cost.iso_bytes` or, for coupled modes,
    :func:`layersim.plan.cost.coupled_bytes`: with idle blocks parked on a disk where the
    workspace of the solve will be there (:func:`layersim.outofcore.parking.park_directory` of
    the in-memory estimate, the test the solve makes with the plan's estimate), else
    resident.

    Parameters
    ----------
    ings : list of Ingredient
        The solved layers (:func:`layersim.plan.cost.ingredients`).
    grid : Grid
    md : int
        Fourier orders of the solve.
    channels : int
        Colour channels (solved one after the other on one plan).
    anisotropic : bool
        Whether the stack is solved with coupled modes.
    """
    if not anisotropic:
        return cost.iso_bytes(ings, grid, md, channels)
    resident = cost.coupled_bytes(ings, grid, md, channels, parked=False)
    if park_directory(resident) is None:
        return resident
    return cost.coupled_bytes(ings, grid, md, channels, parked=True)


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
# A solve's time is modelled as three parts (projection, media, adding), each a sum of work
# units times seconds per unit measured on the shared 2-core CI VM
# (layersim.plan.cost.SECONDS; benchmarks/speed/plan_estimates.py and its output,
# benchmarks/speed/plan_estimates.txt, list every case with its estimated and measured time).


def estimate_seconds(ings: list, grid: Grid, md: int, channels: int,
                     anisotropic: bool) -> tuple[dict, dict]:
    """``(seconds, work)``: the time of each part of a solve (:data:`layersim.plan.cost.PARTS`)
    and its ``"total"``, and the work units they come from (:func:`layersim.plan.cost.iso_work`,
    :func:`layersim.plan.cost.coupled_work`)."""
    work = (cost.coupled_work if anisotropic else cost.iso_work)(ings, grid, md, channels)
    return cost.seconds(work), work


def extrapolated_coat(memory: int, work: dict, projections: int,
                      held: int) -> tuple[int, dict, dict]:
    """The cost of a solve whose top coat is projected ``projections`` times and the raised
    operators combined before one adding (the brushed route's extrapolation,
    :func:`layersim.layers.brushed.coat_operator`).

    Parameters
    ----------
    memory : int
        Peak bytes of one solve (:func:`estimate_bytes`).
    work : dict
        One solve's work units (:func:`estimate_seconds`).
    projections : int
        Number of projections of the coat (>= 1).
    held : int
        Bytes of the coat's operators (:func:`layersim.plan.cost.layer_bytes` times its
        variants over the channels: channels with one coat share its operator).

    Returns
    -------
    (int, dict, dict)
        Peak bytes: one solve's with the raised operators and their combination held; seconds
        and work units: the projection's work ``projections`` times (the base's, projected
        once, counted again: a small, conservative excess), the adding's once.
    """
    if projections <= 1:
        return memory, cost.seconds(work), work
    projecting = cost.PARTS["projection"]
    work = {k: v * (projections if k in projecting else 1) for k, v in work.items()}
    return int(memory + (projections + 1) * held), cost.seconds(work), work


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


def refuse_over_time(seconds: dict, n: int, md: int, ms: int = 0) -> None:
    """Refuse a plan whose estimated time exceeds :func:`time_limit`, naming the largest part
    (and ``ms``, a coupled plan's coupling half-width, which costs time in every part but the
    media).

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
        f"the plan (n = {n}, md = {md}{f', ms = {ms}' if ms else ''}) needs about "
        f"{seconds['total']:.0f} s ("
        + ", ".join(f"{k} {v:.0f} s" for k, v in parts.items())
        + f"), over the limit of {limit:g} s (LAYERSIM_MAX_SECONDS); the {worst} part is the "
        "largest: "
        + _TIME_ADVICE[worst] + (", or lower ms or the anisotropy"
                                 if ms and worst != "media" else ""))
