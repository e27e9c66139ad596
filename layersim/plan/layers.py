"""The survey of a stack: what the solve does with each layer, and the lobes that set ``n``.

Each layer's kind plans it (:meth:`layersim.layers.LayerKind.survey`): interfaces are projected
(with coupled modes if anisotropic) or solved exactly (smooth, near-specular); media are added by
adding-doubling with the Fourier orders of their phase function; a diffuse base needs order 0
only. Index-matched interfaces and empty media are exact no-ops and are left out.
"""

from __future__ import annotations

from ..layers import brushed, kind_of, near_specular_inner
from ..layers.base import Survey
from ..operators.operator import Grid
from ..scene import Scene

__all__ = ["Survey", "survey_layers", "survey_projected", "scale_media"]


def survey_layers(scene: Scene) -> Survey:
    """The action of every layer of ``scene`` (RGB channels share it: the geometry is the
    first channel's, and a layer is left out only if it is a no-op in every channel).

    Raises
    ------
    InfeasibleError
        For a layer the solve cannot represent (e.g. a smooth dielectric interface inside the
        stack), naming it and what to change.
    """
    survey = Survey()
    for i, layer in enumerate(scene.channel(0).layers):
        kind_of(layer).survey(scene, i, survey)
    if scene.opaque:
        survey.left_out.append("transmission blocks (Ttb, Tbt) and bottom reflection: the "
                               "base is opaque")
    return survey


def survey_projected(scene: Scene, inner: str | None = None,
                     exact: bool = False) -> tuple[Survey, Scene]:
    """The survey of the scene the Fourier solve projects, and that scene: ``scene`` itself, or
    with a brushed top coat's narrow roughness raised (:func:`layersim.layers.brushed.
    projected_scene`; the survey then says so and holds the floor in ``brushed_floor``) and,
    with ``inner`` (why the exact plan is not used), near-specular inner interfaces under a
    rough one raised below a mirror (:mod:`layersim.layers.near_specular_inner`; in
    ``survey.inner_mirrors``; with ``exact``, their reflection from above is projected at their
    own roughness where it can be). A brushed coat or inner interface that cannot take its
    route adds why to ``survey.hints``."""
    projected, is_brushed, hints = brushed.projected_scene(scene)
    mirrored, inner_hints = near_specular_inner.route_layers(scene, inner is not None)
    projected = near_specular_inner.projected_scene(projected, mirrored)
    survey = survey_layers(projected)
    survey.hints += hints + inner_hints
    if is_brushed:
        brushed.annotate(survey, scene)
    if mirrored:
        near_specular_inner.annotate(survey, scene, mirrored, inner, exact)
    return survey, projected


def scale_media(scene: Scene, survey: Survey, grid: Grid) -> int:
    """Let every layer of ``survey.scaled`` decide its representation on ``grid``
    (:meth:`~layersim.layers.LayerKind.on_grid`: a medium keeps its whole phase-function series
    or is delta-M scaled, with the function the solve uses), and return the Fourier orders the
    media need.

    Raises
    ------
    InfeasibleError
        Naming the layer and field for a representation the grid cannot hold.
    """
    mono = scene.channel(0)
    for lp in survey.scaled:
        orders = kind_of(mono.layers[lp.index]).on_grid(scene, lp, grid)
        survey.media_orders = max(survey.media_orders, orders)
    return survey.media_orders
