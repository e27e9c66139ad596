"""A near-specular dielectric interface inside a stack, under a rough one: its reflection from
above projected at its own roughness (or a mirror), raised below.

An inner dielectric interface of roughness at most :data:`~layersim.solved.lobe.
NEAR_SPECULAR_ALPHA` needs ``n ~ 1 / (alpha |1 - 1/eta|)`` ordinates (about 4900 at alpha 0.01,
relative index 1.3 / 1.5) for its refraction lobe. Under a rough dielectric interface (lobe
wider than :data:`~layersim.solved.lobe.NEAR_SPECULAR_ALPHA`) and over layers that scatter
wider than the interface's refraction blur, the route splits its operator (adding equations:
Grant & Hunt 1969; Zeltner & Jakob 2018, eq. 10):

* its reflection from above, ``Rt``, is what the rough interface above blurs by its own
  refraction lobe (``alpha_c |1 - 1/eta_c|`` per pass, 0.067 rad for a coat of 0.2 into 1.5).
  Its lobe is about ``2 alpha`` wide (0.02-0.06 rad), which a few hundred ordinates resolve,
  so it is projected at the interface's own roughness on the plan's grid (the interface's
  ordinary projection of that block only; the plan's ``n`` resolves it,
  :func:`annotate`), where :func:`exact_reflection` asks for it and that plan is affordable
  (:func:`layersim.plan.route.exact_unaffordable`). Elsewhere it is a mirror (diagonal in
  every Fourier order) whose reflectance is the rough interface's reflected energy
  ``E_R(mu)`` (:meth:`layersim.solved.lobe.NearSpecularLobe.mean_energies`, azimuth average;
  beyond the critical angle of a dense-to-light interface total up to the microsurface's
  loss), mixed with a share :func:`tail_weight` of the raised lobe: exact up to the inner
  lobe's slope variance against the blur's (:func:`blur_ratio`), which for a Beckmann lobe
  up to :data:`MIRROR_RATIO_MAX` the walk at 1e7 paths does not resolve;
* its transmission both ways and its reflection from below are those of the interface with
  both roughnesses raised to :data:`FLOOR` (an ordinary projection), whose refraction blur
  ``FLOOR |1 - 1/eta|`` the layers below hide (an opaque base that scatters wider, as a
  near-specular coat needs) and the rough interface above dominates; their energies are
  rescaled, reciprocally, to the interface's own: per node, ``E_Ttb`` from above is the rough
  ``E_T`` and ``E_Rb + E_Tbt`` from below the rough ones
  (:func:`layersim.ingredients.energy_match.two_sided_factors`), so that ``R + T + loss`` per
  direction is the rough interface's.

One solve, on the plan of the raised stack; only where the exact plan is unaffordable and the
scene's ``[discretization]`` leaves ``n``, ``md`` and ``tol`` free (:func:`layersim.plan.
make_plan`). The solved BSDF is an ordinary Fourier BSDF. Its error against the Monte Carlo
walk is :data:`MEASURED_ERROR`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sps

from ..ingredients.energy_match import (energy_kernel, kept_energy_factors, rescaled,
                                        scaled_block, two_sided_factors)
from ..solved.lobe import NEAR_SPECULAR_ALPHA, NEAR_SPECULAR_WIDE_MAX, NearSpecularLobe
from .near_specular import blurred_below

__all__ = ["FLOOR", "MIRROR_RATIO_MAX", "MEASURED_ERROR", "is_candidate", "why_not", "route_layers",
           "projected_scene", "projected", "annotate", "blur_ratio", "exact_reflection",
           "own_reflection_layer", "own_reflections", "lobe_params", "inner_operator"]

#: Roughness both axes of the inner interface are raised to for its transmission and its
#: reflection from below. Its refraction blur at relative index 1.15 is 0.013 rad, a fifth of
#: a coat of 0.2's; the raised plan of ``inner_under_rough`` needs n = 488 (0.56 GiB).
FLOOR = 0.1

#: A Beckmann inner interface whose reflection lobe's slope variance is at most this fraction
#: of the blur's above (:func:`blur_ratio`) keeps the mirror from above: at 0.09 (Beckmann
#: 0.01 under a coat of 0.2 into 1.5) mirror and projected lobe agree with 1e7 walk paths
#: alike (farthest bin 1.7 sigma both) and the mirror solves in 5.3 s against 9.3 s; at 0.36
#: (Beckmann 0.02) the mirror's farthest bin is 3.6 sigma, the projected lobe's 1.8. GGX,
#: whose ``alpha^2 / s^4`` tail a variance does not describe, is always projected: its mirror
#: misses by 14 sigma already at 0.12 (GGX 0.01 under a coat of 0.2 into 1.4).
MIRROR_RATIO_MAX = 0.1

#: Measured error against 1e7 walk paths per incidence at 0-70 deg
#: (``benchmarks/accuracy/near_specular_anywhere.py --case NAME --cache ...``, 2-core VM):
#: ``(case, largest albedo gap in units of max(4 se, 1e-3), fraction of the populated
#: 10 x 12 bins of all incidences within 3 sigma)``; every incidence on its own has every bin
#: within 3 sigma. With a mirror from above the GGX 0.02 case had 94.8 % (up to 33 sigma next
#: to the mirror direction), the GGX 0.01 one 98.1 % (14 sigma).
MEASURED_ERROR: tuple = (
    ("inner_under_rough (Beckmann 0.01, mirror)", 0.51, 1.0),
    ("inner_beckmann_0.02 (projected)", 0.48, 1.0),
    ("inner_ggx_under_coat (GGX 0.02, projected)", 0.29, 1.0),
    ("inner_ggx_0.01 (projected)", 0.30, 1.0),
    ("inner_ggx_0.007 (projected)", 0.30, 1.0),
)


def is_candidate(layer) -> bool:
    """True for a near-specular dielectric interface the route may take: analytic NDF, no
    film, narrow roughness in (0, NEAR_SPECULAR_ALPHA], wide one at most
    NEAR_SPECULAR_WIDE_MAX."""
    if layer.kind != "dielectric" or layer.ndf is not None or layer.film is not None:
        return False
    lo, hi = min(layer.alpha_u, layer.alpha_v), max(layer.alpha_u, layer.alpha_v)
    return 0.0 < lo <= NEAR_SPECULAR_ALPHA and hi <= NEAR_SPECULAR_WIDE_MAX


def why_not(scene, i: int) -> str | None:
    """Why candidate layer ``i`` (:func:`is_candidate`) of ``scene`` cannot be a mirror over its
    raised transmission (None if it can): the top interface (its reflection is seen directly),
    no rough interface above to blur the mirror, nothing opaque below or an interface below that
    would show the raised blur, or energy compensation."""
    layers = scene.channel(0).layers
    if i == 0:
        return "it is the top interface (its reflection is seen directly)"
    if not blurred_below(scene, i):
        return (f"no rough dielectric interface (alpha > {NEAR_SPECULAR_ALPHA:g}) above it blurs "
                "its reflection")
    if not layers[-1].opaque:
        return "nothing opaque below it hides its raised refraction blur"
    for j in range(i + 1, len(layers)):
        if layers[j].is_interface and layers[j].lobe_width() <= NEAR_SPECULAR_ALPHA:
            return (f"layer {j} ({layers[j].kind}) below it scatters narrower than alpha "
                    f"{NEAR_SPECULAR_ALPHA:g} and would show its raised refraction blur")
    if layers[i].energy_compensation != "none":
        return "it sets energy_compensation (the mirror has no compensation term)"
    return None


def route_layers(scene, allowed: bool) -> tuple[tuple, list]:
    """The inner layers of ``scene`` the route takes, and hints for those it cannot.

    Parameters
    ----------
    scene : Scene
    allowed : bool
        False where the exact plan is used (affordable, or the scene's ``[discretization]``
        sets ``n``, ``md`` or ``tol``): no layer is taken, and a candidate that could be gets a
        hint saying so.

    Returns
    -------
    (tuple of int, list of str)
        Layer indices, and one hint per candidate left to the exact projection.
    """
    taken, hints = [], []
    for i, layer in enumerate(scene.channel(0).layers):
        if not is_candidate(layer):
            continue
        why = why_not(scene, i)
        if why is None and allowed:
            taken.append(i)
            continue
        why = why or ("the scene's [discretization] sets n, md or tol, or the exact plan is "
                      "affordable")
        if i > 0:
            hints.append(
                f"layer {i} (dielectric) is a near-specular inner interface (alpha=("
                f"{layer.alpha_u:g}, {layer.alpha_v:g})) projected exactly, at a cost that "
                f"grows like 1 / alpha: it is solved as a mirror over its raised transmission "
                f"only under a rough dielectric interface, over an opaque base and interfaces "
                f"rougher than alpha {NEAR_SPECULAR_ALPHA:g}, without energy compensation and "
                f"with n, md and tol left to the plan; here {why}; use layersim.montecarlo for "
                "this stack")
    return tuple(taken), hints


def projected_scene(scene, indices) -> object:
    """``scene`` with layers ``indices`` raised to :data:`FLOOR` (both axes, never lowered)
    in every channel; rotation and everything else kept."""
    if not indices:
        return scene
    lift = lambda x: replace(x, alpha_u=max(x.alpha_u, FLOOR), alpha_v=max(x.alpha_v, FLOOR))
    stacks = tuple(tuple(lift(x) if i in indices else x for i, x in enumerate(s))
                   for s in scene.stacks)
    return replace(scene, stacks=stacks)


def projected(scene, plan):
    """The scene the solve of ``scene`` projects on ``plan`` (:attr:`layersim.plan.Plan.
    inner_mirrors`): its mirrored inner interfaces raised, or ``scene`` itself."""
    if not plan.inner_mirrors:
        return scene
    return projected_scene(scene, tuple(plan.inner_mirrors["layers"]))


def annotate(survey, scene, indices: tuple, why: str, exact: bool = False) -> None:
    """Mark layers ``indices`` of ``survey`` (the survey of the raised scene) as split: the
    split, the floor, why the exact plan is not used (``why``) and the measured error in their
    plan lines; ``survey.inner_mirrors = {"floor", "layers": {index: (alpha_u, alpha_v)},
    "exact": (index, ...)}`` (their own roughnesses, and those whose reflection from above is
    projected at it: with ``exact``, the isotropic ones, :func:`exact_reflection`). Their
    action is a projection (the plan's pre-pass prices the raised blocks), and each projected
    reflection from above adds its lobe to ``survey.widths`` (``alpha`` wide, as a conductor's
    reflection lobe counts) so that ``n`` resolves it."""
    mono = scene.channel(0)
    own = {i: mono.layers[i] for i in indices}
    exact = tuple(i for i in indices if exact and exact_reflection(scene, i))
    for lp in survey.layers:
        if lp.index not in indices:
            continue
        x = own[lp.index]
        reflection = ("projected at its own roughness" if lp.index in exact else
                      "a mirror with the rough reflected energy")
        lp.action = f"project (near-specular inner interface: reflection from above {reflection})"
        lp.detail = (f"{x.distribution} alpha=({x.alpha_u:g}, {x.alpha_v:g}) under a rough "
                     f"interface: {why}, so its reflection from above is {reflection}, and its "
                     f"transmission and reflection from below are projected at alpha {FLOOR:g} "
                     f"and rescaled to its own energies (layersim.layers.near_specular_inner) "
                     f"-- {lp.detail}; {error_line()}")
    survey.widths += [(own[i].lobe_width(), i, "dielectric", "reflection lobe from above")
                      for i in exact]
    survey.inner_mirrors = {"floor": FLOOR, "layers": {i: (x.alpha_u, x.alpha_v)
                                                      for i, x in own.items()},
                            "exact": exact}


def blur_ratio(scene, i: int) -> float:
    """``(2 alpha / blur)^2``: the slope variance of inner interface ``i``'s reflection lobe
    (``2 alpha`` wide, ``alpha`` its narrower roughness) against that of the blur of the rough
    dielectric interfaces above it, whose refraction lobes (``alpha_j |1 - 1/eta_j|`` per
    pass) add in variance: 0.09 for Beckmann 0.01 under a coat of 0.2 into 1.5."""
    mono = scene.channel(0)
    blur2 = 0.0
    for j, x in enumerate(mono.layers[:i]):
        if x.is_interface and not x.opaque and x.lobe_width() > NEAR_SPECULAR_ALPHA:
            eta = mono.relative_ior(j).real
            blur2 += (x.lobe_width() * abs(1.0 - 1.0 / max(eta, 1.0 / eta))) ** 2
    return (2.0 * mono.layers[i].lobe_width()) ** 2 / blur2


def exact_reflection(scene, i: int) -> bool:
    """True where the reflection from above of inner interface ``i`` is projected at its own
    roughness rather than a mirror: an isotropic interface (an anisotropic one would need
    coupled modes that the raised, isotropic operator does not have) unless it is a Beckmann
    one whose lobe is small against the blur above (:func:`blur_ratio` at most
    :data:`MIRROR_RATIO_MAX`, where the mirror matches its Gaussian slope variance)."""
    layer = scene.channel(0).layers[i]
    if layer.alpha_u != layer.alpha_v:
        return False
    return layer.distribution != "beckmann" or blur_ratio(scene, i) > MIRROR_RATIO_MAX


def own_reflection_layer(layer, own: tuple):
    """The raised record ``layer`` at its own roughness ``own`` ``(alpha_u, alpha_v)``."""
    return replace(layer, alpha_u=own[0], alpha_v=own[1])


def own_reflections(mono, inner_mirrors: dict | None) -> dict:
    """``{index: record at its own roughness}`` of the inner interfaces whose reflection from
    above is projected at it (``inner_mirrors["exact"]``; ``mono``: one channel of the raised
    scene), for the plan's pre-pass (:func:`layersim.plan.orders.interface_lengths`)."""
    if not inner_mirrors:
        return {}
    return {i: own_reflection_layer(mono.layers[i], inner_mirrors["layers"][i])
            for i in inner_mirrors.get("exact", ())}


def error_line() -> str:
    """The plan's words for :data:`MEASURED_ERROR`."""
    if not MEASURED_ERROR:
        return "its error against Monte Carlo is not measured; use layersim.montecarlo"
    rows = "; ".join(f"{name}: albedo gap {gap:.2f} of max(4 se, 1e-3), {100 * frac:.1f} % of "
                     "bins within 3 sigma" for name, gap, frac in MEASURED_ERROR)
    return ("measured against 1e7 walk paths at 0-70 deg "
            f"(benchmarks/accuracy/near_specular_anywhere.py): {rows}; a mirror from above "
            "(a lobe unaffordable to project, an anisotropic interface) whose lobe is not small "
            "against the blur above misses next to the mirror direction: where that matters, "
            "use layersim.montecarlo")


def lobe_params(mono, i: int, own: tuple) -> dict:
    """Parameters of :class:`~layersim.solved.lobe.NearSpecularLobe` for layer ``i`` of the
    one-channel scene ``mono`` (as given or as projected) at its own roughness ``own``
    ``(alpha_u, alpha_v)``, seen from above (relative index below / above, < 1 for a
    dense-to-light interface)."""
    layer = mono.layers[i]
    return {"eta": mono.relative_ior(i).real, "alpha_u": own[0], "alpha_v": own[1],
            "distribution": layer.distribution, "rotation": layer.rotation, "k": 0.0}


def mirror_block(op, reflectance: np.ndarray):
    """The mirror ``Rt`` of reflectance ``reflectance`` (h,) in ``op``'s representation: the
    same diagonal in every Fourier order (isotropic) or slot (coupled; block diagonal,
    :meth:`layersim.aniso.operator.AnisoOperator.from_iso`)."""
    if op.representation == "isotropic":
        return [sps.diags(reflectance, format="csr")] * op.m
    slots = op.blocks["Rt"].shape[0] // op.h
    return sps.diags(np.tile(reflectance, slots), format="csr")


def tail_weight(lobe: dict) -> float:
    """The share ``w = alpha^2 / FLOOR^2`` (mean over the two axes) of the reflection from above
    given to the raised lobe, the rest to the mirror: the mixture has the interface's slope
    variance (``w FLOOR^2``; Beckmann), which sets the first-order change of what the blur above
    shows, and for GGX, whose slope density falls like ``alpha^2 / s^4``, its far tail."""
    return 0.5 * (lobe["alpha_u"] ** 2 + lobe["alpha_v"] ** 2) / FLOOR ** 2


def inner_operator(op, lobe: dict, Rt=None):
    """The operator of the split inner interface from ``op``, its raised projection: ``Rt``
    the given block (its reflection from above projected at its own roughness, in ``op``'s
    representation) or, without one, a mirror of the rough ``E_R`` (from above) mixed with a
    share :func:`tail_weight` of the raised reflection; the other blocks rescaled so that
    ``E_Ttb`` from above and ``E_Rb + E_Tbt`` from below are the rough interface's (lobe
    parameters ``lobe``, :func:`lobe_params`)."""
    ns = NearSpecularLobe(**lobe)
    mu = op.grid.mu
    e_r, e_t = ns.mean_energies(mu)
    r_in, t_in = ns.inside_energies(mu)
    a_top, a_bot = two_sided_factors(op, e_t, r_in + t_in)
    if Rt is not None:
        return rescaled(op, a_top, a_bot, Rt)
    w = tail_weight(lobe)
    a = kept_energy_factors(energy_kernel(op, "Rt"), np.zeros((op.h, op.h)), e_r)
    raised = scaled_block(op, "Rt", a, a)
    mirror = mirror_block(op, (1.0 - w) * e_r)
    Rt = ([m + w * r for m, r in zip(mirror, raised)] if op.representation == "isotropic"
          else mirror + w * raised)
    return rescaled(op, a_top, a_bot, Rt, (1.0 - w) * e_r)
