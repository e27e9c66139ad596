"""The solved BSDF of a stack of flat interfaces and clear media, as its specular paths.

:class:`SpecularPathsBSDF` has the public interface of :class:`layersim.solved.bsdf.BSDF`
(``eval``, ``albedo``, ``bin_energies``, ``specular``, ``sample``, ``pdf``, ``save``) on the
representation of :mod:`layersim.specular_paths.model`; ``BSDF.load`` reads it back. The saved
file holds the scene (what rebuilds the paths, deterministically), the pruning threshold and
the metadata.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..solved.directions import bin_arguments, direction_pairs, incident_directions
from ..solved.sampling import Sample
from .channels import ChannelModels
from .paths import PRUNE

__all__ = ["SpecularPathsBSDF", "FORMAT_VERSION_PATHS"]

#: ``version`` of a saved BSDF of specular paths in a ``layersim-bsdf`` archive (its scene and
#: pruning threshold, from which loading rebuilds the paths); older layersim versions refuse
#: it as newer.
FORMAT_VERSION_PATHS = 3



class SpecularPathsBSDF:
    """A stack solved as a sum over specular paths (:mod:`layersim.specular_paths`).

    Attributes
    ----------
    scene : layersim.Scene
    plan : layersim.plan.Plan or None
    info : dict
        Scene name, timings, path counts and pruned energy (saved with the BSDF).
    model : layersim.specular_paths.channels.ChannelModels
        The paths, one model per group of channels sharing their indices (one group unless
        a dielectric's index differs per channel).
    """

    representation = "specular-paths"
    #: Like :class:`layersim.solved.bsdf.BSDF` of an isotropic stack without smooth
    #: boundaries kept out of operators (callers that ask get the plain answer).
    anisotropic = False

    @property
    def boundary(self) -> dict:
        return {}

    def __init__(self, scene, plan=None, info: dict | None = None, prune: float = PRUNE):
        self.scene = scene
        self.plan = plan
        self.prune = float(prune)
        self.model = ChannelModels(scene, self.prune)
        self.info = dict(info or {})
        self.info.setdefault("scene", scene.name)
        self.info["representation"] = self.representation
        self.info["paths"] = self.model.path_counts()
        self.info["pruned"] = self.model.pruned()
        self.lobes = [{} for _ in range(self.channels)]
        self._sampler = None

    @property
    def channels(self) -> int:
        return self.model.channels

    @property
    def chains(self) -> list:
        """The chain of each group of channels (:attr:`model`)."""
        return [m.chain for m in self.model.models]

    @property
    def opaque(self) -> bool:
        return self.model.opaque

    def _out(self, x: np.ndarray, shape: tuple) -> np.ndarray:
        """(Q, C) results in the caller's shape (a trailing channel axis for RGB)."""
        return x[:, 0].reshape(shape) if self.channels == 1 else x.reshape(shape + (x.shape[1],))

    def _incident(self, wi) -> np.ndarray:
        return incident_directions(wi, self.opaque, "a conductor")

    def eval(self, wi, wo) -> np.ndarray:
        """BSDF value ``f(wi, wo)`` in 1/sr without the cosine (radiance convention), deltas
        left out (:meth:`specular`); 0 for light from below an opaque stack and on the
        horizon. Shapes as :meth:`layersim.solved.bsdf.BSDF.eval`."""
        wi, wo, shape = direction_pairs(wi, wo)
        f = self.model.eval(wi, wo)
        if self.opaque:
            f[wi[:, 2] < 0] = 0.0
        return self._out(f, shape)

    interpolant = eval

    def specular(self, wi) -> dict:
        """The delta paths (those without a near-specular event): ``{"top" | "bottom":
        (energy, wo)}`` as :meth:`layersim.solved.bsdf.BSDF.specular`."""
        wi = self._incident(wi)
        shape = wi.shape[:-1]
        res = self.model.specular(wi.reshape(-1, 3))
        return {k: (self._out(e, shape), w.reshape(shape + (3,))) for k, (e, w) in res.items()}

    def albedo(self, wi):
        """Energy fractions ``(R, T)`` of a beam from ``wi`` (deltas included): the paths'
        energies less what their lobes send beyond the horizon."""
        wi = self._incident(wi)
        shape = wi.shape[:-1]
        R, T = self.model.albedo(wi.reshape(-1, 3))
        return self._out(R, shape), self._out(T, shape)

    def bin_energies(self, wi, mu_edges, phi_edges) -> dict:
        """Fraction of the power of a beam from ``wi`` (3,) leaving into each bin, per side
        (as :meth:`layersim.solved.bsdf.BSDF.bin_energies`; each lobe by its quadrature
        nodes, each delta in the bin of its direction)."""
        wi = self._incident(wi)
        mu_edges, phi_edges = bin_arguments(wi, mu_edges, phi_edges)
        out = self.model.bins(wi, mu_edges, phi_edges)
        return {k: (v[..., 0] if self.channels == 1 else v) for k, v in out.items()}

    def sampler(self):
        """:meth:`ChannelModels.sampler`, built once."""
        if self._sampler is None:
            self._sampler = self.model.sampler()
        return self._sampler

    def sample(self, wi, u) -> Sample:
        """Draw ``wo`` (:class:`layersim.specular_paths.sampler.PathSampler`): a path by its
        energy, then a direction from its lobe; deltas are not sampled. Where the indices
        differ per channel, a direction from the mixture of the channels' lobes (each channel
        weighing equally, :class:`layersim.specular_paths.sampler.ChannelMixtureSampler`),
        ``pdf`` that mixture's density and the weights ``f cos / pdf`` per channel."""
        return self.sampler().sample(wi, u)

    def pdf(self, wi, wo) -> np.ndarray:
        """Solid-angle density (1/sr) with which :meth:`sample` draws ``wo``."""
        return self.sampler().pdf(wi, wo)

    # ---- persistence -------------------------------------------------------------------

    def save(self, path) -> Path:
        """Write the scene, the pruning threshold and the metadata (numpy ``.npz``;
        ``BSDF.load`` rebuilds the paths)."""
        if not isinstance(path, (str, os.PathLike)):
            raise TypeError("save takes a path (str or pathlib.Path), got "
                            f"{type(path).__name__}")
        path = Path(path)
        arrays = {"format": np.array("layersim-bsdf"),
                  "version": np.array(FORMAT_VERSION_PATHS),
                  "representation": np.array(self.representation),
                  "scene": np.array(json.dumps(self.scene.to_dict(), default=str)),
                  "prune": np.array(self.prune), "channels": np.array(self.channels),
                  "info": np.array(json.dumps(self.info, default=str))}
        with open(path, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        return path

    @classmethod
    def from_arrays(cls, d) -> "SpecularPathsBSDF":
        """The BSDF saved by :meth:`save` (``d``: the opened archive)."""
        from ..scene import Scene
        scene = Scene.from_dict(json.loads(str(d["scene"])))
        return cls(scene, None, json.loads(str(d["info"])), prune=float(d["prune"]))

    def __repr__(self) -> str:
        n = ", ".join(f"{k}: {v}" for k, v in self.info["paths"].items())
        return (f"SpecularPathsBSDF({self.info.get('scene', '?')}: paths {n}, "
                f"{self.channels} channel(s), {'opaque' if self.opaque else 'transmissive'})")
