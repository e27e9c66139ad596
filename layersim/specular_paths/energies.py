"""Directional energies of the events at one face of a chain (:mod:`.stack`).

A smooth dielectric face reflects the Fresnel fraction ``F`` and transmits ``1 - F``; a smooth
conductor reflects the conductor Fresnel fraction (:func:`layersim.kernels.fresnel.fresnel`, the
walk's own functions). A near-specular face reflects and transmits the rough interface's
directional energies ``E_R``, ``E_T`` (the single-scattering loss left out of both), integrated
over its visible microfacet normals in slope space (Heitz 2014, sec. 5;
:meth:`layersim.solved.lobe.NearSpecularLobe.energies`), tabulated once in the cosine and the
azimuth of the arriving direction and interpolated bilinearly. ``E`` is even in the azimuth
(``P22`` is even in the slope), so the table covers half a period.
"""

from __future__ import annotations

import numpy as np

from ..kernels.fresnel import fresnel
from ..solved.lobe import NearSpecularLobe

__all__ = ["FaceEnergies"]

#: Cosine nodes of a rough face's energy table (squared spacing: dense near grazing, where
#: ``E_T`` falls), and azimuth nodes over half a period for an anisotropic face.
_MU_NODES = 129
_PHI_NODES = 16


class FaceEnergies:
    """Reflected and transmitted energy fractions at one :class:`~.stack.Face`, per channel.

    Parameters
    ----------
    face : layersim.specular_paths.stack.Face
    """

    def __init__(self, face):
        self.face = face
        self._tables: dict = {}

    def __call__(self, down: bool, ph: np.ndarray, mu: np.ndarray):
        """``(R, T)``, each (Q, C), for light arriving from above (``down``) or below at
        cosine ``mu`` (Q,) in the arriving medium, horizontal propagation ``ph`` (Q, 2)
        (only its azimuth matters, for an anisotropic face)."""
        if self.face.smooth:
            return self._smooth(down, mu)
        R, T = [], []
        for c in range(len(self.face.eta)):
            r, t = self._table(down, c)(ph, mu)
            R.append(r)
            T.append(t)
        return np.stack(R, axis=-1), np.stack(T, axis=-1)

    def _smooth(self, down: bool, mu: np.ndarray):
        R, T = [], []
        for eta in self.face.eta:
            eta = complex(eta)
            if eta.imag > 0.0:
                r = fresnel(mu, eta.real, eta.imag) if down else np.ones_like(mu)
                R.append(r)
                T.append(np.zeros_like(mu))
                continue
            r = fresnel(mu if down else -mu, eta.real)
            R.append(r)
            T.append(1.0 - r)
        return np.stack(R, axis=-1), np.stack(T, axis=-1)

    def _table(self, down: bool, c: int):
        key = (down, c if len(set(self.face.eta)) > 1 else 0)
        if key not in self._tables:
            self._tables[key] = _EnergyTable(self._lobe(down, c))
        return self._tables[key]

    def _lobe(self, down: bool, c: int) -> NearSpecularLobe:
        """The rough interface seen from the arriving side, as a top interface (from below:
        the relative index inverted; ``D`` and ``G1`` are even in ``z``)."""
        f, eta = self.face, complex(self.face.eta[c])
        if eta.imag > 0.0:
            return NearSpecularLobe(eta.real, f.alpha_u, f.alpha_v, f.distribution, f.rotation,
                                    k=eta.imag)
        e = eta.real if down else 1.0 / eta.real
        return NearSpecularLobe(e, f.alpha_u, f.alpha_v, f.distribution, f.rotation)


class _EnergyTable:
    """``E_R``, ``E_T`` of a :class:`NearSpecularLobe` on a (cosine, azimuth) grid."""

    def __init__(self, lobe: NearSpecularLobe):
        self.mu = np.linspace(0.0, 1.0, _MU_NODES) ** 2
        self.mu[0] = 1e-6
        iso = lobe.au == lobe.av
        self.phi = np.zeros(1) if iso else np.arange(_PHI_NODES) * np.pi / _PHI_NODES
        st = np.sqrt(1.0 - self.mu ** 2)
        w = np.stack([np.outer(st, np.cos(self.phi)).ravel(),
                      np.outer(st, np.sin(self.phi)).ravel(),
                      np.repeat(self.mu, self.phi.size)], axis=1)
        R, T = lobe.energies(w)
        self.R = R.reshape(self.mu.size, self.phi.size)
        self.T = T.reshape(self.mu.size, self.phi.size)

    def __call__(self, ph: np.ndarray, mu: np.ndarray):
        mu = np.clip(np.asarray(mu, float), self.mu[0], 1.0)
        i = np.clip(np.searchsorted(self.mu, mu) - 1, 0, self.mu.size - 2)
        a = (mu - self.mu[i]) / (self.mu[i + 1] - self.mu[i])
        if self.phi.size == 1:
            return tuple((1 - a) * X[i, 0] + a * X[i + 1, 0] for X in (self.R, self.T))
        step = np.pi / self.phi.size
        x = (np.arctan2(ph[:, 1], ph[:, 0]) % np.pi) / step
        j = np.floor(x).astype(int) % self.phi.size
        b = x - np.floor(x)
        j1 = (j + 1) % self.phi.size
        return tuple((1 - a) * ((1 - b) * X[i, j] + b * X[i, j1])
                     + a * ((1 - b) * X[i + 1, j] + b * X[i + 1, j1]) for X in (self.R, self.T))
