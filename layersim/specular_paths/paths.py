"""Enumeration of the specular paths of a chain (:mod:`.stack`) and their energies.

Reflection and refraction at a flat interface keep the horizontal wave vector
``p = n sin(theta) (cos phi, sin phi)`` of the propagation direction, so that a beam entering a
chain of flat faces and clear slabs splits into *specular paths*: sequences of events
(reflect or transmit at a face, cross a slab) that all share ``p`` and leave through the top
or the bottom. A path's energy at ``p`` is the product of its events' energies
(:class:`.energies.FaceEnergies` at the cosine of the arriving gap, ``mu_g = sqrt(1 - |p|^2 /
n_g^2)``, and ``exp(-tau / mu_g)`` per slab crossing); a path through a gap where
``|p| >= n_g`` (beyond a critical angle) carries nothing.

The tree of paths is walked depth first and a branch is cut where its energy falls below
:data:`PRUNE` of the incident power at every probe direction; what the cut branches carry is
summed and reported (:attr:`PathSet.pruned`), never lumped into the kept paths. Each cut
branch is kept as a *frontier prefix* (:attr:`PathSet.frontier`): its steps up to the cut,
from which :mod:`.continuation` carries its light on (a branch's central energy bounds what it
carries only at the probes' exact wave vectors: a slope deviation beyond a critical angle
traps light whose energy stays near 1 per bounce while the central energy falls as ``R^k``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InfeasibleError
from .energies import FaceEnergies
from .stack import Face

__all__ = ["Path", "PathSet", "Events", "enumerate_paths", "PRUNE", "probe_wave_vectors"]

#: A branch whose energy is below this fraction of the incident power at every probe is cut.
PRUNE = 1e-7
#: Longest path kept (steps); a branch cut here counts as pruned.
MAX_STEPS = 400
#: Most branches weighed per side: where faces reflect nearly all of the light back and forth
#: (near a critical angle), the paths above :data:`PRUNE` multiply with every bounce, and the
#: stack is refused rather than enumerated for hours (a path's bins cost a quadrature each).
MAX_BRANCHES = 10_000
#: Most paths kept per side (each gets its lobe's shape table and, per incident direction, a
#: quadrature): a glass pane keeps 34, a smooth coat over gold 28.
MAX_PATHS = 1_000


@dataclass(frozen=True)
class Path:
    """One specular path: ``steps`` are ``(element, down, what)`` with ``what`` one of
    ``"R"`` (reflect), ``"T"`` (transmit), ``"S"`` (cross a slab), ``down`` the direction of
    travel as the step's element is met; it enters at the top (``start_top``) or bottom and
    leaves at the top (``exit_top``) or bottom. ``gaps[s]`` is the gap in which step ``s``
    arrives; the path leaves from ``gaps[-1]``."""

    steps: tuple
    gaps: tuple
    start_top: bool
    exit_top: bool

    def rough_steps(self, chain) -> list:
        """Indices of the steps that are events at near-specular faces, in order."""
        return [s for s, (e, _, what) in enumerate(self.steps)
                if what != "S" and not chain.elements[e].smooth]

    def rough(self, chain) -> list:
        """``(face, what, gap_in, gap_out)`` of the events at near-specular faces, in order."""
        return [(chain.elements[self.steps[s][0]], self.steps[s][2], self.gaps[s],
                 self.gaps[s + 1]) for s in self.rough_steps(chain)]


@dataclass
class PathSet:
    """The paths kept for light entering at the top or bottom, the central energy of the cut
    branches (at the probes' wave vectors), the largest over the probe directions, per channel
    (C,), and the cut branches themselves: ``frontier`` holds ``(prefix, down)`` pairs, the
    prefix a :class:`Path` whose last gap is where the branch was cut (``exit_top`` unused,
    False) and ``down`` its direction of travel there."""

    paths: list
    pruned: np.ndarray
    frontier: list


class Events:
    """Event energies of a chain at wave vectors ``p`` (Q, 2), computed once per (element,
    direction)."""

    def __init__(self, chain, faces: dict, p: np.ndarray):
        self.chain, self.faces = chain, faces
        self.p = np.asarray(p, float).reshape(-1, 2)
        p2 = np.sum(self.p ** 2, axis=1)
        n = np.asarray(chain.n)[:, None]
        self.open = p2[None, :] < n ** 2                   # gap g propagates at p
        self.mu = np.sqrt(np.clip(1.0 - p2[None, :] / n ** 2, 1e-12, 1.0))
        self._memo: dict = {}

    def step(self, e: int, down: bool, what: str, gap: int) -> np.ndarray:
        """Energy (Q, C) of one step arriving in ``gap``."""
        key = (e, down, what)
        if key not in self._memo:
            el = self.chain.elements[e]
            mu = self.mu[gap]
            if isinstance(el, Face):
                R, T = self.faces[e](down, self.p, mu)
                self._memo[(e, down, "R")] = R * self.open[gap][:, None]
                nxt = gap + 1 if down else gap - 1
                self._memo[(e, down, "T")] = T * (self.open[gap] & self.open[nxt])[:, None]
            else:
                self._memo[key] = np.exp(-np.asarray(el)[None, :] / mu[:, None]) \
                    * self.open[gap][:, None]
        return self._memo[key]

    def energy(self, path: Path, steps=None) -> np.ndarray:
        """Energy (Q, C) of ``path`` (of its ``steps`` indices only, if given)."""
        out = np.ones((self.p.shape[0], self.chain.channels))
        for s in (range(len(path.steps)) if steps is None else steps):
            e, down, what = path.steps[s]
            out = out * self.step(e, down, what, path.gaps[s])
        return out


    def energy_reversed(self, path: Path) -> np.ndarray:
        """Energy (Q, C) of ``path`` travelled backwards (the path that
        :func:`enumerate_paths` finds from its exit): each transmission met from the other
        side, reflections and slab crossings as they are."""
        out = np.ones((self.p.shape[0], self.chain.channels))
        for s, (e, down, what) in enumerate(path.steps):
            if what == "T":
                out = out * self.step(e, not down, "T", path.gaps[s + 1])
            else:
                out = out * self.step(e, down, what, path.gaps[s])
        return out


def face_energies(chain) -> dict:
    """A :class:`FaceEnergies` per face element of ``chain``."""
    return {e: FaceEnergies(el) for e, el in enumerate(chain.elements) if isinstance(el, Face)}


def probe_wave_vectors(n_start: float) -> np.ndarray:
    """Wave vectors (Q, 2) at which branches are weighed: incidence 0-85 degrees in steps of
    5, at azimuths 0, 45 and 90 degrees (anisotropic faces depend on the azimuth)."""
    th = np.radians(np.arange(0.0, 86.0, 5.0))
    ph = np.radians([0.0, 45.0, 90.0])
    s = n_start * np.sin(th)
    return np.stack([np.outer(s, np.cos(ph)).ravel(), np.outer(s, np.sin(ph)).ravel()], axis=1)


def enumerate_paths(chain, faces: dict, start_top: bool, prune: float = PRUNE) -> PathSet:
    """The specular paths of ``chain`` entering at the top (``start_top``) or the bottom,
    depth first, cut below ``prune`` (:data:`PRUNE`) at every probe of
    :func:`probe_wave_vectors`."""
    K = len(chain.elements)
    gap0 = 0 if start_top else K
    ev = Events(chain, faces, probe_wave_vectors(chain.n[gap0]))
    pruned = np.zeros((ev.p.shape[0], chain.channels))
    paths: list = []
    frontier: list = []
    one = np.ones((ev.p.shape[0], chain.channels))
    stack = [((), (gap0,), start_top, one)]
    weighed = 0
    while stack:
        steps, gaps, down, w = stack.pop()
        weighed += 1
        if weighed > MAX_BRANCHES or len(paths) > MAX_PATHS:
            raise InfeasibleError(
                f"specular paths: light entering at the {'top' if start_top else 'bottom'} "
                f"splits into more than {MAX_PATHS} paths or {MAX_BRANCHES} branches above "
                f"{prune:g} of the incident power (faces that reflect nearly all of it back "
                "and forth, e.g. near a critical angle); use layersim.montecarlo for this "
                "stack")
        g = gaps[-1]
        if (down and g == K) or (not down and g == 0):
            paths.append(Path(steps, gaps, start_top, not down))
            continue
        e = g if down else g - 1
        el = chain.elements[e]
        options = [("S", down, g + 1 if down else g - 1)] if not isinstance(el, Face) else \
            [("R", not down, g), ("T", down, g + 1 if down else g - 1)]
        for what, nd, ng in options:
            w2 = w * ev.step(e, down, what, g)
            if not np.any(w2 > 0.0):
                continue
            if w2.max() < prune or len(steps) >= MAX_STEPS:
                pruned += w2
                frontier.append((Path(steps + ((e, down, what),), gaps + (ng,), start_top,
                                      False), nd))
                continue
            stack.append((steps + ((e, down, what),), gaps + (ng,), nd, w2))
    return PathSet(paths, pruned.max(axis=0), frontier)
