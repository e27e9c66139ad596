"""Importance sampling of a BSDF of specular paths.

A path with a lobe is chosen with probability proportional to its energy at the incident wave
vector ``p_i`` (mean over channels; deltas are not sampled, as ``BSDF.sample``), then ``Delta
p`` is drawn from its lobe with the scales at ``p_i`` (:meth:`layersim.specular_paths.lobes.
PathLobe.sample`). The solid-angle density is the mixture ``pdf = sum_k P_k density_k(p_o -
p_i) n_out^2 |wo.z|`` (``d^2 p = n^2 mu dOmega``), which :meth:`PathSampler.pdf` evaluates; a
draw beyond the exit's horizon is an invalid sample (``docs/conventions.md``). The two
uniforms of ``u`` are stretched over the four choices by rescaling: the part of ``u[0]``
within the chosen path's interval picks the shape node of the mixture and, rescaled again,
the azimuth; ``u[1]`` gives the radius.

Where the indices differ per channel (one model per group of channels,
:mod:`.channels`), :class:`ChannelMixtureSampler` draws from the mixture of the groups'
samplers, each channel weighing equally (group ``g`` of ``C_g`` of the ``C`` channels chosen
with probability ``C_g / C`` by the first part of ``u[0]``, the rest rescaled for its
sampler); ``pdf`` is that mixture's density and the weights are ``f cos / pdf`` per channel
(a channel's lobe drawn for another channel gives it a small weight, not a bias).
"""

from __future__ import annotations

import numpy as np

from ..solved.directions import unit_directions
from ..solved.sampling import Sample
from .paths import Events

__all__ = ["PathSampler", "ChannelMixtureSampler"]


