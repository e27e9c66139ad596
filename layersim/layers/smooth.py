"""Smooth interfaces (roughness 0): exact delta transport.

A smooth conductor is a Fresnel diagonal, exact on any grid. A smooth dielectric refracts
between two grids of ordinates that only one of them can match: it is solved exactly as the top
boundary of the stack (and as the bottom one of a transmissive stack with the same index ratio),
on a Snell-matched grid whose inside nodes in the escape cone are the refracted outside nodes
(:mod:`layersim.solved.boundary`); elsewhere it is refused.
"""

from __future__ import annotations

from ..errors import InfeasibleError, SceneError
from ..ingredients.smooth import boundary_reflector, smooth_conductor_operator
from .base import LayerPlan

__all__ = ["plan_conductor", "plan_dielectric", "dielectric_operator", "conductor_operator",
           "refuse_film", "matched_film_error"]


def plan_conductor(i: int, layer, survey) -> None:
    survey.layers.append(LayerPlan(i, layer.kind, "exact (specular delta)",
                                   "smooth: Fresnel reflectance on the diagonal of Rt in "
                                   "every order"))


def matched_film_error(i: int, who: str) -> SceneError:
    """The refusal of a film on an index-matched dielectric interface."""
    return SceneError(f"a film on an index-matched interface (relative index 1) is not "
                      f"handled by {who}: a rough one would transmit a delta through every "
                      "microfacet, which the microfacet model cannot represent; give the "
                      "interface a different index, or put the film on a neighbouring "
                      "interface", layer=i, kind="dielectric", field="film")


def refuse_film(scene, i: int, layer, matched: bool) -> None:
    """Refuse what the solver does not solve with a film on a dielectric: an index-matched
    interface, and a smooth boundary (whose transmission :mod:`layersim.solved.boundary` applies at
    evaluation, with bare Fresnel factors).

    Raises
    ------
    SceneError, InfeasibleError
    """
    if matched:
        raise matched_film_error(i, "the solver")
    if layer.smooth:
        raise InfeasibleError(
            f"layer {i} ({layer.kind}): field 'film': a film on a smooth dielectric boundary "
            "is not solved (the boundary's transmission is applied where the BSDF is "
            "evaluated, with bare Fresnel factors); give the interface a roughness > 0, or use "
            "layersim.montecarlo, which walks it exactly")


def plan_dielectric(scene, i: int, layer, survey) -> None:
    """A smooth dielectric boundary of the stack (top, or bottom of a transmissive stack).

    Raises
    ------
    InfeasibleError
        Inside the stack, with different indices per channel, against a lighter inside medium,
        with a ratio other than the other boundary's, or as one of two boundaries with nothing
        between them; each message says what to change.
    """
    kind = layer.kind
    mono = scene.channel(0)
    etas = {scene.channel(c).relative_ior(i).real for c in range(scene.channels)}
    last = len(mono.layers) - 1
    side = "top" if i == 0 else "bottom" if i == last else None
    if side is None:
        raise InfeasibleError(
            f"layer {i} ({kind}): a smooth dielectric interface inside the stack refracts "
            "between two grids of ordinates that cannot both be matched to the stack's "
            "(only the top interface, and the bottom one of a transmissive stack with the "
            "same index ratio, are solved exactly; a stack of flat interfaces and clear media "
            "is solved as specular paths); give it a roughness > 0, or use "
            "layersim.montecarlo")
    if len(etas) > 1:
        raise InfeasibleError(
            f"layer {i} ({kind}): a smooth dielectric boundary needs the same index in every "
            "channel (the ordinates are matched to one refraction); give one ior, or a "
            "roughness > 0")
    outside = scene.top_ior if side == "top" else layer.ior.real
    inside = mono.ior_above(i) if side == "bottom" else layer.ior.real
    ratio = inside / outside
    if ratio <= 1.0:
        raise InfeasibleError(
            f"layer {i} ({kind}): a smooth {side} boundary needs a denser medium inside the "
            f"stack (index {inside:g}) than outside ({outside:g}); give it a roughness > 0")
    if survey.snell_eta is not None and abs(survey.snell_eta - ratio) > 1e-12 * ratio:
        raise InfeasibleError(
            f"layer {i} ({kind}): the smooth bottom boundary has index ratio {ratio:g}, the "
            f"smooth top one {survey.snell_eta:g}; one grid of ordinates matches only one "
            "ratio: give one of them a roughness > 0")
    if side == "bottom" and survey.boundary and len(mono.layers) == 2:
        raise InfeasibleError(
            f"layer {i} ({kind}): two smooth boundaries with nothing between them trap the "
            "light beyond the critical angle forever (a singular adding step); put a medium "
            "(tau > 0) between them")
    survey.snell_eta = ratio
    survey.boundary[side] = outside
    survey.layers.append(LayerPlan(
        i, kind, f"smooth {side} boundary (Snell-matched ordinates)",
        f"relative index {ratio:.4g}: inside nodes in the escape cone are the refracted "
        "outside nodes; Fresnel reflection (TIR: 1) on the diagonal, transmission applied "
        "at evaluation"))


def dielectric_operator(job, reflectance=None):
    """The internal reflection of the smooth boundary, seen from inside the stack;
    ``reflectance`` (per ordinate) replaces Fresnel's (a near-specular coat's)."""
    side = "top" if job.index == 0 else "bottom"
    layer = job.layer
    inside = layer.ior.real if side == "top" else job.eta_above
    return boundary_reflector(job.grid, job.plan.md, side, inside / job.plan.boundary[side],
                              inside, reflectance)


def conductor_operator(job):
    """The Fresnel diagonal of a smooth conductor; of its film's Airy reflectance where it
    has one."""
    return smooth_conductor_operator(job.grid, job.plan.md, job.scene.relative_ior(job.index),
                                     job.eta_above,
                                     film=job.layer.film_params(job.eta_above))
