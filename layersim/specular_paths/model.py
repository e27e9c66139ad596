"""The BSDF of a chain as a sum over its specular paths (:mod:`.paths`, :mod:`.lobes`).

Per path, for light from ``wi`` (horizontal wave vector of its propagation ``p_i = -n_in
wi_h``) leaving toward ``wo`` (``p_o = n_out wo_h``):

* no near-specular event: a delta (``specular``), leaving at ``p_o = p_i``;
* one near-specular event: the exact microfacet BSDF of that face (Walter et al. 2007, eq. 20-21,
  :func:`layersim.kernels.lobe.microfacet_reflection`) between the Snell images of ``wi`` and
  ``wo`` in the gaps around it, times the smooth events' energies before it (at ``p_i``) and
  after it (at ``p_o``), times ``n_out^2 / n_b^2`` (``n_b`` the index of the gap the event
  leaves into; the density of ``p`` per ``d^2 p = n^2 mu dOmega``);
* several: ``f = E(p_bar) n_out^2 density(p_o - p_i)`` (:class:`.lobes.PathLobe`), ``E`` the
  geometric mean of the path's energy and that of the path travelled backwards (reciprocity).

Energies (``albedo``, bins) of paths with near-specular events are traced exactly along each
path (:mod:`.trace`); delta paths carry their energy at ``p_i``. The light of the branches that
enumeration cuts, and at each incidence of those whose central energy there is low (trapped by
total internal reflection after a slope deviation, among others; :mod:`.frontier`), is carried
on by the walk of :mod:`.continuation` and adds to the albedos and bins; ``eval`` and the
sampler leave out what enumeration cuts (below 1e-3 of the incident power, docs/method.md).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ..kernels.lobe import microfacet_reflection
from .binning import direction_bin, path_bins
from .continuation import continue_frontier, exit_bins
from .frontier import split
from .lobes import PathLobe
from .paths import Events, enumerate_paths, face_energies
from .trace import trace_path

__all__ = ["PathModel"]

#: Sobol nodes per path of the traced energies (:mod:`.trace`) for albedos and bin energies.
ALBEDO_NODES = 2 ** 16
BIN_NODES = 2 ** 16


def _nodes_for(share: float, most: int) -> int:
    """Sobol nodes for a path carrying ``share`` of the strongest path's energy: ``4 most``
    down to a share of 10 %, ``most`` down to 1 %, 4096 below it. A GGX lobe's heavy tail
    makes the traced energy converge slowly (a glass interface of alpha 0.02 at 50 degrees:
    1e-3 relative at 4096 nodes, 3e-5 at 65536), so the strong paths take many nodes and the
    faint ones, whose errors are then below 2e-5 of the incident power, the floor."""
    if share >= 0.1:
        return 4 * most
    return most if share >= 0.01 else min(most, 4096)


class _Entry:
    """A path with its lobe (None for a delta) and its near-specular step indices."""

    def __init__(self, chain, path):
        self.path = path
        self.rough = path.rough(chain)
        self.steps = path.rough_steps(chain)
        self.exact = len(self.rough) == 1
        # a single event's lobe serves sampling; eval uses its exact microfacet BSDF
        self.lobe = PathLobe(self.rough, chain.n) if self.rough else None
        self._n = chain.n

    @functools.cached_property
    def singles(self) -> list:
        """Each near-specular event's lobe alone (:mod:`.tails`), built when first asked."""
        return [PathLobe([r], self._n) for r in self.rough]


