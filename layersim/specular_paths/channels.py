"""The paths of a stack whose indices may differ per channel: one :class:`.model.PathModel` per
group of channels sharing every gap's index (:func:`.stack.channel_groups`).

A path keeps the horizontal wave vector ``p = n sin(theta)``, which in a dispersive gap differs
per channel for the same direction, so the channels' paths never interact: each group is
solved with its own indices and the results are placed on the channel axis. A stack without
dispersion is one group of all channels, whose model answers directly (nothing changes for
it). The delta paths of this class are reflections only (a transmitted delta needs every face
smooth, and the class has a near-specular one), which leave in the mirror direction whatever
the indices: :meth:`ChannelModels.specular` gives one direction per side for all channels.
"""

from __future__ import annotations

import numpy as np

from .model import PathModel
from .sampler import ChannelMixtureSampler, PathSampler
from .stack import chain_of, channel_groups

__all__ = ["ChannelModels"]


class ChannelModels:
    """The path models of ``scene`` (a stack for which :func:`.stack.why_not` is None), one
    per group of channels of equal indices, pruned at ``prune``.

    Attributes
    ----------
    groups : list of tuple of int
        The channel indices of each group.
    models : list of PathModel
        The model of each group (its chain's channels are the group's, in order).
    """

    def __init__(self, scene, prune: float):
        self.groups = channel_groups(scene)
        self.models = [PathModel(chain_of(scene, g), prune) for g in self.groups]
        self.channels = scene.channels

    @property
    def opaque(self) -> bool:
        return any(m.chain.opaque for m in self.models)

    def _place(self, parts: list) -> np.ndarray:
        """The groups' results (..., C_g) on the channel axis (..., C)."""
        if len(parts) == 1:
            return parts[0]
        out = np.zeros(parts[0].shape[:-1] + (self.channels,))
        for g, x in zip(self.groups, parts):
            out[..., list(g)] = x
        return out

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """``f(wi, wo)`` (Q, C) in 1/sr, deltas left out (:meth:`PathModel.eval`)."""
        return self._place([m.eval(wi, wo) for m in self.models])

    def albedo(self, wi: np.ndarray):
        """``(R, T)`` (Q, C) (:meth:`PathModel.albedo`)."""
        parts = [m.albedo(wi) for m in self.models]
        return self._place([r for r, _ in parts]), self._place([t for _, t in parts])

    def specular(self, wi: np.ndarray) -> dict:
        """``{"top" | "bottom": (energy (Q, C), wo (Q, 3))}`` of the delta paths; ``wo``
        is the first group's (the deltas carrying energy are reflections, whose direction is
        every group's)."""
        parts = [m.specular(wi) for m in self.models]
        return {side: (self._place([p[side][0] for p in parts]), parts[0][side][1])
                for side in parts[0]}

    def bins(self, wi: np.ndarray, mu_edges, phi_edges) -> dict:
        """Energy (n_mu, n_phi, C) per bin of each side (:meth:`PathModel.bins`)."""
        parts = [m.bins(wi, mu_edges, phi_edges) for m in self.models]
        return {side: self._place([p[side] for p in parts]) for side in parts[0]}

    def sampler(self):
        """The sampler: the one model's :class:`.sampler.PathSampler`, or the mixture of the
        groups' (:class:`.sampler.ChannelMixtureSampler`)."""
        if len(self.models) == 1:
            return PathSampler(self.models[0])
        return ChannelMixtureSampler(self)

    def path_counts(self) -> dict:
        """``{"top" | "bottom": paths}`` summed over the groups."""
        out: dict = {}
        for m in self.models:
            for top, ps in m.sets.items():
                key = "top" if top else "bottom"
                out[key] = out.get(key, 0) + len(ps.paths)
        return out

    def pruned(self) -> dict:
        """``{"top" | "bottom": energy}``: the largest pruned energy over the groups."""
        out: dict = {}
        for m in self.models:
            for top, ps in m.sets.items():
                key = "top" if top else "bottom"
                out[key] = max(out.get(key, 0.0), float(ps.pruned.max()))
        return out
