"""The light of the walked branches of the path tree (:func:`.frontier.split`: the
enumeration's cut branches and, at one incidence, the branches whose central energy there is
low), carried to its exit by a walk over the chain's faces.

A slope deviation at a near-specular event can turn part of a lobe beyond a critical angle of a
gap: that light is trapped by total internal reflection (``F = 1`` at every face), keeps an
energy near 1 per bounce and leaves after many bounces near grazing, inside branches whose
central energy (at the exact wave vector) is tiny. Every walked branch's continuations are
disjoint from the kept paths (the tree's subtrees), so their light adds to the kept paths'
without double counting. At one incident wave vector ``p_i`` each walked prefix is traced exactly
(:func:`.trace.trace_path`) to its states in the chain (wave
vector, gap, direction, weight per channel), and each state walks on (:func:`walk`): at a
near-specular face a visible microfacet normal is drawn (Heitz 2014, sec. 3;
:func:`layersim.kernels.lobe.sample_reflection`), reflection or refraction chosen by that
facet's Fresnel reflectance (conductors: reflection, weighted by it) and the weight multiplied
by ``G1(wo, m)`` (the microfacet BSDF of Walter et al. 2007, eq. 20-21, with separable
shadowing, over the visible-normal density); at a smooth face reflection or transmission by the
face's Fresnel energies; across a slab ``exp(-tau / mu)``. A state below :data:`ROULETTE` of
the incident power per node plays Russian roulette (unbiased). The seeds are fixed: the result
is deterministic. The estimate is unbiased; its standard error per bin is
:func:`standard_error` (docs/method.md, "Specular paths", gives measured values).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..kernels.fresnel import fresnel
from ..kernels.lobe import refraction, sample_reflection
from ..kernels.pointwise import smith_g1
from .frontier import split
from .stack import Face
from .trace import trace_path

__all__ = ["Exits", "continue_frontier", "walk", "standard_error", "WALKERS", "MIN_NODES",
           "nodes_per_prefix", "ROULETTE", "MAX_EVENTS"]

#: Walkers per incident direction, shared among the walked prefixes: the trapped light they
#: carry is compared with walks of 1e7 paths, of which it holds a few percent, so the
#: continuation needs well over 1e5 walkers in it to stay below their noise (a GGX pane of eta 1.3
#: at 70 degrees: 65 % of the bins within 3 sigma at 2^17 walkers, 85 % at 2^20).
WALKERS = 2 ** 20
#: Fewest Sobol nodes per walked prefix.
MIN_NODES = 2 ** 12
#: A walker whose largest channel weight (share of the incident power per node) is below this
#: survives with probability ``weight / ROULETTE`` and then carries ``ROULETTE``.
ROULETTE = 1e-3
#: Events after which a walker still inside the chain is dropped (counted in ``Exits.lost``).
MAX_EVENTS = 20000


@dataclass
class Exits:
    """Walkers that left the chain: wave vectors ``p`` (N, 2), the side (``top`` (N,) bool)
    and energies ``w`` (N, C) as shares of the incident power (summed: the energy); ``lost``
    the energy (C,) of walkers dropped after :data:`MAX_EVENTS`."""

    p: np.ndarray
    top: np.ndarray
    w: np.ndarray
    lost: np.ndarray


class _Prefix:
    """A frontier prefix in the form :func:`.trace.trace_path` reads."""

    def __init__(self, chain, path):
        self.path = path
        self.steps = path.rough_steps(chain)


def _mu(p: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Cosines (N,) of wave vectors ``p`` (N, 2) in gaps of index ``n`` (N,)."""
    return np.sqrt(np.clip(1.0 - np.sum(p ** 2, axis=1) / n ** 2, 0.0, 1.0))


def _to_face(w: np.ndarray, rotation: float, sign: float = 1.0) -> np.ndarray:
    """Rotate directions (N, 3) into a face's frame (``sign`` -1: back)."""
    c, s = math.cos(rotation), sign * math.sin(rotation)
    return np.stack([c * w[:, 0] + s * w[:, 1], -s * w[:, 0] + c * w[:, 1], w[:, 2]], axis=1)


