"""The stacks Belcour's statistical model represents, read from a :class:`~layersim.Scene`.

Bati et al. 2021 (sec. 3, "Hypothesis") restrict the model to GGX interfaces (dielectric or a
conductor base) with non-scattering, Beer-Lambert absorbing media between them. Anything else
is refused with an error naming the layer and the field.
"""

from __future__ import annotations

from ..errors import SceneError
from ..layers import kind_of
from ..scene import Scene, as_scene
from .atomic import Absorber, Interface


class UnsupportedStack(SceneError):
    """A scene that the statistical model does not represent."""


def _layer(scene: Scene, i: int, layer, source):
    def refuse(fld, why):
        return UnsupportedStack(why + " (Belcour's statistical model: GGX interfaces and "
                                "non-scattering absorbing media only)", layer=i,
                                kind=layer.kind, field=fld, source=source)
    atom = kind_of(layer).statistical_atom(layer, refuse)
    if atom[0] == "absorber":
        return Absorber(*atom[1:])
    return Interface(*atom[1:])


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
