"""Model-based subtraction: the unknown part of a solved stack found by fitting a template of the
whole stack (its known layers fixed, the unknown one's fields free) to the stack by exact
transport, then solved alone over the whole hemisphere.

The plain subtraction (:func:`layersim.subtract`, Zeltner & Jakob 2018 eq. (13)-(16)) inverts
the adding equations direction by direction: below a coating it cannot see the directions beyond
the coating's critical angle, and the light that the base returns through them biases what it
recovers elsewhere (docs/method.md, "Subtracting equations"). A base that belongs to a model
family (a rough conductor, a medium over a diffuse base) is determined by a few parameters,
which the reflection of the stack pins down; once they are fitted, the base is solved in every
direction, hidden ones included.

Which layers are unknown: with ``side="top"`` (the known layers on top, as for
:func:`layersim.subtract`) the known part is the template's layers above the first layer with a
free value, and the unknown part that layer and every layer below it; with ``side="bottom"``
the known part is the layers below the last layer with a free value. Fixed layers between free
ones belong to the unknown part.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import OperatorError
from ..scene import Scene
from ..solved.bsdf import BSDF
from ..solver import add, solve
from ..stacking.subtract import relative_error, subtract
from .optimize import fit
from .result import FitResult
from .template import Template

__all__ = ["ModelSubtraction", "subtract_model", "split_layers"]

#: Largest relative L2 distance (energy basis) of a given known layer from the template's
#: fixed layers solved on the same discretisation: above rounding and the truncation of
#: coupled operators (1e-7 per ordinate pair), below any change of a physical value that
#: matters.
KNOWN_TOLERANCE = 1e-5


@dataclass
class ModelSubtraction:
    """The result of :func:`subtract_model`.

    Attributes
    ----------
    base : BSDF
        The unknown part, solved alone with the fitted values on the stack's discretisation,
        over the whole hemisphere (its top in the medium between it and the known part).
    fit : FitResult
        The fit of the whole template to the stack (values, standard errors, residual).
    scene : Scene
        The unknown part's scene with the fitted values.
    known : BSDF
        The known part as the template fixes it, solved on the stack's discretisation.
    layers : tuple of int
        The template's layers (indices) that make up the unknown part.
    side : {"top", "bottom"}
        Where the known part sits.
    residual : float
        Relative L2 distance (energy basis, all orders and blocks, worst channel) of the known
        part added to ``base`` from the stack: the model's re-adding residual, comparable with
        the plain subtraction's ``info["subtract"]["residual_filled"]``.
    plain : BSDF or None
        The plain subtraction of the same known part, when asked for (for comparison).
    """

    base: BSDF
    fit: FitResult
    scene: Scene
    known: BSDF
    layers: tuple
    side: str
    residual: float
    plain: BSDF | None = None


def _free_layers(template: Template) -> list:
    return sorted({p.path[1] for p in template.params})


def split_layers(template: Template, side: str) -> tuple:
    """``(known, unknown)``: the indices of the template's layers of the known part and of the
    unknown part (module docstring).

    Raises
    ------
    ValueError
        A side that is not "top" or "bottom", or a template without fixed layers on ``side``.
    """
    if side not in ("top", "bottom"):
        raise ValueError(f"side must be 'top' or 'bottom' (where the known layers are), got "
                         f"{side!r}")
    count = len(template.data.get("layer", ()))
    free = _free_layers(template)
    if side == "top":
        known, unknown = tuple(range(free[0])), tuple(range(free[0], count))
    else:
        known, unknown = tuple(range(free[-1] + 1, count)), tuple(range(free[-1] + 1))
    if not known:
        where = "above its first" if side == "top" else "below its last"
        raise ValueError(f"model subtraction: the template has no fixed layer {where} layer "
                         f"with a free value (layer {free[0] if side == 'top' else free[-1]}): "
                         f"with side '{side}' the known layers are the fixed ones {where} "
                         "free layer")
    return known, unknown


def _part(template: Template, x, indices: tuple, top_ior: float) -> Scene:
    """The scene of the template's layers ``indices`` at the values ``x``, below a medium of
    index ``top_ior``, with the template's other ``[stack]`` settings."""
    data = template.as_dict(x)
    stack = {k: v for k, v in data.get("stack", {}).items() if k not in ("top_ior", "name")}
    name = f"{template.source or 'template'} layers {indices[0]}-{indices[-1]}"
    return Scene.from_dict({"stack": stack | {"top_ior": top_ior, "name": name},
                            "layer": [data["layer"][i] for i in indices]},
                           source=template.source)


def _index_above(template: Template, x, layer: int) -> float:
    """Absolute index of the medium above ``layer`` of the template at ``x`` (one value for
    every channel)."""
    scene = template.scene(x)
    values = {round(scene.channel(c).ior_above(layer), 12) for c in range(scene.channels)}
    if len(values) != 1:
        raise ValueError(f"model subtraction: the medium above layer {layer} has a different "
                         "index per channel; the unknown part cannot be solved alone")
    return values.pop()


