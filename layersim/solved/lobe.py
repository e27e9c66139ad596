"""Near-specular rough dielectric boundaries: the smooth transport plus the observable lobe.

A dielectric top interface whose roughness is at most :data:`NEAR_SPECULAR_ALPHA` (both axes)
is solved as a smooth boundary on the Snell-matched grid (:mod:`layersim.solved.boundary`), and its
roughness is applied where it is observable:

* its direct reflection is the single-scattering microfacet lobe of
  :func:`layersim.kernels.physics.microfacet_eval` (Walter et al. 2007, eq. 20), not a mirror
  delta: ``eval`` returns it, albedos and bin energies integrate it;
* light that crosses it is refracted as by the smooth boundary (the refraction blur,
  ``alpha |1 - 1/eta|`` radians, is far below the ordinate spacing and below what the rough
  layers inside resolve) with the rough interface's transmitted energy ``E_T`` in place of
  ``1 - F``, so that the energy entering and leaving is the rough model's (the single-scattering
  loss included);
* its internal reflection is the smooth Fresnel reflection (total beyond the critical angle)
  less the rough interface's single-scattering loss (:meth:`NearSpecularLobe.
  internal_reflectance`).

The error of this split against the Monte Carlo walk (exact for any roughness) is measured by
``benchmarks/features/near_specular.py`` and reported by the plan (:data:`MEASURED_ERROR`).

Both energies are integrals over microfacet normals in slope space (Heitz 2014, sec. 5): the
slope distribution ``P22`` is mapped to the unit square by its radial inverse CDF
(:func:`layersim.kernels.physics.slope_radius` at unit roughness, scaled by ``alpha_u``,
``alpha_v``), with Gauss-Legendre nodes in ``u`` and uniform ones in the azimuth; the integrand
is the visible-normal factor times the event's weight
(:func:`layersim.kernels.lobe.facet_events`), so that the energies are exactly those the walk
samples, up to the quadrature.
"""

from __future__ import annotations

import math

import numpy as np

from ..kernels.fresnel import fresnel
from ..kernels.lobe import facet_events, microfacet_reflection, reflection_pdf, sample_reflection
from ..kernels.pointwise import slope_radius

#: A dielectric top interface whose narrower roughness ``min(alpha_u, alpha_v)`` is at most
#: this is solved as a near-specular boundary: its exact projection over rough gold costs
#: n = 650, md = 783, 3.9 GiB and about 130 s at 0.03 (n = 976 and 12 GiB at 0.02;
#: ``layersim plan``), and grows like 1 / alpha.
NEAR_SPECULAR_ALPHA = 0.03

#: ... provided that its wider roughness ``max(alpha_u, alpha_v)`` is at most this: the
#: refraction blur it leaves out, ``alpha |1 - 1/eta|`` (0.017 rad at 0.05, eta 1.5), stays
#: below the spacing of the ordinates and the lobes of the rough layers inside.
NEAR_SPECULAR_WIDE_MAX = 0.1

#: Measured error of the split against Monte Carlo (``benchmarks/features/near_specular.txt``, 1e7
#: paths per direction, incidence 5-80 deg): for a coat (eta 1.5) over rough gold (alpha 0.2),
#: ``(wider alpha, largest |albedo difference|, smallest fraction of populated 18 x 36 bins
#: within 3 sigma)``; isotropic coats at 0.001, 0.005 and 0.02, 1:10 anisotropic ones (0.001,
#: 0.01) and (0.005, 0.05) at 0.01 and 0.05. The plan interpolates it in ``log alpha``.
MEASURED_ERROR = (
    (0.001, 3.6e-5, 1.000),
    (0.005, 4.2e-5, 1.000),
    (0.01, 1.2e-4, 1.000),
    (0.02, 4.0e-4, 1.000),
    (0.05, 8.6e-4, 0.991),
)

#: Quadrature nodes (radial, azimuthal) of the bin energies: each node's energy falls whole
#: into one bin, so a lobe straddling a bin edge is split to about 1 / (nodes across it); at
#: (512, 1024) a 1:10 anisotropic lobe cut by two bin edges through its peak is split within
#: the standard errors of 1e7 Monte Carlo paths (0.1 s per incident direction).
_BIN_NODES = (512, 1024)