class PathSampler:
    """Sampler of the paths of one :class:`layersim.specular_paths.model.PathModel` (a stack
    whose indices are one for all channels)."""

    def __init__(self, model):
        self.model = model
        self.channels = model.chain.channels
        self.opaque = model.chain.opaque

    def _eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return self.model.eval(wi, wo)

    def _probabilities(self, top: bool, p: np.ndarray):
        """The sampled paths' entries and their probabilities (Q, P) at ``p`` (Q, 2)."""
        entries = [x for x in self.model.entries[top] if x.rough]
        ev = Events(self.model.chain, self.model.faces, p)
        w = np.stack([ev.energy(x.path).mean(axis=1) for x in entries], axis=1) \
            if entries else np.zeros((p.shape[0], 0))
        tot = w.sum(axis=1, keepdims=True)
        return entries, np.divide(w, tot, out=np.zeros_like(w), where=tot > 0)

    def _rows(self, wi, u=None):
        wi = unit_directions("wi", wi)
        if u is None:
            return wi.reshape(-1, 3), wi.shape[:-1], None
        u = np.asarray(u, float)
        if u.shape[-1:] != (2,) or np.any((u < 0) | (u >= 1)) or not np.all(np.isfinite(u)):
            raise ValueError("u must be uniforms in [0, 1) of shape (..., 2)")
        # u padded to three columns only to broadcast against wi (..., 3)
        wi, u = np.broadcast_arrays(wi, np.concatenate([u, u[..., :1]], axis=-1))
        return wi.reshape(-1, 3), wi.shape[:-1], u[..., :2].reshape(-1, 2)

    def sample(self, wi, u) -> Sample:
        wi, shape, u = self._rows(wi, u)
        Q = wi.shape[0]
        wo = np.zeros((Q, 3))
        live = (wi[:, 2] != 0) & ~((wi[:, 2] < 0) & self.opaque)
        wo[live] = self._directions(wi[live], u[live])
        ok = np.linalg.norm(wo, axis=1) > 0
        pdf = np.zeros(Q)
        weight = np.zeros((Q, self.channels))
        if ok.any():
            pdf[ok] = self._pdf(wi[ok], wo[ok])
            f = self._eval(wi[ok], wo[ok])
            good = pdf[ok] > 0
            weight[np.flatnonzero(ok)[good]] = f[good] * (np.abs(wo[ok][good, 2])
                                                          / pdf[ok][good])[:, None]
        bad = pdf <= 0
        wo[bad], pdf[bad], weight[bad] = 0.0, 0.0, 0.0
        w = weight[:, 0].reshape(shape) if self.channels == 1 \
            else weight.reshape(shape + (self.channels,))
        return Sample(wo.reshape(shape + (3,)), w, pdf.reshape(shape))

    def _directions(self, wi: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Drawn directions (Q, 3) for rows ``wi`` (Q, 3) that light can enter; (0, 0, 0)
        where none is drawn."""
        wo = np.zeros((wi.shape[0], 3))
        for top in self.model.entries:
            sel = np.flatnonzero((wi[:, 2] > 0) == top)
            if sel.size:
                wo[sel] = self._draw(top, wi[sel], u[sel])
        return wo

    def _draw(self, top: bool, wi: np.ndarray, u: np.ndarray) -> np.ndarray:
        p = self.model.p_in(wi)
        entries, P = self._probabilities(top, p)
        wo = np.zeros((wi.shape[0], 3))
        if not entries:
            return wo
        C = np.cumsum(P, axis=1)
        k = np.minimum((C < u[:, :1]).sum(axis=1), len(entries) - 1)
        rows = np.arange(wi.shape[0])
        lo = np.where(k > 0, C[rows, np.maximum(k - 1, 0)], 0.0)
        v = np.clip((u[:, 0] - lo) / np.maximum(P[rows, k], 1e-300), 0.0, 1.0 - 1e-16)
        for j in np.unique(k):
            s = np.flatnonzero((k == j) & (P[rows, k] > 0))
            if s.size == 0:
                continue
            x = entries[j]
            _, a = x.lobe.mixture(np.linalg.norm(p[s], axis=1))
            pick = v[s] < a
            v2 = np.where(pick, v[s] / np.maximum(a, 1e-300),
                          (v[s] - a) / np.maximum(1.0 - a, 1e-300))
            # first column below a: the upper shape node (PathLobe.sample), else the lower
            uu = np.stack([np.where(pick, -1.0, 2.0), u[s, 1], np.clip(v2, 0.0, 1.0 - 1e-16)],
                          axis=1)
            dp = x.lobe.sample(p[s], uu)
            wo[s] = self.model.exit_direction(p[s] + dp, x.path.exit_top)
        return wo

    def pdf(self, wi, wo) -> np.ndarray:
        """Solid-angle density (1/sr) of :meth:`sample` at ``wo``; shape of the broadcast."""
        wi, wo = np.broadcast_arrays(unit_directions("wi", wi), unit_directions("wo", wo))
        shape = wi.shape[:-1]
        return self._pdf(wi.reshape(-1, 3), wo.reshape(-1, 3)).reshape(shape)

    def _pdf(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        out = np.zeros(wi.shape[0])
        for top in self.model.entries:
            sel = np.flatnonzero((wi[:, 2] > 0) == top)
            sel = sel[(wo[sel, 2] != 0) & (wi[sel, 2] != 0)]
            if sel.size == 0:
                continue
            p, po = self.model.p_in(wi[sel]), self.model.p_out(wo[sel])
            entries, P = self._probabilities(top, p)
            for j, x in enumerate(entries):
                side = (wo[sel, 2] > 0) == x.path.exit_top
                n_out = self.model.n_side(x.path.exit_top)
                d = x.lobe.density(po - p, p) * n_out ** 2 * np.abs(wo[sel, 2])
                out[sel] += np.where(side, P[:, j] * d, 0.0)
        return out


class ChannelMixtureSampler(PathSampler):
    """Sampler of a :class:`layersim.specular_paths.channels.ChannelModels` of several groups:
    the mixture of the groups' :class:`PathSampler`, group ``g`` with probability ``C_g /
    C`` (each channel's lobes weigh equally); weights ``f cos / pdf`` per channel with ``f``
    of every channel and ``pdf`` the mixture's."""

    def __init__(self, models):
        self.models = models
        self.channels = models.channels
        self.opaque = models.opaque
        self.parts = [PathSampler(m) for m in models.models]
        self.share = np.array([len(g) for g in models.groups], float) / models.channels

    def _eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return self.models.eval(wi, wo)

    def _directions(self, wi: np.ndarray, u: np.ndarray) -> np.ndarray:
        edges = np.concatenate([[0.0], np.cumsum(self.share)])
        g = np.minimum(np.searchsorted(edges, u[:, 0], side="right") - 1, len(self.parts) - 1)
        # the part of u[0] within the chosen group's interval, rescaled, serves its sampler
        v = np.clip((u[:, 0] - edges[g]) / self.share[g], 0.0, 1.0 - 1e-16)
        wo = np.zeros((wi.shape[0], 3))
        for j, part in enumerate(self.parts):
            s = np.flatnonzero(g == j)
            if s.size:
                wo[s] = part._directions(wi[s], np.stack([v[s], u[s, 1]], axis=1))
        return wo

    def _pdf(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        return sum(w * part._pdf(wi, wo) for w, part in zip(self.share, self.parts))