class PathModel:
    """The paths of ``chain`` (:class:`layersim.specular_paths.stack.Chain`) for light
    entering at the top and, if the chain transmits, at the bottom."""

    def __init__(self, chain, prune: float):
        self.chain = chain
        self.faces = face_energies(chain)
        self.sets, self.entries = {}, {}
        for top in ((True,) if chain.opaque else (True, False)):
            ps = enumerate_paths(chain, self.faces, top, prune)
            self.sets[top] = ps
            self.entries[top] = [_Entry(chain, p) for p in ps.paths]
        self._walked = {}

    def walked(self, top: bool, p_i: np.ndarray):
        """The split at ``p_i`` (2,) (:func:`.frontier.split`: the traced entries and the
        walked prefixes) and the exits of its walked branches
        (:func:`.continuation.continue_frontier`), for light entering at the top (``top``)
        or bottom. The walk is deterministic (one seed), so ``albedo`` and ``bins`` at one
        incidence share it: the latest incidence's is kept (its 2^20 exits take about 40 MB),
        and a caller of both pays one walk."""
        key = (top, np.asarray(p_i, float).tobytes())
        if key not in self._walked:
            entries, prefixes = split(self, top, p_i)
            self._walked = {key: (entries, continue_frontier(self, top, p_i, prefixes))}
        return self._walked[key]

    # ---- geometry ----------------------------------------------------------------------

    def n_side(self, top: bool) -> float:
        return self.chain.n[0] if top else self.chain.n[-1]

    def p_in(self, wi: np.ndarray) -> np.ndarray:
        """Horizontal wave vectors (Q, 2) of the propagation of light from ``wi`` (Q, 3)."""
        n = np.where(wi[:, 2] > 0, self.n_side(True), self.n_side(False))
        return -n[:, None] * wi[:, :2]

    def p_out(self, wo: np.ndarray) -> np.ndarray:
        n = np.where(wo[:, 2] > 0, self.n_side(True), self.n_side(False))
        return n[:, None] * wo[:, :2]

    def exit_direction(self, p: np.ndarray, top: bool) -> np.ndarray:
        """Unit directions (Q, 3) leaving at the top or bottom with wave vectors ``p``; rows
        beyond the horizon are (0, 0, 0)."""
        n = self.n_side(top)
        h = p / n
        z2 = 1.0 - np.sum(h ** 2, axis=1)
        ok = z2 > 0
        z = np.sqrt(np.where(ok, z2, 0.0)) * (1.0 if top else -1.0)
        return np.where(ok[:, None], np.concatenate([h, z[:, None]], axis=1), 0.0)

    # ---- evaluation --------------------------------------------------------------------

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """``f(wi, wo)`` (Q, C) in 1/sr, deltas left out."""
        out = np.zeros((wi.shape[0], self.chain.channels))
        pi, po = self.p_in(wi), self.p_out(wo)
        for top in self.entries:
            for out_top in (True, False):
                sel = ((wi[:, 2] > 0) == top) & ((wo[:, 2] > 0) == out_top) & (wi[:, 2] != 0) \
                    & (wo[:, 2] != 0)
                if sel.any():
                    out[sel] = self._eval_block(top, out_top, pi[sel], po[sel])
        return out

    def _eval_block(self, top: bool, out_top: bool, pi, po) -> np.ndarray:
        out = np.zeros((pi.shape[0], self.chain.channels))
        for x in self.entries[top]:
            if x.path.exit_top == out_top and x.rough:
                out += self.eval_path(x, pi, po)
        return out

    def eval_path(self, x: _Entry, pi: np.ndarray, po: np.ndarray) -> np.ndarray:
        """``f`` (Q, C) of the path ``x`` from wave vectors ``pi`` to ``po`` (Q, 2)."""
        if x.exact:
            ev_in = Events(self.chain, self.faces, pi)
            ev_out = Events(self.chain, self.faces, po)
            return self.single_event(x.path, x.steps[0], ev_in, ev_out, pi, po)
        return self.linearised(x, [x.lobe], pi, po)[0]

    def linearised(self, x: _Entry, lobes: list, pi: np.ndarray, po: np.ndarray) -> list:
        """``f`` (Q, C) of the path ``x`` from ``pi`` to ``po`` with each of ``lobes`` as its
        deviation's density (:class:`.lobes.PathLobe`; the path's own, or one event's alone
        for :mod:`.tails`): ``E(p_bar) n_out^2 density(p_o - p_i)``."""
        n_out = self.n_side(x.path.exit_top)
        pbar = 0.5 * (pi + po)
        ev_mid = Events(self.chain, self.faces, pbar)
        # the geometric mean with the reversed path makes f reciprocal: a rough face
        # transmits slightly differently from either side (single-scattering loss)
        energy = np.sqrt(ev_mid.energy(x.path) * ev_mid.energy_reversed(x.path))
        return [energy * (n_out ** 2 * lobe.density(po - pi, pbar))[:, None] for lobe in lobes]

    def single_event(self, path, s: int, ev_in: Events, ev_out: Events, pi, po) -> np.ndarray:
        """``f`` (Q, C) of ``path`` with its step ``s`` the only deviating event: that face's
        microfacet BSDF times the energies of the steps before it at ``pi`` and after it at
        ``po`` (``ev_in``, ``ev_out``), times ``n_out^2 / n_b^2``. Exact for a path with one
        near-specular event; for several, the term of :mod:`.tails`."""
        e, down, what = path.steps[s]
        face = self.chain.elements[e]
        a, b = path.gaps[s], path.gaps[s + 1]
        before = ev_in.energy(path, range(s))
        after = ev_out.energy(path, range(s + 1, len(path.steps)))
        na, nb = self.chain.n[a], self.chain.n[b]
        mu_a, mu_b = ev_in.mu[a], ev_out.mu[b]
        ok = ev_in.open[a] & ev_out.open[b]
        up_after = down if what == "R" else not down      # travels up after the event
        wi_l = np.concatenate([-pi / na, (mu_a if down else -mu_a)[:, None]], axis=1)
        wo_l = np.concatenate([po / nb, (mu_b if up_after else -mu_b)[:, None]], axis=1)
        if not down:                   # seen from below: mirror, relative index inverted
            wi_l[:, 2], wo_l[:, 2] = -wi_l[:, 2], -wo_l[:, 2]
        cr, sr = math.cos(face.rotation), math.sin(face.rotation)
        frame = lambda w: np.stack([cr * w[:, 0] + sr * w[:, 1], -sr * w[:, 0] + cr * w[:, 1],
                                    w[:, 2]], axis=1)
        f = np.zeros((pi.shape[0], self.chain.channels))
        for c, eta in enumerate(face.eta):
            eta = complex(eta)
            er = eta.real if (down or eta.imag > 0) else 1.0 / eta.real
            f[ok, c] = microfacet_reflection(frame(wi_l[ok]), frame(wo_l[ok]), er, face.alpha_u,
                                             face.alpha_v, face.distribution, eta.imag)
        return f * before * after * (self.n_side(path.exit_top) / self.chain.n[b]) ** 2

    # ---- energies ------------------------------------------------------------------------

    def step_energy(self, step: tuple, gap: int, p: np.ndarray) -> np.ndarray:
        """Energy (N, C) of one smooth or slab step arriving in ``gap`` at wave vectors
        ``p`` (N, 2)."""
        return Events(self.chain, self.faces, p).step(*step, gap)

    def albedo(self, wi: np.ndarray):
        """``(R, T)`` (Q, C) with the deltas, per incident direction: the delta paths'
        energies at ``p_i`` and the traced energies of the others (:func:`.trace.trace_path`,
        :data:`ALBEDO_NODES` nodes) that leave inside the exit's horizon, and the light of the
        walked branches (:func:`.frontier.split`, :func:`.continuation.continue_frontier`)."""
        R = np.zeros((wi.shape[0], self.chain.channels))
        T = np.zeros_like(R)
        for q in range(wi.shape[0]):
            top = bool(wi[q, 2] > 0)
            p = self.p_in(wi[q:q + 1])
            ev = Events(self.chain, self.faces, p)
            entries, ex = self.walked(top, p[0])
            energy = [ev.energy(x.path)[0].max() for x in entries]
            for x, e0 in zip(entries, energy):
                if x.rough:
                    count = _nodes_for(e0 / max(max(energy), 1e-300), ALBEDO_NODES)
                    po, w = trace_path(self, x, p[0], count)
                    e = self._inside(po, w, x.path.exit_top).sum(axis=0) / count
                else:
                    e = ev.energy(x.path)[0]
                if x.path.exit_top == top:
                    R[q] += e
                else:
                    T[q] += e
            R[q] += ex.w[ex.top == top].sum(axis=0)
            T[q] += ex.w[ex.top != top].sum(axis=0)
        return R, T

    def _inside(self, po: np.ndarray, w: np.ndarray, top: bool) -> np.ndarray:
        """The weights ``w`` (N, C) of exit wave vectors ``po`` (N, 2) inside the exit's
        horizon (0 beyond it)."""
        return w * (np.sum(po ** 2, axis=1) < self.n_side(top) ** 2)[:, None]

    def specular(self, wi: np.ndarray) -> dict:
        """``{"top" | "bottom": (energy (Q, C), wo (Q, 3))}`` of the delta paths."""
        p = self.p_in(wi)
        out = {s: [np.zeros((wi.shape[0], self.chain.channels)), None] for s in ("top", "bottom")}
        for side, top_exit in (("top", True), ("bottom", False)):
            out[side][1] = self.exit_direction(p, top_exit)
        for top in self.entries:
            sel = (wi[:, 2] > 0) == top
            if not sel.any():
                continue
            ev = Events(self.chain, self.faces, p[sel])
            for x in self.entries[top]:
                if not x.rough:
                    out["top" if x.path.exit_top else "bottom"][0][sel] += ev.energy(x.path)
        for side in out:
            out[side][0][np.linalg.norm(out[side][1], axis=1) == 0] = 0.0
        return {k: tuple(v) for k, v in out.items()}

    def bins(self, wi: np.ndarray, mu_edges, phi_edges) -> dict:
        """Energy (n_mu, n_phi, C) per bin of each side for one direction ``wi`` (3,):
        each delta in the bin of its direction, each path with lobes by
        :func:`.binning.path_bins` (traced where its nodes are dense, its BSDF integrated over
        the bin elsewhere), the walked branches' light (:func:`.frontier.split`) by its exits
        (:func:`.continuation.continue_frontier`)."""
        top = bool(wi[2] > 0)
        p = self.p_in(wi[None, :])
        ev = Events(self.chain, self.faces, p)
        shape = (mu_edges.size - 1, phi_edges.size - 1, self.chain.channels)
        out = {"top": np.zeros(shape), "bottom": np.zeros(shape)}
        entries, ex = self.walked(top, p[0])
        energy = [ev.energy(x.path)[0].max() for x in entries]
        for x, e in zip(entries, energy):
            side = out["top" if x.path.exit_top else "bottom"]
            if x.rough:
                share = e / max(max(energy), 1e-300)
                side += path_bins(self, x, p[0], _nodes_for(share, BIN_NODES), mu_edges,
                                  phi_edges)
                continue
            wo = self.exit_direction(p, x.path.exit_top)
            if np.linalg.norm(wo) > 0:
                i, j = direction_bin(wo[0], mu_edges, phi_edges)
                if i is not None:
                    side[i, j] += ev.energy(x.path)[0]
        cut = exit_bins(self, ex, mu_edges, phi_edges)
        return {k: out[k] + cut[k] for k in out}
