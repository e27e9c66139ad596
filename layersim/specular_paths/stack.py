"""The stacks that specular paths solve, as a chain of flat elements.

A stack of flat interfaces (smooth, or near-specular: both roughnesses at most
:data:`~layersim.solved.lobe.NEAR_SPECULAR_ALPHA`) and non-scattering media (albedo 0) is a
list of elements, top to bottom: *faces* (interfaces) and *slabs* (media). Between elements
lie *gaps*: gap ``g`` is above element ``g``; gap 0 is the medium above the stack and gap
``K`` the one below it. Each gap has one real absolute index; a slab attenuates a crossing
at cosine ``mu`` by ``exp(-tau / mu)`` per channel (Beer-Lambert; ``tau`` along the normal,
``docs/conventions.md``). Where a dielectric's index differs per channel (dispersion), the
channels are split into groups sharing every gap's index (:func:`channel_groups`), each with
its own chain: the horizontal wave vector a path keeps is one per group, and the paths of
different channels never interact.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import InfeasibleError
from ..layers.registry import kind_of
from ..solved.lobe import NEAR_SPECULAR_ALPHA

__all__ = ["Face", "Chain", "chain_of", "channel_groups", "why_not"]


@dataclass(frozen=True)
class Face:
    """An interface between gap ``g`` (above, index ``n_above``) and gap ``g + 1``.

    ``eta`` (per channel) is the index below relative to the one above, complex ``eta + i k``
    for a conductor (``k > 0``: it only reflects). ``alpha_u``, ``alpha_v``, ``rotation``
    (radians) and ``distribution`` as :class:`layersim.layers.interface.Interface`."""

    eta: tuple
    alpha_u: float
    alpha_v: float
    distribution: str
    rotation: float

    @property
    def smooth(self) -> bool:
        return self.alpha_u == 0.0 and self.alpha_v == 0.0

    @property
    def conductor(self) -> bool:
        return any(complex(e).imag > 0.0 for e in self.eta)


@dataclass(frozen=True)
class Chain:
    """The elements of a stack (:class:`Face` or a slab's per-channel ``tau`` tuple), the
    absolute index of every gap (``len(elements) + 1`` values) and the channel count."""

    elements: tuple
    n: tuple
    channels: int

    @property
    def opaque(self) -> bool:
        return any(isinstance(e, Face) and e.conductor for e in self.elements)

    def rough_faces(self) -> list:
        return [e for e in self.elements if isinstance(e, Face) and not e.smooth]


def why_not(scene) -> str | None:
    """Why ``scene`` is not a stack of flat interfaces and clear media (one line), or None
    if it is one (all of its interfaces smooth or near-specular; an all-smooth stack is a sum
    of delta paths, which the plan takes where the Fourier basis cannot: a smooth dielectric
    inside the stack)."""
    mono = scene.channel(0)
    for i, layer in enumerate(mono.layers):
        if kind_of(layer).walk_role == "slab":          # a medium: (tau, albedo, g)
            if any(kind_of(x).walk_slab(x)[1] > 0.0 and kind_of(x).walk_slab(x)[0] > 0.0
                   for x in (scene.channel(c).layers[i] for c in range(scene.channels))):
                return f"layer {i} (medium) scatters (albedo > 0)"
            continue
        if not layer.is_interface:
            return f"layer {i} ({layer.kind}) is not a flat interface"
        if layer.ndf is not None or layer.film is not None:
            return f"layer {i} ({layer.kind}) has a tabulated NDF or a film"
        if max(layer.alpha_u, layer.alpha_v) > NEAR_SPECULAR_ALPHA:
            return (f"layer {i} ({layer.kind}) is rougher than {NEAR_SPECULAR_ALPHA:g} on an "
                    "axis")
        if layer.energy_compensation != "none" or layer.shadowing != "separable":
            return f"layer {i} ({layer.kind}) has energy compensation or correlated shadowing"
    return None


def chain_of(scene, channels=None) -> Chain:
    """The :class:`Chain` of ``scene`` (a stack for which :func:`why_not` is None) for the
    channel indices ``channels`` (default all), which must share every gap's index
    (:func:`channel_groups`)."""
    why = why_not(scene)
    if why is not None:
        raise InfeasibleError(f"scene {scene.name!r} is not solved by specular paths: {why}")
    channels = tuple(range(scene.channels)) if channels is None else tuple(channels)
    chains = {c: _chain(scene, (c,)) for c in channels}
    if len({chains[c].n for c in channels}) > 1:
        raise InfeasibleError(f"scene {scene.name!r}: channels {channels} have different "
                              "indices (one chain per group of channel_groups)")
    return _chain(scene, channels)


def channel_groups(scene) -> list:
    """The channels of ``scene`` (a stack for which :func:`why_not` is None) grouped by their
    gaps' indices, in order of first appearance: one group of all channels unless a
    dielectric's index differs per channel."""
    groups: dict = {}
    for c in range(scene.channels):
        groups.setdefault(_chain(scene, (c,)).n, []).append(c)
    return [tuple(g) for g in groups.values()]


def _chain(scene, channels: tuple) -> Chain:
    """The chain of the channels ``channels``, with the gap indices of the first of them."""
    monos = [scene.channel(c) for c in channels]
    elements, n = [], [scene.top_ior]
    for i, layer in enumerate(monos[0].layers):
        if not layer.is_interface:
            elements.append(tuple(float(m.layers[i].tau) for m in monos))
            n.append(n[-1])
            continue
        eta = tuple(complex(m.relative_ior(i)) for m in monos)
        elements.append(Face(eta, float(layer.alpha_u), float(layer.alpha_v),
                             layer.distribution, float(layer.rotation)))
        n.append(n[-1] * eta[0].real if eta[0].imag == 0.0 else n[-1])
        if eta[0].imag > 0.0:
            break
    return Chain(tuple(elements), tuple(float(x) for x in n), len(channels))
