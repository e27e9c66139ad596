"""The dielectric interface: into a dielectric of real absolute index ``ior``, rough (Beckmann,
GGX or tabulated microfacets; Walter et al. 2007) or smooth.

Index-matched interfaces are exact no-ops and left out; a smooth one is a boundary of the stack
(:mod:`.smooth`), a near-specular top coat is split into smooth transport and its lobe
(:mod:`.near_specular`), a brushed top coat (narrow axis near-specular, wide axis rough) is
projected with its narrow roughness raised and its own reflection left to its exact lobe
(:mod:`.brushed`), a near-specular interface inside the stack under a rough one is a mirror from
above over its raised transmission (:mod:`.near_specular_inner`); every other one is projected
(:mod:`.interface`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from . import brushed, near_specular, near_specular_inner, smooth
from .base import LayerPlan
from .fields import MAX_IOR, Field, per_channel, real
from .interface import Interface, InterfaceKind
from .registry import register

__all__ = ["Dielectric", "DielectricKind"]


@dataclass(frozen=True)
class Dielectric(Interface):
    """Rough (or smooth) interface into a dielectric of real index ``ior``."""

    kind = "dielectric"

    def index_below(self, eta_above: float) -> float:
        return self.ior.real


class DielectricKind(InterfaceKind):
    name = "dielectric"
    record = Dielectric
    fields = (Field("ior", "absolute index of refraction of the dielectric below",
                    parse=None, required=True, per_channel=True, fit=True),
              ) + InterfaceKind.common_fields

    def parse_ior(self, ctx, value) -> list:
        return per_channel(ctx, "ior", value, lambda c, f, v: complex(
            real(lo=0.0, hi=MAX_IOR, lo_open=True)(c, f, v)))

    def raw_ior(self, per_channel):
        return self.channel_value(per_channel, lambda x: complex(x.ior).real)

    def describe_ior(self, per_channel) -> str:
        return self.values(per_channel, lambda x: f"{x.ior.real:g}")

    def plan_special(self, scene, i, layer, survey) -> bool:
        matched = all(scene.channel(c).relative_ior(i) == 1.0 for c in range(scene.channels))
        if layer.film is not None:
            smooth.refuse_film(scene, i, layer, matched)
        if matched:
            survey.left_out.append(f"layer {i} (dielectric): index-matched interface (relative "
                                   "index 1) is an exact no-op")
            survey.layers.append(LayerPlan(i, self.name, "left out", "index-matched"))
            return True
        if layer.smooth:
            smooth.plan_dielectric(scene, i, layer, survey)
            return True
        return near_specular.plan_coat(scene, i, layer, survey)

    def lobe(self, layer, eta_rel):
        """About ``alpha |1 - 1/eta|`` in refraction (the refracted direction moves by that
        fraction of the facet tilt); infinite for an index-matched interface."""
        eta = eta_rel.real
        if eta == 1.0:
            return math.inf, ""
        return (layer.lobe_width() * abs(1.0 - 1.0 / max(eta, 1.0 / eta)), "refraction lobe")

    def operator(self, job):
        mirrors = job.plan.inner_mirrors
        if mirrors and job.index in mirrors["layers"]:
            return self._inner_operator(job, mirrors)
        if job.index != 0 or job.plan.brushed is None:
            return super().operator(job)
        # a brushed coat: projected raised, in memory (its blocks are rescaled before the
        # adding takes them), its energies made the exact coat's and its own reflection left
        # to the exact lobe at evaluation (layersim.layers.brushed.coat_operator)
        return brushed.coat_operator(job, super().operator)

    def _inner_operator(self, job, mirrors: dict):
        """A near-specular inner interface (:mod:`.near_specular_inner`): projected raised, in
        memory (its blocks are rescaled before the adding takes them), its reflection from
        above projected at its own roughness (``mirrors["exact"]``) or a mirror."""
        own = mirrors["layers"][job.index]
        op = super().operator(replace(job, workspace=None))
        Rt = None
        if job.index in mirrors.get("exact", ()):
            layer = near_specular_inner.own_reflection_layer(job.layer, own)
            Rt = super().operator(replace(job, scene=job.scene.with_layer(job.index, layer),
                                          workspace=None, blocks=("Rt",))).blocks["Rt"]
        return near_specular_inner.inner_operator(
            op, near_specular_inner.lobe_params(job.scene, job.index, own), Rt)

    def evaluated_lobes(self, plan, scene, i: int) -> dict:
        """A brushed top coat's direct reflection: its exact microfacet lobe, which the
        projection leaves out."""
        if i == 0 and plan.brushed is not None:
            return {"top": brushed.lobe_params(scene, plan.brushed)}
        return {}

    def special_operator(self, job):
        if job.layer.smooth:
            return smooth.dielectric_operator(job)
        if job.index in job.plan.near_specular:
            return near_specular.coat_operator(job)
        return None

    def walk_boundary(self, scene, i):
        if scene.relative_ior(i).real == 1.0:    # nothing changes index: a pass-through
            if scene.layers[i].film is not None:
                raise smooth.matched_film_error(i, "the Monte Carlo walk")
            return None
        return super().walk_boundary(scene, i)


register(DielectricKind())
