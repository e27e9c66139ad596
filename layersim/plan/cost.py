"""What a solve will cost: its peak memory and its time, from what the plan knows before any
heavy work (the pre-pass of the projected interfaces, the media's scattering orders, ``n``,
``md``, ``ms`` and the channels).

The model follows the solve (:func:`layersim.solve`) step by step rather than pricing the
stack as a whole:

* **Operators per channel.** RGB channels share one plan, and a layer whose parameters are the
  same in every channel (a clear coat over a coloured base) is built once and reused; only its
  variants are paid for (:attr:`Ingredient.variants`). The adding runs once per channel.
* **Interfaces** (isotropic, numeric projection on the CPU). Time: the sampling and transform
  of every significant ordinate pair at ``md + series length`` azimuths,
  ``SECONDS["pair_orders"]`` per pair and order. Memory: the per-pair series, ``md``
  float64 each, of every block, then the assembly's scratch and the stored nonzeros
  (:func:`interface_transient`).
* **Media** (adding-doubling). Time: the matrix exponential and doublings of the scattering
  orders (``orders h^3``) and the dense ``(md, h, h)`` arrays every order of the unscattered
  beam passes through (``md h^2``). Memory: those arrays (:func:`medium_transient`).
* **Adding** (isotropic equations, :mod:`layersim.stacking.adding`). An order is solved with dense
  LAPACK (``h^3``) only where its operands are dense enough (:func:`layersim.stacking.adding.
  sparse_density`); the others go through sparse LU at a cost per stored nonzero. The
  densities per order come from the pre-pass (pairs whose series reach the order) and the
  media's orders (:func:`adding_chain`).
* **Coupled modes** (:mod:`layersim.aniso`). Time: the coefficients ``f_{d,s}`` projected per
  pair, the block-LU factorisation of the banded adding equations and the sparse products with
  the coupled operands. Memory: a fixed working set of the projection's batches plus the
  larger of the projection of the largest coupled layer and the adding step's solution, which
  grow with the operators' nonzeros (:func:`layersim.aniso.plan.operator_entries`) to the
  power 0.8 (:func:`coupled_scale`); when the solve keeps its idle blocks in memory (no
  parking directory on a disk) the operands of the adding step stay resident beside them
  (:func:`coupled_bytes`).

The constants (bytes and seconds per unit of work) are measured: ``python
benchmarks/speed/plan_estimates.py`` solves the bench scenes and a set of RGB, anisotropic and
scaled stacks in fresh processes and prints each estimate beside the measured peak resident
memory (above the baseline of a warmed-up process) and time (output in
``benchmarks/speed/plan_estimates.txt``). Seconds are fitted to the CPU time (user + system) of
each part on the shared 2-core CI VM (AMD EPYC, two threads), which the other jobs on that
machine do not inflate as they do the wall time; on the idle machine the wall time of the
media and the isotropic adding equals it, and that of the projection and the coupled adding,
which run on both cores, is shorter. Another machine scales them by its single-core speed (LAPACK,
FFT, memory bandwidth); more cores shorten the projection only, and a CUDA device
(``LAYERSIM_DEVICE``) takes the interfaces' projection off the CPU, so the estimate is then
an upper bound.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..stacking.adding import ORDER_BATCH_ELEMENTS, SPARSE_MIN_H, sparse_density
from ..aniso import plan as aplan
from ..ingredients.medium import hg_scaling
from ..operators.operator import Grid
from ..scene import Medium, Scene

#: Seconds per unit of work on the 2-core CI VM (see the module docstring and
#: ``benchmarks/speed/plan_estimates.txt``).
SECONDS = {
    # isotropic projection, per significant ordinate pair (all blocks) and Fourier order
    "pair_orders": 4.2e-8,
    # every isotropic interface operator (launches, thread pool, energy check)
    "interfaces": 0.02,
    # media: per scattering order x h^3 (matrix exponential and doublings), and per
    # md x h^2 entry of the dense arrays of every order
    "medium_cubes": 6.5e-9,
    "medium_entries": 2.0e-8,
    # isotropic adding: per dense order x h^3, per operand nonzero of a sparse order, per order
    "dense_cubes": 3.2e-10,
    "sparse_nonzeros": 1.4e-8,
    "adding_orders": 7.0e-5,
    # coupled modes: per projected coefficient f_{d,s}; per (estimated) nonzero of the
    # operands of an adding step (products, substitutions, pruning); per unit of block-LU
    # factorisation (block rows x band^2 x (active ordinates)^3)
    "coupled_coefficients": 1.7e-7,
    "coupled_entries": 2.2e-7,
    "factor_cubes": 5.0e-11,
    # every coupled adding step (conversions, residual check, assembly)
    "coupled_steps": 0.05,
    # every solve: planning, Warp launches and bookkeeping
    "solve": 0.005,
}

#: Bytes of the model's terms (see the module docstring).
BYTES = {
    # one stored nonzero of a CSR block (float64 value, int32 column)
    "nonzero": 12,
    # projection: the scratch per stored coefficient while the blocks are assembled
    "assembly": 16,
    # media: per md x h^2 entry (dense unscattered beam, its copy and masks), per scattering
    # order x h^2 entry (exponential and doublings)
    "medium_entries": 25,
    "medium_orders": 140,
    # adding: arrays of a batch of dense orders in flight (each at most
    # layersim.stacking.adding.ORDER_BATCH_ELEMENTS float64)
    "adding_arrays": 10,
    # every solve: bookkeeping beside the operators
    "solve": 2 << 20,
    # coupled solves: the projection's batches and thread pools; per (estimated nonzeros)^0.8
    # of the largest coupled layer while it is projected, and of the lowest while the adding
    # step forms and assembles its solution (coupled_scale); per nonzero of the operands held
    # in memory where idle blocks cannot be parked
    "coupled_fixed": 70 << 20,
    "coupled_projection": 17,
    "coupled_solution": 27,
    "coupled_resident": 9,
}


@dataclass
class Ingredient:
    """What the cost model knows of one solved layer (top to bottom).

    Attributes
    ----------
    index : int
        Position in the stack.
    form : str
        The operator's form, whatever the layer's kind: ``"interface"`` (isotropic
        projection), ``"coupled"`` (coupled-mode projection),
        ``"medium"`` (adding-doubling) or ``"diagonal"`` (diffuse base, smooth or
        near-specular interfaces: a diagonal or a single order, built in no time).
    blocks : int
        Blocks the operator stores: 1 below an opaque base (``Rt``), else 4.
    variants : int
        Distinct operators over the channels (1: one operator shared by every channel).
    pairs : int
        Significant ordinate pairs of the pre-pass, all blocks.
    stored : int
        Coefficients the projection stores, ``sum(min(length, md))`` over those pairs.
    profile : ndarray (md,)
        Nonzeros of an average block per Fourier order.
    orders : list of int
        Scattering orders of a medium, per variant.
    ms : int
        Coupling half-width of a coupled layer.
    entries : int
        Estimated nonzeros of a coupled operator (:func:`layersim.aniso.plan.operator_entries`).
    coefficients : int
        Coefficients ``f_{d,s}`` a coupled projection computes.
    """

    index: int
    form: str
    blocks: int = 4
    variants: int = 1
    pairs: int = 0
    stored: int = 0
    profile: np.ndarray = field(default_factory=lambda: np.zeros(0))
    orders: list = field(default_factory=list)
    entries: int = 0
    coefficients: int = 0
    ms: int = 0


def ingredients(scene: Scene, layers: list, lengths: list, grid: Grid, md: int) -> list:
    """The :class:`Ingredient` of every solved layer of ``scene`` (top to bottom).

    Parameters
    ----------
    scene : Scene
    layers : list of LayerPlan
    lengths : list of (LayerPlan, ndarray)
        The pre-pass of the projected interfaces (:func:`layersim.plan.orders.
        interface_lengths`), with the coupled layers' ``ms``.
    grid : Grid
    md : int
    """
    h = grid.h
    monos = [scene.channel(c) for c in range(scene.channels)]
    prepass = {lp.index: pair_lengths for lp, pair_lengths in lengths}
    out = []
    for lp in layers:
        if lp.action == "left out":
            continue
        i = lp.index
        layer = monos[0].layers[i]
        variants = len({(m.layers[i], m.ior_above(i)) for m in monos})
        blocks = 1 if layer.opaque else 4
        ing = Ingredient(i, "diagonal", blocks, variants)
        if i in prepass:
            pair_lengths = np.minimum(prepass[i], md)
            ing.pairs = int(pair_lengths.size)
            ing.stored = int(pair_lengths.sum())
            if lp.ms:
                ing.form, ing.ms = "coupled", lp.ms
                ing.entries = aplan.operator_entries(prepass[i], md, lp.ms)
                ing.coefficients = int(np.sum((2 * pair_lengths - 1) * (2 * lp.ms + 1)))
            else:
                ing.form = "interface"
            # pairs whose series reach order l, per block
            reach = np.bincount(pair_lengths, minlength=md + 1)[::-1].cumsum()[::-1]
            ing.profile = np.minimum(reach[1:md + 1] / blocks, h * h)
        elif lp.action == "adding-doubling":
            ing.form = "medium"
            ing.orders = [_scattering_orders(m.layers[i], grid, md) for m in
                          {(m.layers[i], m.ior_above(i)): m for m in monos}.values()]
            # R and T dense in the scattering orders, the unscattered beam on T's diagonal
            ing.profile = np.where(np.arange(md) < max(ing.orders), float(h * h), 0.5 * h)
        elif lp.action == "diffuse":
            ing.profile = np.where(np.arange(md) == 0, float(h * h), 0.0)
        else:
            ing.profile = np.full(md, float(h))
        out.append(ing)
    return out


def _scattering_orders(medium: Medium, grid: Grid, md: int) -> int:
    """Fourier orders in which ``medium`` scatters on ``grid`` (those of
    :func:`layersim.ingredients.medium_operator`)."""
    scaling = hg_scaling(grid, medium.g, medium.albedo, medium.tau)
    if scaling.albedo == 0.0 or scaling.tau == 0.0:
        return 0
    return min(md, scaling.moments)


def operator_bytes(ing: Ingredient, md: int, h: int) -> int:
    """Bytes of the stored operator of ``ing`` (stacked CSR: nonzeros and row pointers)."""
    return int(BYTES["nonzero"] * ing.blocks * ing.profile.sum() + 8 * ing.blocks * (md * h + 1))


def layer_bytes(ing: Ingredient, md: int, h: int) -> int:
    """Bytes of the stored operator of ``ing``: its estimated nonzeros where it is coupled
    (:func:`layersim.aniso.plan.operator_entries`), else :func:`operator_bytes`."""
    if ing.form == "coupled":
        return int(BYTES["nonzero"] * ing.entries)
    return operator_bytes(ing, md, h)


def interface_transient(ing: Ingredient, md: int) -> int:
    """Peak bytes of projecting an isotropic interface beyond what is already held: the series
    of every pair (``md`` float64 each; the mirrored triangles of the reflection blocks and the
    scaled image of ``Ttb`` are copies), the slab of the assembly (at most 2^22 float64) and
    the scratch of the stored coefficients."""
    return int(8 * md * ing.pairs + 8 * min(1 << 22, md * ing.pairs)
               + BYTES["assembly"] * ing.stored)


def medium_transient(ing: Ingredient, md: int, h: int) -> int:
    """Peak bytes of building a medium's operator: the dense ``(md, h, h)`` arrays of the
    unscattered beam with their copies and masks, and the exponential and doublings of the
    scattering orders."""
    return int(BYTES["medium_entries"] * md * h * h
               + BYTES["medium_orders"] * max(ing.orders, default=0) * h * h)


@dataclass
class Step:
    """One isotropic adding step of :func:`adding_chain`."""

    dense_orders: int           # orders solved with dense LAPACK
    sparse_nonzeros: float      # operand nonzeros of the orders solved with sparse LU
    out_bytes: int              # the resulting stack


def adding_chain(ings: list, md: int, h: int) -> list:
    """The steps of adding ``ings`` (isotropic, top to bottom) bottom up, as
    :func:`layersim.solver.solve` does: per step, the orders that go dense (their operands'
    nonzeros, the top's ``Rb``, ``Ttb``, ``Tbt`` and the bottom's blocks, at least
    :func:`layersim.stacking.adding.sparse_density` of the entries; every order below
    :data:`~layersim.stacking.adding.SPARSE_MIN_H` ordinates), the nonzeros of the others, and the
    size of the stack. A stack's blocks hold, per order, the nonzeros of both operands (products
    spread them; at most ``h^2``)."""
    if not ings:
        return []
    steps = []
    profile, blocks = ings[-1].profile, ings[-1].blocks
    for top in reversed(ings[:-1]):
        opaque = blocks == 1
        counts = 3 * top.profile + (1 if opaque else 4) * profile
        entries = (4 if opaque else 7) * float(h * h)
        if h < SPARSE_MIN_H:
            dense = np.ones(md, bool)
        else:
            dense = counts / entries >= sparse_density(h)
        profile = np.minimum(top.profile + profile, h * h)
        out = Ingredient(-1, "stack", blocks=blocks, profile=profile)
        steps.append(Step(int(dense.sum()), float(counts[~dense].sum()),
                          operator_bytes(out, md, h)))
    return steps


def iso_bytes(ings: list, grid: Grid, md: int, channels: int) -> int:
    """Peak bytes of an isotropic solve: its steps in order (per channel, the operators not
    yet built bottom up, then the adding steps), each step's transient on top of what is held
    then (operators still needed, the stacks of the channels done)."""
    h = grid.h
    channels = max(1, channels)
    sizes = [operator_bytes(ing, md, h) for ing in ings]
    steps = adding_chain(ings, md, h)
    batch = BYTES["adding_arrays"] * 8 * min(ORDER_BATCH_ELEMENTS, md * h * h)
    held = peak = BYTES["solve"]
    for c in range(channels):
        for ing, size in zip(reversed(ings), reversed(sizes)):
            if c and ing.variants == 1:
                continue            # built for the first channel, kept for all
            transient = (interface_transient(ing, md) if ing.form == "interface" else
                         medium_transient(ing, md, h) if ing.form == "medium" else 0)
            peak = max(peak, held + transient)
            held += size
        stack = 0
        for step in steps:
            peak = max(peak, held + batch + 2 * step.out_bytes)
            held += step.out_bytes - stack
            stack = step.out_bytes
        # the channel's own operators go, the shared ones and its stack stay
        held -= sum(size for ing, size in zip(ings, sizes) if ing.variants > 1)
    return int(peak)


def stacks_bytes(ings: list, grid: Grid, md: int, channels: int, anisotropic: bool) -> int:
    """Bytes of the solved stacks of all ``channels`` (what a solve returns): the last adding
    step's result (:func:`coupled_chain` or :func:`adding_chain`), or the one operator of a
    one-layer stack."""
    h = grid.h
    if anisotropic:
        steps = coupled_chain(ings, md, h)
        one = BYTES["nonzero"] * steps[-1].result if steps else 0
    else:
        steps = adding_chain(ings, md, h)
        one = steps[-1].out_bytes if steps else 0
    if not steps and ings:
        one = operator_bytes(ings[0], md, h)
    return int(max(1, channels) * one)


def iso_work(ings: list, grid: Grid, md: int, channels: int) -> dict:
    """Work units of an isotropic solve (the keys of :data:`SECONDS`)."""
    h = float(grid.h)
    steps = adding_chain(ings, md, grid.h)
    return {
        "pair_orders": float(sum(i.variants * i.pairs * md for i in ings
                                 if i.form == "interface")),
        "medium_cubes": float(sum(sum(i.orders) * h ** 3 for i in ings if i.form == "medium")),
        "medium_entries": float(sum(i.variants * md * h * h for i in ings
                                    if i.form == "medium")),
        "dense_cubes": channels * float(sum(s.dense_orders for s in steps)) * h ** 3,
        "sparse_nonzeros": channels * float(sum(s.sparse_nonzeros for s in steps)),
        "adding_orders": channels * float(len(steps) * md),
        "interfaces": float(sum(i.variants for i in ings if i.form == "interface")),
        "solve": 1.0,
    }


#: The parts of the time model and the work units each is made of.
PARTS = {"projection": ("pair_orders", "interfaces", "coupled_coefficients", "solve"),
         "media": ("medium_cubes", "medium_entries"),
         "adding": ("dense_cubes", "sparse_nonzeros", "adding_orders", "coupled_entries",
                    "factor_cubes", "coupled_steps")}


def seconds(work: dict) -> dict:
    """Seconds of each part of :data:`PARTS` from the work units, and their ``"total"``."""
    out = {part: sum(work.get(k, 0.0) * SECONDS[k] for k in keys)
           for part, keys in PARTS.items()}
    out["total"] = sum(out.values())
    return out


# --- coupled modes -----------------------------------------------------------------------------


def _groups(ings: list) -> list:
    """The operands of the coupled adding (top to bottom): each run of consecutive isotropic
    ingredients (a list, added isotropically first, :func:`layersim.solver._add_mixed`) and each
    coupled ingredient."""
    groups: list = []
    for ing in ings:
        if ing.form == "coupled":
            groups.append(ing)
        elif groups and isinstance(groups[-1], list):
            groups[-1].append(ing)
        else:
            groups.append([ing])
    return groups


def _run_entries(run: list, md: int, h: int) -> int:
    """Nonzeros of an isotropic run's operator once converted to coupled modes (block diagonal:
    a cosine and a sine copy of every order)."""
    steps = adding_chain(run, md, h)
    last = run[-1] if not steps else None
    nonzeros = (last.blocks * last.profile.sum() if last is not None
                else steps[-1].out_bytes / BYTES["nonzero"])
    return int(2 * nonzeros)


@dataclass
class CoupledStep:
    """One coupled adding step of :func:`coupled_chain`."""

    entries: int            # nonzeros of both operands (estimated)
    lowest: int             # nonzeros of the lower operand
    band: int               # coupling half-width of the step's system (blocks each side)
    converted: int          # nonzeros of an isotropic operand converted to coupled modes
    result: int             # nonzeros of the stack (estimated)


def coupled_chain(ings: list, md: int, h: int) -> list:
    """The coupled adding steps of a stack with coupled layers, bottom up. The system of a
    step couples the orders ``ms`` of its top plus that of its bottom operand apart; the
    stack of a step holds at most 0.3 of the estimated nonzeros of its larger operand
    (measured: 0.19-0.32)."""
    groups = _groups(ings)
    size = lambda g: (_run_entries(g, md, h), 0) if isinstance(g, list) else (g.entries, g.ms)
    below, ms_below = size(groups[-1])
    converted_below = below if isinstance(groups[-1], list) else 0
    steps = []
    for g in reversed(groups[:-1]):
        above, ms_above = size(g)
        converted = (above if isinstance(g, list) else 0) + converted_below
        result = int(0.3 * max(above, below))
        steps.append(CoupledStep(above + below, below, ms_above + ms_below, converted, result))
        below, ms_below, converted_below = result, ms_above + ms_below, 0
    return steps


#: Exponent of the coupled transients' growth with the operators' nonzeros (see
#: :func:`coupled_scale`).
COUPLED_EXPONENT = 0.8


def coupled_scale(entries: int) -> float:
    """``1e6 (entries / 1e6)^0.8``: the measured peaks of the projection and the adding step of
    coupled solves grow more slowly than the operators' estimated nonzeros (at ``ms`` 6-16
    and ``n`` 66-390: 21 bytes per estimated nonzero at 17.8 million, 9.5 at 163 million,
    parked): the products are formed in chunks and the pieces of the out-of-core workspace
    have bounded sizes, so their transients level off while the stored nonzeros grow."""
    return 1e6 * (max(entries, 0) / 1e6) ** COUPLED_EXPONENT


def coupled_bytes(ings: list, grid: Grid, md: int, channels: int, parked: bool) -> int:
    """Peak bytes of a solve with coupled modes: per channel, its operators built bottom up
    (a coupled projection costs a fixed working set plus ``BYTES["coupled_projection"]`` per
    :func:`coupled_scale` of its estimated nonzeros; isotropic ones as in :func:`iso_bytes`),
    then its adding steps (the fixed working set plus ``BYTES["coupled_solution"]`` per
    :func:`coupled_scale` of the lower operand's nonzeros, and the isotropic operands
    converted). Without ``parked`` (no parking directory on a disk,
    :func:`layersim.outofcore.parking.park_directory`) the coupled operators and the
    converted isotropic ones stay resident meanwhile. Held throughout: the shared isotropic
    operators and the stacks of the channels done."""
    h = grid.h
    channels = max(1, channels)
    resident = lambda entries: 0 if parked else BYTES["coupled_resident"] * entries
    steps = coupled_chain(ings, md, h)
    stack_bytes = BYTES["nonzero"] * steps[-1].result if steps else 0
    shared = sum(operator_bytes(i, md, h) for i in ings
                 if i.form != "coupled" and i.variants == 1)
    held = peak = BYTES["solve"]
    done = 0
    for c in range(channels):
        held = BYTES["solve"] + done + (shared if c else 0)
        coupled_held = 0
        for ing in reversed(ings):
            if ing.form == "coupled":
                peak = max(peak, held + coupled_held + BYTES["coupled_fixed"]
                           + BYTES["coupled_projection"] * coupled_scale(ing.entries))
                coupled_held += resident(ing.entries)
            elif not (c and ing.variants == 1):
                transient = (interface_transient(ing, md) if ing.form == "interface" else
                             medium_transient(ing, md, h) if ing.form == "medium" else 0)
                peak = max(peak, held + coupled_held + transient)
                held += operator_bytes(ing, md, h)
        for step in steps:
            peak = max(peak, held + coupled_held + BYTES["coupled_fixed"]
                       + BYTES["coupled_solution"] * coupled_scale(step.lowest)
                       + BYTES["nonzero"] * step.converted)
        done += stack_bytes
    return int(peak)


def coupled_work(ings: list, grid: Grid, md: int, channels: int) -> dict:
    """Work units of a solve with coupled modes (the keys of :data:`SECONDS`): the isotropic
    parts as in :func:`iso_work` (runs of isotropic layers are added isotropically), the
    coupled projections' coefficients, and per coupled adding step the nonzeros of its
    operands and its block-LU factorisation (``2 md`` block rows of ``h / 2`` active
    ordinates on average, a band of ``band`` blocks each side: ``2 md band^2 (h / 2)^3``)."""
    h = float(grid.h)
    iso = [g for g in _groups(ings) if isinstance(g, list)]
    work = {k: 0.0 for k in SECONDS}
    for run in iso:
        for k, v in iso_work(run, grid, md, channels).items():
            work[k] += v
    steps = coupled_chain(ings, md, grid.h)
    work["coupled_coefficients"] = float(sum(i.variants * i.coefficients for i in ings
                                             if i.form == "coupled"))
    work["coupled_entries"] = channels * float(sum(s.entries for s in steps))
    work["factor_cubes"] = channels * float(sum(2 * md * s.band ** 2 * (h / 2) ** 3
                                                for s in steps))
    work["coupled_steps"] = channels * float(len(steps))
    work["solve"] = 1.0
    return work


# --- before the pre-pass ---------------------------------------------------------------------


def pairs_lower_bound(alpha: float, blocks: int, h: int) -> int:
    """A lower bound on the significant ordinate pairs of a rough interface of roughness
    ``alpha`` (its narrowest axis): ``blocks min(0.7, 2 alpha) h^2``. The pre-pass keeps
    ``c blocks alpha h^2`` pairs with ``c`` from 0.77 (alpha 1) to 9.6 (alpha 0.01) for
    dielectrics and 1 to 15 for conductors, independent of ``n`` (64 to 800 ordinates,
    Beckmann)."""
    return int(blocks * min(0.7, 2.0 * alpha) * h * h)


def lower_bytes(interfaces: list, media: int, grid: Grid, md: int) -> int:
    """A lower bound on the peak memory of a plan, from what is known before the pre-pass:
    the largest transient of projecting one of ``interfaces`` (``(alpha, blocks, ms)`` each,
    at least :func:`pairs_lower_bound` pairs of at least one coefficient; coupled layers at
    the estimated fill of :func:`layersim.aniso.plan.operator_entries`) and of building one
    of ``media`` media, at ``md`` orders."""
    h = grid.h
    peak = BYTES["medium_entries"] * md * h * h if media else 0
    for alpha, blocks, ms in interfaces:
        pairs = pairs_lower_bound(alpha, blocks, h)
        if ms:
            peak = max(peak, BYTES["coupled_fixed"] + BYTES["coupled_projection"]
                       * coupled_scale(aplan.FILL * pairs * (2 * ms + 1)))
        else:
            ing = Ingredient(-1, "interface", blocks, pairs=pairs, stored=pairs)
            peak = max(peak, interface_transient(ing, md))
    return int(BYTES["solve"] + peak)