def rough_event(face: Face, p, na, nb, down: bool, u):
    """One walker event at a near-specular face met from above (``down``) or below by wave
    vectors ``p`` (N, 2) from a gap of index ``na`` into one of ``nb``, uniforms ``u`` (N, 4).
    Returns the new wave vectors (N, 2), whether each reflected (N,) and the weight factors
    (N, C)."""
    wi = np.concatenate([-p / na, _mu(p, np.full(len(p), na))[:, None]], axis=1)
    wi = _to_face(wi, face.rotation)
    r = sample_reflection(wi, u[:, :3], face.alpha_u, face.alpha_v, face.distribution)
    m = wi + r
    m /= np.linalg.norm(m, axis=1, keepdims=True)
    c = np.sum(wi * m, axis=1)
    g1 = lambda w, side: smith_g1(w, face.alpha_u, face.alpha_v, face.distribution) \
        * (side * w[:, 2] > 0)
    eta = [complex(e) for e in face.eta]
    if face.conductor:
        F = np.stack([fresnel(c, e.real, e.imag) for e in eta], axis=1)
        return p_of(r, na, face.rotation), np.ones(len(p), bool), F * g1(r, 1.0)[:, None]
    er = eta[0].real if down else 1.0 / eta[0].real
    refl = u[:, 3] < fresnel(c, er)
    t = refraction(wi, m, er)
    wo = np.where(refl[:, None], r, t)
    factor = np.where(refl, g1(r, 1.0), g1(t, -1.0))
    p_new = p_of(wo, np.where(refl, na, nb), face.rotation)
    return p_new, refl, np.repeat(factor[:, None], len(eta), axis=1)


def p_of(wo: np.ndarray, n, rotation: float) -> np.ndarray:
    """Wave vectors (N, 2) of propagation directions ``wo`` (N, 3) in a face's frame, in gaps
    of index ``n``."""
    return np.asarray(n, float).reshape(-1, 1) * _to_face(wo, rotation, -1.0)[:, :2]


def smooth_event(R: np.ndarray, T: np.ndarray, u: np.ndarray):
    """Reflect (with probability ``mean R / mean (R + T)``) or transmit, energies ``R``, ``T``
    (N, C); returns whether each reflected (N,) and the weight factors (N, C)."""
    r, t = R.mean(axis=1), T.mean(axis=1)
    P = np.divide(r, r + t, out=np.ones_like(r), where=r + t > 0)
    refl = u < P
    factor = np.where(refl[:, None], R / np.maximum(P, 1e-300)[:, None],
                      T / np.maximum(1.0 - P, 1e-300)[:, None])
    return refl, factor


def _event(model, e: int, down: bool, p, gap, w, u):
    """Walkers (wave vectors ``p`` (N, 2), gaps (N,), weights (N, C)) meeting element ``e``
    travelling down (``down``) or up; returns their new ``p``, gaps, directions (N,) and
    weights."""
    chain = model.chain
    el = chain.elements[e]
    step = 1 if down else -1
    mu = _mu(p, np.full(len(p), chain.n[gap[0]]))
    if not isinstance(el, Face):
        att = np.exp(-np.asarray(el)[None, :] / np.maximum(mu, 1e-12)[:, None])
        return p, gap + step, np.full(len(p), down), w * att
    if el.smooth:
        R, T = model.faces[e](down, p, mu)
        refl, factor = smooth_event(R, T, u[:, 3])
    else:
        p, refl, factor = rough_event(el, p, chain.n[gap[0]], chain.n[gap[0] + step], down, u)
    return p, np.where(refl, gap, gap + step), np.where(refl, not down, down), w * factor