def _check_stack(template: Template, stack: BSDF) -> None:
    """Refuse a template that cannot be this stack: another index above it, or an opaque base
    where the stack transmits (or the reverse)."""
    scene = template.scene(template.start)
    op = stack.operators[0]
    if abs(scene.top_ior - op.eta_top) > 1e-9 * max(1.0, op.eta_top):
        raise ValueError(f"model subtraction: the template starts in a medium of index "
                         f"{scene.top_ior:g}, the stack in {op.eta_top:g}")
    if scene.opaque != stack.opaque:
        what = {True: "opaque", False: "transmissive"}
        raise ValueError(f"model subtraction: the template is {what[scene.opaque]}, the stack "
                         f"{what[stack.opaque]}")


def _fixed_index_above(template: Template, layer: int) -> float:
    """The index of the medium above the known part's first ``layer``, which no free value may
    change: the known layers' operator depends on it."""
    eta = _index_above(template, template.start, layer)
    for k, p in enumerate(template.params):
        for end in (p.lo, p.hi):
            x = template.start.copy()
            x[k] = end
            if abs(_index_above(template, x, layer) - eta) > 1e-12 * eta:
                raise ValueError(f"model subtraction: {p.name} changes the index of the medium "
                                 f"above the known layers (layer {layer}), on which they "
                                 "depend: fix it, or fit the whole stack with layersim fit")
    return eta


def _check_known(known: BSDF, mine: BSDF, indices: tuple) -> None:
    """Refuse a given known layer that is not the template's fixed layers."""
    if len(known.operators) != len(mine.operators) and len(known.operators) != 1:
        raise ValueError(f"model subtraction: KNOWN has {len(known.operators)} channel(s), the "
                         f"template {len(mine.operators)}")
    for c, op in enumerate(mine.operators):
        other = known.operators[min(c, len(known.operators) - 1)]
        try:
            dist = relative_error(other, op)
        except (ValueError, OperatorError):
            dist = np.inf
        if not dist <= KNOWN_TOLERANCE:
            raise ValueError(f"model subtraction: KNOWN differs from the template's fixed "
                             f"layers {', '.join(map(str, indices))} (relative L2 {dist:.2g} in "
                             f"channel {c}, more than {KNOWN_TOLERANCE:g}): they must be the "
                             "same layers, solved on the stack's discretisation")


def _readding_residual(stack: BSDF, known: BSDF, base: BSDF, side: str) -> float:
    again = add(known, base) if side == "top" else add(base, known)
    return max(relative_error(a, s) for a, s in zip(again.operators, stack.operators))


def subtract_model(stack, template, side: str = "top", known: BSDF | None = None,
                   plain: bool | None = None, progress: bool | None = None,
                   threads: int | None = None) -> ModelSubtraction:
    """The unknown part of ``stack`` by a fit of ``template`` (module docstring).

    Parameters
    ----------
    stack : BSDF or path
        The solved stack (or the path of a saved one, ``.lsim``); its top reflection is the
        fit's target, compared on the pairs of :func:`layersim.fit.direction_pairs`.
    template : Template, dict or path
        The whole stack with the known layers fixed and the unknown layer's fields free
        (``{ fit = [lo, hi] }``; docs/conventions.md, "Fit templates").
    side : {"top", "bottom"}
        Where the known layers are.
    known : BSDF, optional
        The known part solved on the stack's discretisation: checked against the template's
        fixed layers (relative L2 within :data:`KNOWN_TOLERANCE`).
    plain : bool, optional
        Also run the plain subtraction of the known part, for comparison (default: when
        ``known`` is given).
    progress : bool, optional
        The fit's progress bar (default: when stderr is a terminal).
    threads : int, optional
        Threads of each solve.

    Returns
    -------
    ModelSubtraction

    Raises
    ------
    SceneError, ValueError
        A bad template, no fixed layer on ``side``, a template that cannot be the stack, a
        ``known`` that is not the template's fixed layers; all before the fit.
    """
    stack = stack if isinstance(stack, BSDF) else BSDF.load(stack)
    template = template if isinstance(template, Template) else Template(template)
    known_idx, unknown_idx = split_layers(template, side)
    _check_stack(template, stack)
    mine = solve(_part(template, template.start, known_idx,
                       _fixed_index_above(template, known_idx[0])), like=stack, threads=threads)
    if known is not None:
        _check_known(known, mine, known_idx)
    result = fit(template, stack, like=stack, progress=progress, threads=threads)
    x = np.array([result.params[n] for n in template.names])
    scene = _part(template, x, unknown_idx, _index_above(template, x, unknown_idx[0]))
    base = solve(scene, like=stack, threads=threads)
    compare = known is not None if plain is None else plain
    return ModelSubtraction(
        base=base, fit=result, scene=scene, known=mine, layers=unknown_idx, side=side,
        residual=_readding_residual(stack, mine, base, side),
        plain=subtract(stack, mine, side=side) if compare else None)