def near_specular_error(alpha: float) -> str:
    """Report line: the split's measured error against Monte Carlo (:data:`MEASURED_ERROR`)
    at the wider roughness ``alpha``, interpolated in ``log alpha`` (clamped to the measured
    range)."""
    return _error_line(MEASURED_ERROR, alpha, "over rough gold",
                       "benchmarks/features/near_specular.txt")


def _error_line(table, alpha: float, where: str, output: str) -> str:
    if not table:
        return "its error against Monte Carlo is not measured"
    a, dr, frac = (np.array(v, float) for v in zip(*table))
    la = np.clip(math.log(alpha), np.log(a).min(), np.log(a).max())
    order = np.argsort(a)
    err = np.interp(la, np.log(a[order]), dr[order])
    ok = np.interp(la, np.log(a[order]), frac[order])
    return (f"measured against Monte Carlo {where} ({output}): "
            f"albedo within {err:.1e}, {100 * ok:.0f} % of bins within 3 sigma")


#: A conductor under other layers whose roughness (both axes) is at most this is solved as a
#: mirror with its rough reflectance (:func:`layersim.plan.layers._near_specular_conductor`);
#: rougher ones are projected exactly, which under a coat of alpha 0.1 costs n = 326,
#: md = 1145, 1.4 GiB and about 13 s at 0.02 (n = 650 and 9.9 GiB at 0.01; ``layersim plan``).
#: The mirror's error grows with the ratio of its lobe to the blur of the layers above
#: (:data:`MEASURED_CONDUCTOR_ERROR`).
NEAR_SPECULAR_BASE_ALPHA = 0.015

#: Measured error of a near-specular conductor base (a mirror with the rough reflectance)
#: under a coat, against Monte Carlo (``benchmarks/features/near_specular_conductors.txt``), as
#: :data:`MEASURED_ERROR`: ``(wider alpha of the conductor, largest |albedo difference|,
#: smallest fraction of populated bins within 3 sigma)``, 1e7 paths per direction at 5-80 deg,
#: gold under coats of alpha 0.1 and 0.3 (eta 1.5). Part of it is the coats' own plan: smooth gold
#: under the 0.1 coat, exact in both, is within 4.7e-4 with 97 % of bins within 3 sigma.
MEASURED_CONDUCTOR_ERROR = (
    (0.001, 7.3e-4, 0.985),
    (0.005, 2.0e-3, 0.921),
    (0.01, 1.4e-3, 0.931),
)


def near_specular_conductor_error(alpha: float) -> str:
    """Report line: the measured error of a near-specular conductor base
    (:data:`MEASURED_CONDUCTOR_ERROR`) at its wider roughness ``alpha``."""
    return _error_line(MEASURED_CONDUCTOR_ERROR, alpha, "under a coat",
                       "benchmarks/features/near_specular_conductors.txt")


_X_TABLE = 129
_CHUNK = 2048


