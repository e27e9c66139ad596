"""Discretisation plan: from a validated scene, decide what to compute and at what resolution.

The plan is made before any heavy work, and says what it chose and why. Each decision is one
module of this package, and :func:`make_plan` composes them in order:

* **What each layer gets** (:mod:`.layers`): interfaces are projected, media added by
  adding-doubling, a diffuse base needs order 0; transmission blocks below an opaque base,
  index-matched interfaces and empty media (exact no-ops) are left out.
* **Representation and coupling** ``ms`` (:mod:`.coupling`; see :mod:`layersim.aniso`):
  isotropic stacks use the cosine series of :class:`~layersim.operators.operator.IsoOperator`. A
  stack with an anisotropic interface (``alpha_u != alpha_v``) uses coupled modes; each anisotropic
  layer is projected with the ``ms`` its roughness ratio needs
  (:func:`layersim.aniso.plan.ms_for_layer`), isotropic layers keep their cheaper operators
  and runs of them are added isotropically before conversion.
* **Media** (:mod:`.layers`): a Henyey-Greenstein medium with ``|g|`` above
  :data:`layersim.ingredients.medium.G_EXACT_MAX` is delta-M scaled to the Legendre moments the
  grid represents (Wiscombe 1977); its ``N``, ``f`` and scaled ``tau``/albedo are reported.
* **Ordinates** ``n`` (:mod:`.ordinates`; quadrature on mu in [-1, 1]): from the narrowest
  angular lobe of the stack.
* **Fourier orders** ``md`` (:mod:`.orders`): from the lobes themselves, through the
  projection's pre-pass over every ordinate pair (a public function of the projection
  modules); pairs near the horizon beyond :data:`THETA_FULL` are truncated and tapered, which
  never changes energy, and the plan reports how many.
* **Memory** (:mod:`.budget`, :mod:`.cost`): the solve's steps priced one by one from the
  same pre-pass (pairs and coefficients of every interface, the media's orders, operators
  shared by the channels), and refused up front when the peak exceeds the limit
  (``LAYERSIM_MAX_MEMORY`` bytes, default: half the available RAM); plans are first checked
  against a lower bound, before the pre-pass.
* **Time** (:mod:`.budget`, :mod:`.cost`): a cost model of projection, media and adding
  (isotropic and coupled), calibrated on the 2-core CI VM
  (``benchmarks/speed/plan_estimates.py``); a plan above the limit (``LAYERSIM_MAX_SECONDS``,
  default 600 s) is refused before any heavy work.

A ``[discretization]`` table in the scene overrides ``n``, ``md``, ``ms`` and the quadrature
rule.

* **Route** (:mod:`.route`): a stack of flat interfaces and clear media with a near-specular
  interface is solved by its specular paths (:mod:`layersim.specular_paths`) where the Fourier
  plan is refused or over :data:`.route.FOURIER_MAX_BYTES`; so is a near-specular dielectric
  interface inside the stack under a rough one solved as a mirror over its raised transmission
  (:mod:`layersim.layers.near_specular_inner`, :func:`.route.wants_inner_mirrors`).
"""

from __future__ import annotations

from ..errors import InfeasibleError
from ..layers.near_specular_inner import own_reflections
from ..scene import Scene, as_scene
from ..outofcore.memory import memory_limit
from .budget import (MD_LOWER_PER_INV_ALPHA, estimate_bytes, estimate_seconds, lower_bound,
                     refuse_below_lower_bound, refuse_over_limit, refuse_over_time,
                     extrapolated_coat)
from .cost import ingredients, layer_bytes
from .coupling import choose_ms, needed_ms
from .layers import scale_media, survey_projected
from .model import LayerPlan, Plan
from .route import (exact_unaffordable, fourier_unaffordable, paths_plan, try_fourier,
                    wants_inner_mirrors, wants_paths)
from .ordinates import DEFAULT_RULE, N_MAX, N_MIN, N_PER_WIDTH, SNELL_N_FACTOR, choose_grid
from .orders import (MD_MAX, THETA_FULL, choose_md, interface_lengths, needed_orders,
                     truncation_notes)

__all__ = ["Plan", "LayerPlan", "make_plan", "memory_limit", "THETA_FULL", "N_PER_WIDTH",
           "N_MIN", "N_MAX", "MD_MAX", "MD_LOWER_PER_INV_ALPHA", "DEFAULT_RULE"]


def make_plan(scene: Scene, refuse: bool = True) -> Plan:
    """Plan the solve of a monochromatic or RGB scene (RGB channels share one plan).

    Parameters
    ----------
    scene : Scene, path or dict
        As :func:`layersim.solve` takes it.
    refuse : bool
        If False, a plan over the memory limit is returned with the reason in
        :attr:`Plan.refused` instead of raising (``layersim plan`` prints it). A plan refused
        at the lower bound, before the pre-pass, then holds that bound's ``md`` and memory.

    Raises
    ------
    InfeasibleError
        If a layer cannot be represented (smooth interface) or the discretisation it needs
        exceeds the limits (ordinates, orders, and with ``refuse`` memory). The message names
        the layer, the limit and what to change.
    """
    scene = as_scene(scene, "make_plan()")
    if wants_paths(scene):
        why = fourier_unaffordable(try_fourier(fourier_plan, scene))
        if why is not None:
            try:
                return paths_plan(scene, why)
            except InfeasibleError as exc:
                if refuse:
                    raise InfeasibleError(f"{why}, and {exc}") from None
                plan = fourier_plan(scene, refuse)
                plan.notes.append(str(exc))
                return plan
    if wants_inner_mirrors(scene):
        why = fourier_unaffordable(try_fourier(fourier_plan, scene))
        if why is not None:
            return inner_plan(scene, refuse, why)
    return fourier_plan(scene, refuse)


