"""The conductor: an opaque interface of complex index ``ior = eta + i k``, rough (Beckmann, GGX
or tabulated microfacets) or smooth.

A smooth conductor is a Fresnel diagonal (:mod:`.smooth`), a near-specular one a mirror with the
rough reflected energy (:mod:`.near_specular`); every other one is projected
(:mod:`.interface`), its reflection block only.
"""

from __future__ import annotations

from dataclasses import dataclass

from . import near_specular, smooth
from .fields import Field, conductor_ior
from .interface import Interface, InterfaceKind
from .registry import register

__all__ = ["Conductor", "ConductorKind"]


@dataclass(frozen=True)
class Conductor(Interface):
    """Rough (or smooth) opaque conductor with complex index ``ior = eta + i k``."""

    kind = "conductor"

    @property
    def opaque(self) -> bool:
        return True


class ConductorKind(InterfaceKind):
    name = "conductor"
    record = Conductor
    fields = (Field("ior", "complex index [eta, k] (k > 0), or three [eta, k] pairs for R, G, B",
                    parse=None, required=True, per_channel=True, fit=True),
              ) + InterfaceKind.common_fields

    def parse_ior(self, ctx, value) -> list:
        if (isinstance(value, (list, tuple)) and len(value) == 3
                and all(isinstance(v, (list, tuple, complex)) for v in value)):
            return [conductor_ior(ctx, f"ior[{c}]", v) for c, v in enumerate(value)]
        return [conductor_ior(ctx, "ior", value)]

    def raw_ior(self, per_channel):
        return self.channel_value(per_channel, lambda x: [x.ior.real, x.ior.imag])

    def describe_ior(self, per_channel) -> str:
        return self.values(per_channel, lambda x: f"{x.ior.real:g}+{x.ior.imag:g}i")

    def plan_special(self, scene, i, layer, survey) -> bool:
        if layer.smooth:
            smooth.plan_conductor(i, layer, survey)
            return True
        return near_specular.plan_conductor(scene, i, layer, survey)

    def lobe(self, layer, eta_rel):
        return layer.lobe_width(), "reflection lobe"

    def evaluated_lobes(self, plan, scene, i: int) -> dict:
        """Alone (on top, nothing below it is seen), a near-specular conductor is its exact
        microfacet lobe, which its operator's mirror stands for."""
        if i == 0 and i in plan.near_specular:
            return {"top": near_specular.conductor_lobe(scene.layers[i],
                                                        scene.relative_ior(i)).params()}
        return {}

    def special_operator(self, job):
        if job.layer.smooth:
            return smooth.conductor_operator(job)
        if job.index in job.plan.near_specular:
            return near_specular.conductor_operator(job)
        return None


register(ConductorKind())
