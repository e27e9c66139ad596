"""The Lambertian base: opaque, reflectance ``albedo`` in every direction.

Its operator holds order 0 only (:mod:`layersim.ingredients.diffuse`); the walk draws
cosine-distributed directions.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..ingredients.diffuse import diffuse_operator
from ..kernels import walk
from .base import Layer, LayerKind, LayerPlan, WalkBoundary
from .fields import Field, real
from .registry import register

__all__ = ["Diffuse", "DiffuseKind"]


@dataclass(frozen=True)
class Diffuse(Layer):
    """Opaque Lambertian reflector with reflectance ``albedo``."""

    kind = "diffuse"
    albedo: float = 0.0

    @property
    def opaque(self) -> bool:
        return True


class DiffuseKind(LayerKind):
    name = "diffuse"
    record = Diffuse
    fields = (Field("albedo", "Lambertian reflectance", parse=real(lo=0.0, hi=1.0),
                    required=True, per_channel=True, fit=True),)

    def build(self, ctx, values, raw, defaults) -> list:
        return [Diffuse(albedo=a) for a in values["albedo"]]

    def to_raw(self, per_channel) -> dict:
        return {"kind": self.name, "albedo": self.channel_value(per_channel, lambda x: x.albedo)}

    def describe(self, per_channel) -> str:
        return f"diffuse albedo={self.values(per_channel, lambda x: f'{x.albedo:g}')}"

    def survey(self, scene, i, survey) -> None:
        survey.layers.append(LayerPlan(i, self.name, "diffuse", "order 0 only"))

    def operator(self, job):
        return diffuse_operator(job.grid, job.layer.albedo, job.eta_above)

    def walk_boundary(self, scene, i) -> WalkBoundary:
        floats = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, scene.layers[i].albedo, 0.0, 0.0, 0.0]
        return WalkBoundary((walk.DIFFUSE, 0, 0), tuple(floats))


register(DiffuseKind())
