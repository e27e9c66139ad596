"""The stacks Belcour's statistical model represents, read from a :class:`~layersim.Scene`.

Bati et al. 2021 (sec. 3, "Hypothesis") restrict the model to GGX interfaces (dielectric or a
conductor base) with non-scattering, Beer-Lambert absorbing media between them. Anything else
is refused with an error naming the layer and the field.
"""

from __future__ import annotations

from ..errors import SceneError
from ..scene import Conductor, Dielectric, Medium, Scene, as_scene
from .atomic import Absorber, Interface


class UnsupportedStack(SceneError):
    """A scene that the statistical model does not represent."""


def _layer(scene: Scene, i: int, layer, source):
    def refuse(fld, why):
        return UnsupportedStack(why + " (Belcour's statistical model: GGX interfaces and "
                                "non-scattering absorbing media only)", layer=i,
                                kind=layer.kind, field=fld, source=source)
    if isinstance(layer, Medium):
        if layer.albedo > 0.0:
            raise refuse("albedo", f"a scattering medium (albedo {layer.albedo:g}) is not "
                                   "represented; use albedo = 0")
        return Absorber(layer.tau)
    if isinstance(layer, (Dielectric, Conductor)):
        if layer.distribution != "ggx":
            raise refuse("distribution", f"'{layer.distribution}' is not represented; use "
                                         "distribution = \"ggx\"")
        if layer.anisotropic:
            raise refuse("roughness", "anisotropic roughness is not represented")
        if layer.alpha_u > 1.0:
            raise refuse("roughness", f"{layer.alpha_u:g} is beyond the FGD table (<= 1)")
        return Interface(complex(layer.ior), layer.alpha_u)
    raise refuse("kind", f"a {layer.kind} layer is not represented")


def statistical_stacks(scene) -> tuple[tuple, ...]:
    """Per channel, the layers of ``scene`` as :class:`Interface` / :class:`Absorber`.

    Raises
    ------
    UnsupportedStack
        Naming the first layer and field the model does not represent.
    """
    scene = as_scene(scene, "layersim.statistical")
    return tuple(tuple(_layer(scene, i, layer, scene.source) for i, layer in enumerate(layers))
                 for layers in scene.stacks)
