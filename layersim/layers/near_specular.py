"""Near-specular interfaces (roughness up to :data:`~layersim.solved.lobe.NEAR_SPECULAR_ALPHA`): the
smooth transport plus the observable lobe (:mod:`layersim.solved.lobe`).

* a dielectric top coat over an opaque base that scatters wider than its refraction blur is
  a smooth boundary (Snell-matched ordinates) whose direct reflection is the microfacet lobe
  and whose transmitted and internally reflected energies are the rough interface's;
* a conductor is a mirror (Fresnel diagonal) whose reflectance is the rough interface's
  reflected energy; alone it is evaluated as its exact lobe, under other layers its lobe must
  be blurred by a rough interface above it.

Elsewhere a near-specular interface is left to the exact projection (its cost grows like
``1 / alpha``), and the plan says so.
"""

from __future__ import annotations

from ..errors import InfeasibleError
from ..ingredients.smooth import smooth_conductor_operator
from ..solved.lobe import (NEAR_SPECULAR_ALPHA, NEAR_SPECULAR_BASE_ALPHA, NEAR_SPECULAR_WIDE_MAX,
                           NearSpecularLobe, near_specular_conductor_error, near_specular_error)
from . import smooth
from .base import LayerPlan

__all__ = ["plan_coat", "plan_conductor", "coat_operator", "conductor_operator"]


def plan_coat(scene, i: int, layer, survey) -> bool:
    """Plan a nearly smooth dielectric top interface as a smooth boundary plus its lobe and
    return True; False where the split does not apply, leaving it to the exact projection: not
    the top interface, too rough, a tabulated NDF, a boundary the smooth machinery refuses, or a
    base that would show the refraction blur the split leaves out (the split needs an opaque
    base that scatters wider than that blur: diffuse, measured, or a conductor rougher than
    :data:`~layersim.solved.lobe.NEAR_SPECULAR_ALPHA`)."""
    lo, hi = min(layer.alpha_u, layer.alpha_v), max(layer.alpha_u, layer.alpha_v)
    if layer.ndf is not None or layer.film is not None:
        # the lobe of layersim.solved.lobe is analytic, with bare Fresnel factors
        return False
    base = scene.channel(0).layers[-1]
    if (i != 0 or lo > NEAR_SPECULAR_ALPHA or hi > NEAR_SPECULAR_WIDE_MAX
            or not base.opaque or base.lobe_width() <= NEAR_SPECULAR_ALPHA):
        return False
    if layer.energy_compensation != "none":
        # the split's lobe has no compensation term, and the exact projection of so narrow a
        # lobe is far over the memory limit
        raise InfeasibleError(
            f"layer {i} (dielectric): field 'energy_compensation': a near-specular coat (alpha "
            f"<= {NEAR_SPECULAR_ALPHA:g}) is solved by the smooth split, which has no "
            "compensation term; set energy_compensation = \"none\" on this layer (at alpha "
            "0.03 the hemispherical single-scattering loss is 4e-4)")
    try:
        smooth.plan_dielectric(scene, i, layer, survey)
    except InfeasibleError:
        return False
    lp = survey.layers[-1]
    lp.action = "near-specular split (smooth top boundary + lobe)"
    lp.detail = (f"{layer.distribution} alpha=({layer.alpha_u:g}, {layer.alpha_v:g}), relative "
                 f"index {survey.snell_eta:.4g}: Snell-matched smooth transport with the rough "
                 "transmittance; the direct reflection is the microfacet lobe (layersim.solved.lobe); "
                 f"{near_specular_error(hi)}")
    survey.lobes["top"] = {"eta": survey.snell_eta, "alpha_u": layer.alpha_u,
                           "alpha_v": layer.alpha_v, "distribution": layer.distribution,
                           "rotation": layer.rotation, "k": 0.0}
    survey.near_specular = (*survey.near_specular, i)
    return True


def blurred_below(scene, i: int) -> bool:
    """True if a rough dielectric interface that the solve projects (not smooth, not
    near-specular) lies above layer ``i``: it blurs what layer ``i`` reflects by more than a
    near-specular lobe's width."""
    return any(x.is_interface and not x.opaque and x.lobe_width() > NEAR_SPECULAR_ALPHA
               for x in scene.channel(0).layers[:i])