def _roulette(w: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Weights (N, C) after Russian roulette of those below :data:`ROULETTE` (uniforms ``u``
    (N,)): a survivor's weight is divided by its survival probability; the others are 0."""
    top = w.max(axis=1)
    q = np.where(top < ROULETTE, top / ROULETTE, 1.0)
    alive = u < q
    return np.where(alive[:, None], w / np.maximum(q, 1e-300)[:, None], 0.0)


def walk(model, p, gap, down, w, rng) -> Exits:
    """Walk states (wave vectors ``p`` (N, 2), gaps (N,), directions ``down`` (N,), weights
    (N, C)) through the chain of ``model`` until they leave; ``rng`` a NumPy generator."""
    K = len(model.chain.elements)
    gap, down = np.asarray(gap, int), np.asarray(down, bool)
    out = {"p": [], "top": [], "w": []}
    for _ in range(MAX_EVENTS):
        w = _roulette(w, rng.random(len(w)))
        live = w.max(axis=1, initial=0.0) > 0
        left = live & ((down & (gap == K)) | (~down & (gap == 0)))
        out["p"].append(p[left])
        out["top"].append(~down[left])
        out["w"].append(w[left])
        stay = live & ~left
        p, gap, down, w = p[stay], gap[stay], down[stay], w[stay]
        if not len(p):
            break
        u = rng.random((len(p), 4))
        elem = np.where(down, gap, gap - 1)
        for e, d in {(int(a), bool(b)) for a, b in zip(elem, down)}:
            s = np.flatnonzero((elem == e) & (down == d))
            p[s], gap[s], down[s], w[s] = _event(model, e, d, p[s], gap[s], w[s], u[s])
    return Exits(np.concatenate(out["p"]), np.concatenate(out["top"]),
                 np.concatenate(out["w"]), w.sum(axis=0))


def frontier_states(model, prefixes: list, p_i: np.ndarray, nodes: int, seed: int):
    """The states (``p`` (N, 2), gaps (N,), ``down`` (N,), weights (N, C)) at the ends of the
    walked ``prefixes`` (``(Path, down)``, :func:`.frontier.split`) of light entering with wave
    vector ``p_i`` (2,), ``nodes`` traced nodes per prefix (those of weight 0 left out)."""
    chain = model.chain
    parts = [(np.zeros((0, 2)), np.zeros(0, int), np.zeros(0, bool),
              np.zeros((0, chain.channels)))]
    for k, (path, d) in enumerate(prefixes):
        po, w = trace_path(model, _Prefix(chain, path), p_i, nodes, seed=seed + k)
        keep = w.max(axis=1) > 0
        n = int(keep.sum())
        parts.append((po[keep], np.full(n, path.gaps[-1]), np.full(n, d), w[keep]))
    return tuple(np.concatenate(x) for x in zip(*parts))


def nodes_per_prefix(count: int) -> int:
    """Sobol nodes (a power of 2) per walked prefix: :data:`WALKERS` shared among ``count``
    prefixes, at least :data:`MIN_NODES` each."""
    return max(MIN_NODES, 1 << max(0, (WALKERS // max(count, 1)).bit_length() - 1))


def continue_frontier(model, top: bool, p_i: np.ndarray, prefixes: list | None = None,
                      seed: int = 1) -> Exits:
    """The exits of the light of every walked prefix for light entering at the top (``top``)
    or bottom with wave vector ``p_i`` (2,): ``prefixes`` (default: :func:`.frontier.split`'s
    at ``p_i``) traced on :func:`nodes_per_prefix` nodes each (:func:`frontier_states`),
    walked on (:func:`walk`); weights as shares of the incident power. Deterministic
    (``seed``)."""
    p_i = np.asarray(p_i, float)
    if prefixes is None:
        prefixes = split(model, top, p_i)[1]
    nodes = nodes_per_prefix(len(prefixes))
    p, gap, down, w = frontier_states(model, prefixes, p_i, nodes, seed)
    ex = walk(model, p, gap, down, w, np.random.default_rng(seed))
    return Exits(ex.p, ex.top, ex.w / nodes, ex.lost / nodes)


def exit_bins(model, ex: Exits, mu_edges, phi_edges, square: bool = False) -> dict:
    """Energy (n_mu, n_phi, C) per bin of each side (``"top"``, ``"bottom"``) of the exits
    ``ex``; with ``square`` the sums of squared energies instead (:func:`standard_error`)."""
    out = {}
    for side, is_top in (("top", True), ("bottom", False)):
        s = ex.top == is_top
        wo = model.exit_direction(ex.p[s], is_top)
        mu = np.abs(wo[:, 2])
        phi = np.arctan2(wo[:, 1] + 0.0, wo[:, 0] + 0.0) % (2 * np.pi)
        w = ex.w[s] ** 2 if square else ex.w[s]
        out[side] = np.stack([np.histogram2d(mu, phi, bins=[mu_edges, phi_edges],
                                             weights=w[:, c])[0]
                              for c in range(ex.w.shape[1])], axis=-1)
    return out


def standard_error(model, ex: Exits, mu_edges, phi_edges) -> dict:
    """Standard error (n_mu, n_phi, C) per bin of each side of the energies of
    :func:`exit_bins`, treating the walkers as independent: ``sqrt(sum w^2)`` (an upper
    bound: the mean is not subtracted)."""
    return {k: np.sqrt(v) for k, v in exit_bins(model, ex, mu_edges, phi_edges, True).items()}