class NearSpecularLobe:
    """The rough top interface of a near-specular boundary (relative index ``eta`` > 1,
    roughness ``alpha_u`` along the direction at ``rotation`` radians, ``alpha_v`` across), or
    a near-specular conductor (relative index ``eta + i k``, ``k > 0``), which only reflects."""

    def __init__(self, eta: float, alpha_u: float, alpha_v: float, distribution: str,
                 rotation: float = 0.0, nodes: tuple = (48, 64), k: float = 0.0):
        self.eta, self.au, self.av = float(eta), float(alpha_u), float(alpha_v)
        self.k = float(k)
        self.distribution, self.rotation = distribution, float(rotation)
        self.nodes = nodes
        nu, nphi = nodes
        u, wu = np.polynomial.legendre.leggauss(nu)
        u, wu = 0.5 * (u + 1.0), 0.5 * wu
        t = slope_radius(u, 1.0, distribution)
        phi = (np.arange(nphi) + 0.5) * 2.0 * np.pi / nphi
        sx = -self.au * np.outer(t, np.cos(phi)).ravel()
        sy = -self.av * np.outer(t, np.sin(phi)).ravel()
        m = np.stack([-sx, -sy, np.ones_like(sx)], axis=1)
        self.m = m / np.linalg.norm(m, axis=1)[:, None]
        self.w = np.repeat(wu, nphi) / nphi
        self._table = None
        self._reflected = None
        self._flipped = None
        self._fine = None

    def params(self) -> dict:
        return {"eta": self.eta, "alpha_u": self.au, "alpha_v": self.av,
                "distribution": self.distribution, "rotation": self.rotation, "k": self.k}

    def _frame(self, w: np.ndarray, sign: float = 1.0) -> np.ndarray:
        """Directions (Q, 3) into the tangent frame (``sign=-1``: back out of it)."""
        c, s = math.cos(self.rotation), sign * math.sin(self.rotation)
        return np.stack([c * w[:, 0] + s * w[:, 1], -s * w[:, 0] + c * w[:, 1], w[:, 2]], axis=1)

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Direct reflection ``f(wi, wo)`` (1/sr), 0 unless both lie above."""
        out = np.zeros(wi.shape[0])
        sel = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        if sel.any():
            out[sel] = microfacet_reflection(self._frame(wi[sel]), self._frame(wo[sel]),
                                             self.eta, self.au, self.av, self.distribution,
                                             self.k)
        return out

    def sample(self, wi: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Directions (Q, 3) reflected about visible normals drawn for ``wi`` (Q, 3, above)
        with uniforms ``u`` (Q, 3); the density is :meth:`pdf` (the Fresnel factor and the
        shadowing of the reflected direction stay in the sample's weight)."""
        wo = sample_reflection(self._frame(wi), u, self.au, self.av, self.distribution)
        return self._frame(wo, sign=-1.0)

    def pdf(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """Solid-angle density (1/sr) of :meth:`sample` at ``wo`` (Q, 3)."""
        return reflection_pdf(self._frame(wi), self._frame(wo), self.au, self.av,
                              self.distribution)

    def _events(self, wi: np.ndarray):
        vis, refl, trans, wo = facet_events(self._frame(wi), self.m, self.eta, self.au,
                                            self.av, self.distribution, self.k)
        return vis * self.w, refl, trans, wo

    def energies(self, wi: np.ndarray):
        """Reflected and transmitted energy ``(E_R, E_T)`` (Q,) of incident directions above
        (in chunks that bound the (Q, K) work arrays)."""
        wi = np.asarray(wi, float).reshape(-1, 3)
        R, T = np.zeros(wi.shape[0]), np.zeros(wi.shape[0])
        for s in range(0, wi.shape[0], _CHUNK):
            v, refl, trans, _ = self._events(wi[s:s + _CHUNK])
            R[s:s + _CHUNK], T[s:s + _CHUNK] = np.sum(v * refl, axis=1), np.sum(v * trans, axis=1)
        return R, T

    def _average(self, x: np.ndarray, which: int) -> np.ndarray:
        """Reflected (``which=0``) or transmitted (1) energy at cosines ``x``, averaged over
        the incident azimuth (8 azimuths over a half period where anisotropic)."""
        n_az = 1 if self.au == self.av else 8
        az = np.arange(n_az) * np.pi / n_az
        st = np.sqrt(np.clip(1.0 - x**2, 0.0, 1.0))
        w = np.stack([np.outer(st, np.cos(az)).ravel(), np.outer(st, np.sin(az)).ravel(),
                      np.repeat(x, n_az)], axis=1)
        return self.energies(w)[which].reshape(x.size, n_az).mean(axis=1)

    def mean_energies(self, x: np.ndarray):
        """Reflected and transmitted energy ``(E_R, E_T)`` (each ``x.shape``) at cosines ``x``
        (> 0) on the side the lobe is seen from, averaged over the incident azimuth."""
        x = np.asarray(x, float)
        return self._average(x, 0), self._average(x, 1)

    def inside_energies(self, mu: np.ndarray):
        """:meth:`mean_energies` of the same interface lit from the dense side (relative index
        ``1 / eta``) at cosines ``mu``: its internal reflection, total beyond the critical angle
        up to the microsurface's blur and loss, and what leaves."""
        return self._inside().mean_energies(np.abs(np.asarray(mu, float)))

    def reflectance(self, mu: np.ndarray) -> np.ndarray:
        """Reflected energy ``E_R`` at cosines ``mu`` (> 0), averaged over the incident
        azimuth: the diagonal that stands for a near-specular conductor in the solve
        (:func:`layersim.ingredients.smooth.smooth_conductor_operator`)."""
        return self._average(np.asarray(mu, float), 0)

    def internal_reflectance(self, mu: np.ndarray) -> np.ndarray:
        """Reflectance of the boundary for light arriving from inside at cosines ``mu``: the
        smooth boundary's Fresnel ``F`` (1 beyond the critical angle) less the rough
        interface's single-scattering loss ``1 - E_R - E_T`` seen from the dense side (the
        same microsurface: relative index ``1 / eta`` seen from above; ``D`` and ``G1`` are
        even in ``z``), azimuth average. The split keeps the smooth transport, in which what
        crosses from inside leaves at the Snell image with the outside transmittance
        (reciprocity), and takes from the rough model the energy the microsurface loses
        (masking at grazing inside angles, where light trapped by total internal reflection
        meets the coat many times). The rough counterpart of the boundary's ``F`` in
        :func:`layersim.ingredients.smooth.boundary_reflector`."""
        mu = np.abs(np.asarray(mu, float))
        inside = self._inside()
        loss = 1.0 - inside._average(mu, 0) - inside._average(mu, 1)
        return np.clip(fresnel(-mu, self.eta) - loss, 0.0, 1.0)

    def _inside(self) -> "NearSpecularLobe":
        """The same interface seen from the dense side (relative index ``1 / eta``)."""
        if self._flipped is None:
            self._flipped = NearSpecularLobe(1.0 / self.eta, self.au, self.av,
                                              self.distribution, self.rotation)
        return self._flipped

    def reflected(self, x) -> np.ndarray:
        """Reflected energy at outside cosines ``x``, averaged over the incident azimuth and
        interpolated in a table (the share of the lobe when a BSDF with it is sampled,
        :class:`layersim.solved.sampling.LobeSampler`)."""
        if self._reflected is None:
            nodes = np.linspace(0.0, 1.0, _X_TABLE) ** 2
            self._reflected = (nodes, self._average(nodes, 0))
        return np.interp(np.asarray(x, float), *self._reflected)

    def transmittance(self, x) -> np.ndarray:
        """Transmitted energy at outside cosines ``x``, averaged over the incident azimuth
        (the rough counterpart of ``1 - F``; by reciprocity also the fraction of inside
        radiance refracted to ``x`` that leaves)."""
        if self._table is None:
            nodes = np.linspace(0.0, 1.0, _X_TABLE) ** 2   # dense near grazing, where 1 - F falls
            self._table = (nodes, self._average(nodes, 1))
        return np.interp(np.asarray(x, float), *self._table)

    def bins(self, wi: np.ndarray, mu_edges: np.ndarray, phi_edges: np.ndarray) -> np.ndarray:
        """Energy of the direct reflection in the bins ``mu_edges x phi_edges`` (top side)
        for one incident direction ``wi`` (3,)."""
        if self._fine is None:
            self._fine = NearSpecularLobe(self.eta, self.au, self.av, self.distribution,
                                          self.rotation, nodes=_BIN_NODES, k=self.k)
        v, refl, _, wo = self._fine._events(wi[None, :])
        e = (v * refl)[0]
        wo = self._frame(wo[0], sign=-1.0)
        keep = (e > 0) & (wo[:, 2] > 0)
        phi = np.arctan2(wo[keep, 1], wo[keep, 0]) % (2 * np.pi)
        E, _, _ = np.histogram2d(wo[keep, 2], phi, bins=[mu_edges, phi_edges],
                                 weights=e[keep])
        return E
