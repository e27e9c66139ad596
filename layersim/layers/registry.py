"""The registry of layer kinds: scene-file name -> :class:`~layersim.layers.base.LayerKind`.

A kind module registers its kind once (:func:`register`); the scene parser, the planner, the
solver, the walk set-up and the statistical model look kinds up here (:func:`kind_of`,
:func:`kind_named`). A kind defined outside the package registers the same way.
"""

from __future__ import annotations

from .base import LayerKind

__all__ = ["KINDS", "register", "kind_named", "kind_of", "names"]

#: Every registered kind, by scene-file name.
KINDS: dict[str, LayerKind] = {}


def register(kind: LayerKind) -> LayerKind:
    """Register ``kind`` (an instance) under ``kind.name`` and return it; a name registered
    twice replaces the earlier kind only if it is the same class."""
    if not isinstance(kind, LayerKind):
        raise TypeError(f"register() takes a LayerKind instance, got {type(kind).__name__}")
    old = KINDS.get(kind.name)
    if old is not None and type(old) is not type(kind):
        raise ValueError(f"a layer kind named {kind.name!r} is already registered "
                         f"({type(old).__name__})")
    if kind.record.kind != kind.name:
        raise ValueError(f"{type(kind).__name__}: its record's kind is {kind.record.kind!r}, "
                         f"not {kind.name!r}")
    KINDS[kind.name] = kind
    return kind


def kind_named(name: str) -> LayerKind | None:
    """The kind registered as ``name``, or None."""
    return KINDS.get(name)


def kind_of(layer) -> LayerKind:
    """The kind of a layer record."""
    return KINDS[layer.kind]


def names() -> list[str]:
    """The registered kinds' names, sorted."""
    return sorted(KINDS)