def plan_conductor(scene, i: int, layer, survey) -> bool:
    """Plan a nearly smooth conductor as a mirror (Fresnel diagonal) whose reflectance is the
    rough interface's reflected energy ``E_R`` (azimuth average, single-scattering loss
    included; :meth:`layersim.solved.lobe.NearSpecularLobe.reflectance`), and return True; False
    where it is left to the exact projection.

    Alone (the top layer), the conductor is the whole BSDF: ``eval``, ``albedo`` and
    ``bin_energies`` use its exact microfacet lobe, and the mirror only stands for it when the
    BSDF is added to other layers. Under other layers its lobe (about ``2 alpha`` wide) must be
    blurred by a rough interface above it (:func:`blurred_below`) and both its roughnesses be
    at most :data:`~layersim.solved.lobe.NEAR_SPECULAR_BASE_ALPHA`; behind a smooth or near-specular
    coat the lobe is seen directly, and near the coat's critical angle part of it is trapped, which
    a mirror does not reproduce (``benchmarks/features/near_specular.txt``)."""
    lo, hi = min(layer.alpha_u, layer.alpha_v), max(layer.alpha_u, layer.alpha_v)
    if lo > NEAR_SPECULAR_ALPHA or layer.film is not None:
        # (a film: the mirror's reflectance and its lobe have bare Fresnel factors)
        return False
    if i > 0 and (hi > NEAR_SPECULAR_BASE_ALPHA or not blurred_below(scene, i)):
        why = (f"its wider roughness exceeds {NEAR_SPECULAR_BASE_ALPHA:g}"
               if hi > NEAR_SPECULAR_BASE_ALPHA else "no rough interface above it blurs its lobe")
        survey.hints.append(
            f"layer {i} (conductor) is near-specular but is projected exactly, at a cost that "
            f"grows like 1 / alpha: it is split into a mirror only under a rough interface "
            f"(alpha > {NEAR_SPECULAR_ALPHA:g}) and with both roughnesses at most "
            f"{NEAR_SPECULAR_BASE_ALPHA:g}, and here {why}; use layersim.montecarlo for this "
            "stack")
        return False
    if layer.energy_compensation != "none":
        # the mirror and its lobe have no compensation term (as near-specular coats)
        raise InfeasibleError(
            f"layer {i} (conductor): field 'energy_compensation': a near-specular conductor "
            f"(alpha <= {NEAR_SPECULAR_ALPHA:g}) is solved as a mirror with its lobe, which has "
            "no compensation term; set energy_compensation = \"none\" on this layer (its "
            "single-scattering loss is negligible but near grazing: a mirror of alpha 0.03 "
            "loses 1e-6 at 78 degrees, 1.6 % at 85)")
    where = ("alone: eval, albedo and bin_energies use its exact microfacet lobe "
             "(layersim.solved.lobe)" if i == 0 else
             f"the rough interface above blurs its lobe; {near_specular_conductor_error(hi)}")
    survey.layers.append(LayerPlan(
        i, layer.kind, "near-specular conductor (mirror with the rough reflectance)",
        f"{layer.distribution} alpha=({layer.alpha_u:g}, {layer.alpha_v:g}): Fresnel diagonal "
        f"scaled to the rough reflected energy; {where}"))
    survey.near_specular = (*survey.near_specular, i)
    return True


def coat_operator(job):
    """The smooth boundary with the rough coat's internal reflectance."""
    lobe = job.plan.lobes.get("top")
    R = None if lobe is None else NearSpecularLobe(**lobe).internal_reflectance(job.grid.mu)
    return smooth.dielectric_operator(job, R)


def conductor_lobe(layer, eta: complex) -> NearSpecularLobe:
    """The microfacet reflection lobe of the conductor ``layer`` at relative index ``eta``."""
    return NearSpecularLobe(eta.real, layer.alpha_u, layer.alpha_v, layer.distribution,
                            layer.rotation, k=eta.imag)


def conductor_operator(job):
    """A mirror whose reflectance is the rough reflected energy; alone, its exact lobe replaces
    that mirror when the BSDF is evaluated (:meth:`ConductorKind.evaluated_lobes`)."""
    eta = job.scene.relative_ior(job.index)
    lobe = conductor_lobe(job.layer, eta)
    return smooth_conductor_operator(job.grid, job.plan.md, eta, job.eta_above,
                                     lobe.reflectance(job.grid.mu))
