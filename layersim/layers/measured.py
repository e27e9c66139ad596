"""The measured base: an opaque surface whose isotropic BRDF is a MERL-layout table
(:mod:`layersim.layers.merl`), three channels.

It is projected numerically (cosine series; :mod:`layersim.ingredients.measured`) and sized as a
Beckmann lobe as wide as its specular peak; the walk samples it with cosine-weighted directions
(:mod:`layersim.kernels.measured`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import merl
from ..operators.energy import check_operator_energy
from ..ingredients.measured import measured_operator
from ..kernels import walk
from .base import Layer, LayerKind, LayerPlan, WalkBoundary
from .conductor import Conductor
from .fields import Field
from .registry import register

__all__ = ["Measured", "MeasuredKind"]


@dataclass(frozen=True)
class Measured(Layer):
    """Opaque base with a measured isotropic BRDF (MERL layout, :mod:`layersim.layers.merl`): channel
    ``channel`` of ``data``. ``alpha`` is the width (radians) of its specular lobe
    (:meth:`layersim.layers.merl.MERLTable.equivalent_alpha`), which sizes the plan as a Beckmann
    lobe of that roughness would."""

    kind = "measured"
    data: Any = field(default=None, compare=False)
    channel: int = 0
    alpha: float = 0.5 * math.pi

    @property
    def opaque(self) -> bool:
        return True

    @property
    def alpha_u(self) -> float:
        return self.alpha

    @property
    def alpha_v(self) -> float:
        return self.alpha

    def lobe_width(self) -> float:
        return self.alpha


@dataclass(frozen=True)
class _Channel:
    """One channel of a measured BRDF, packed after the walk's records like an NDF table."""

    data: object
    channel: int

    def packed(self, dtype):
        return self.data.packed(self.channel, dtype)


class MeasuredKind(LayerKind):
    name = "measured"
    record = Measured
    fields = (Field("file", "path of a MERL binary file (relative to the scene file)",
                    required=True),)

    def build(self, ctx, values, raw, defaults) -> list:
        value = raw["file"]
        if not isinstance(value, (str, os.PathLike)):
            raise ctx.error("file", f"must be the path of a MERL binary file, got {value!r}")
        path = Path(value)
        if not path.is_absolute() and ctx.source is not None:
            path = Path(ctx.source).parent / path
        data = merl.read_merl(path, layer=ctx.layer, kind=self.name)
        alpha = data.equivalent_alpha()
        return [Measured(data=data, channel=c, alpha=alpha) for c in range(3)]

    def describe(self, per_channel) -> str:
        layer = per_channel[0]
        return (f"measured BRDF {layer.data.source} (MERL layout, 3 channels, lobe width "
                f"{math.degrees(layer.alpha):.3g} deg"
                + (f", {layer.data.missing} unmeasured samples read as 0" if layer.data.missing
                   else "") + ")")

    def survey(self, scene, i, survey) -> None:
        layer = scene.channel(0).layers[i]
        survey.widths.append((layer.alpha, i, self.name, "measured lobe"))
        survey.layers.append(LayerPlan(
            i, self.name, "project (measured, sampled)",
            f"{layer.data.source}: MERL layout 90 x 90 x 180 (theta_h, theta_d, phi_d), lobe "
            f"width {math.degrees(layer.alpha):.3g} deg; n and md as for a Beckmann lobe of "
            "that roughness", width=layer.alpha))

    def equivalent_lobe(self, layer):
        """A conductor (an index with the Fresnel factor of a metal: its value does not change
        the series lengths much) with the lobe width as roughness."""
        return Conductor(ior=complex(1.0, 3.0), alpha_u=layer.alpha, alpha_v=layer.alpha)

    def operator(self, job):
        op = measured_operator(job.grid, job.plan.md, job.layer, job.eta_above,
                               device=job.device)
        job.notes += check_operator_energy(op, job.index, job.layer, job.plan.n)
        return op

    def walk_boundary(self, scene, i) -> WalkBoundary:
        layer = scene.layers[i]
        floats = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        return WalkBoundary((walk.MEASURED, 0, 0), floats, _Channel(layer.data, layer.channel))


register(MeasuredKind())