def inner_plan(scene: Scene, refuse: bool, why: str) -> Plan:
    """The plan of ``scene`` with its near-specular inner interfaces split
    (:mod:`layersim.layers.near_specular_inner`; ``why``: why the exact plan is not used):
    their reflection from above projected at their own roughness where
    :func:`~layersim.layers.near_specular_inner.exact_reflection` asks for it and that plan
    is affordable (:func:`.route.exact_unaffordable`), else a mirror (the plan line says
    why)."""
    try:
        exact = fourier_plan(scene, False, inner=why, exact=True)
        if not exact.inner_mirrors["exact"]:
            return fourier_plan(scene, refuse, inner=why)
        reason = exact_unaffordable(exact)
    except InfeasibleError as exc:
        reason = str(exc)
    if reason is None:
        return exact
    why = (f"{why}, and its reflection from above projected at its own roughness is "
           f"unaffordable ({reason})")
    return fourier_plan(scene, refuse, inner=why)


def fourier_plan(scene: Scene, refuse: bool = True, inner: str | None = None,
                 exact: bool = False) -> Plan:
    """The plan of ``scene`` in the Fourier basis (:func:`make_plan` without the route);
    ``inner`` (why the exact plan is not used), when given, solves the near-specular inner
    interfaces under a rough one split, their reflection from above a mirror or, with
    ``exact``, projected at their own roughness where it can be (:mod:`layersim.layers.
    near_specular_inner`)."""
    disc = scene.discretization
    rule = disc.quadrature or DEFAULT_RULE
    notes: list[str] = []
    overridden: dict = {}
    # a brushed top coat is projected raised (layersim.layers.brushed): every size below is
    # that of the projected scene
    survey, scene = survey_projected(scene, inner, exact)
    layers = survey.layers
    ms_needed = needed_ms(layers, survey.left_out, notes)
    anisotropic = ms_needed > 0
    representation = "anisotropic" if anisotropic else "isotropic"
    try:
        grid = choose_grid(disc, rule, survey, notes, overridden)
    except InfeasibleError as exc:
        raise with_hints(exc, survey.hints) from None
    scale_media(scene, survey, grid)
    mono = scene.channel(0)
    try:
        refuse_below_lower_bound(disc, mono, layers, grid, survey.media_orders, ms_needed)
    except InfeasibleError as exc:
        exc = with_hints(exc, survey.hints)
        if refuse:
            raise exc from None
        md, memory = lower_bound(disc, mono, layers, grid, survey.media_orders, ms_needed)
        if disc.md is None:
            notes.append(f"md = {md} is a lower bound: the pre-pass that finds the orders the "
                         "lobes need is not run for a plan refused already at this bound")
        for k in ("md", "ms"):
            if getattr(disc, k) is not None:
                overridden[k] = getattr(disc, k)
        return Plan(rule=grid.rule, n=grid.n, md=md, ms=(disc.ms or ms_needed) if anisotropic
                    else 0, layers=layers, left_out=survey.left_out, notes=notes,
                    memory_bytes=memory, overridden=overridden,
                    representation=representation, refused=str(exc), boundary=survey.boundary,
                    lobes=survey.lobes, near_specular=survey.near_specular,
                    brushed=survey.brushed, inner_mirrors=survey.inner_mirrors)
    theta_full = disc.theta_full or THETA_FULL
    lengths = interface_lengths(grid, mono, layers, theta_full,
                                own_reflections(mono, survey.inner_mirrors))
    md_needed = needed_orders(lengths, survey.media_orders, survey.inner_mirrors)
    md = choose_md(disc, md_needed, notes, overridden)
    ms = choose_ms(disc, layers, ms_needed, notes, overridden)
    truncation_notes(lengths, md, notes, theta_full,
                     (survey.inner_mirrors or {}).get("layers", {}))
    ings = ingredients(scene, layers, lengths, grid, md)
    memory = estimate_bytes(ings, grid, md, scene.channels, anisotropic)
    seconds, work = estimate_seconds(ings, grid, md, scene.channels, anisotropic)
    if survey.brushed is not None:      # the coat projected at each floor, added once
        memory, seconds, work = extrapolated_coat(
            memory, work, len(survey.brushed["floors"]),
            ings[0].variants * layer_bytes(ings[0], md, grid.h))
    refused = None
    try:
        refuse_over_limit(memory, grid.n, md, ms, anisotropic)
        refuse_over_time(seconds, grid.n, md, ms if anisotropic else 0)
    except InfeasibleError as exc:
        exc = with_hints(exc, survey.hints)
        if refuse:
            raise exc from None
        refused = str(exc)
    return Plan(rule=grid.rule, n=grid.n, md=md, ms=ms, layers=layers, left_out=survey.left_out,
                notes=notes, memory_bytes=memory, seconds=seconds, work=work,
                overridden=overridden, representation=representation, refused=refused,
                boundary=survey.boundary, lobes=survey.lobes,
                near_specular=survey.near_specular, brushed=survey.brushed,
                inner_mirrors=survey.inner_mirrors)


def with_hints(exc: InfeasibleError, hints: list) -> InfeasibleError:
    """The refusal ``exc`` with the survey's ``hints`` (why a layer is costly) appended."""
    return InfeasibleError("; ".join([str(exc), *hints])) if hints else exc
