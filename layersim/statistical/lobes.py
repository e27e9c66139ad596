"""The statistical model's result as a BSDF: a sum of GGX lobes (Belcour 2018, eq. 3 of
Bati et al. 2021), one per interface, each with its energy ``R_k(theta_i)`` and the roughness
``f^-1(sigma_k(theta_i))`` of its variance.

Each lobe is a GGX reflection lobe without Fresnel, normalised to carry exactly its energy:
``f_k(wi, wo) = R_k D(h) G2(wi, wo) / (4 wi.z wo.z E(wi.z, alpha_k))`` with ``E`` the lobe's own
directional albedo (:func:`layersim.kernels.fgd.ggx_albedo`). A smooth lobe (roughness 0) is a
mirror delta, left out of :meth:`StatisticalBSDF.eval` and given by ``specular`` (as in
:class:`layersim.BSDF`). Only reflection is modelled (Bati et al. 2021, sec. 3): ``albedo``
reports the model's transmitted energy, but ``bin_energies`` has no bottom-side distribution
(zeros).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ..solved.directions import bin_arguments, bin_edges, direction_pairs, unit_directions
from ..errors import InfeasibleError
from .forward import add_stack
from .stack import statistical_stacks
from .variance import roughness


@dataclass(frozen=True)
class Lobe:
    """One lobe, per channel: ``energy`` (fraction of the incident power), ``variance``
    (Belcour's), ``roughness`` (GGX alpha of that variance); ``layer``: index of the interface
    in the scene."""

    energy: np.ndarray
    variance: np.ndarray
    roughness: np.ndarray
    layer: int


@functools.lru_cache(maxsize=4096)
def _ggx_albedo(mu: float, alpha: float) -> float:
    from ..kernels.fgd import ggx_albedo
    return float(ggx_albedo(mu, alpha))


def incidence_cosine(theta_i) -> float:
    """``cos theta_i`` of an incidence angle ``theta_i`` (radians from the normal), checked:
    one real number in ``[0, pi/2)`` (the model is lit from above; the horizon is excluded),
    rounded to 12 digits (the key of the cached statistics).

    Raises
    ------
    TypeError
        If ``theta_i`` is not one real number.
    ValueError
        If it is not finite or outside ``[0, pi/2)``; an angle that looks like degrees says so.
    """
    a = np.asarray(theta_i) if not isinstance(theta_i, (str, bytes)) else None
    if (a is None or a.shape != () or isinstance(theta_i, bool) or a.dtype == bool
            or not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.floating))):
        raise TypeError(f"theta_i must be one angle in radians (a real number), got "
                        f"{type(theta_i).__name__} {theta_i!r:.40}")
    t = float(a)
    mu = round(math.cos(t), 12) if math.isfinite(t) else 0.0
    if not (math.isfinite(t) and 0.0 <= t < 0.5 * math.pi and mu > 0.0):
        # an angle past the horizon but below 90 may be meant in degrees
        hint = (f"; theta_i is in radians ({t:g} deg would be {math.radians(t):.4g} rad)"
                if math.isfinite(t) and 1.6 <= t < 90.0 else "")
        raise ValueError(f"theta_i = {t:g} rad: the incidence angle must be in [0, pi/2) "
                         f"(from the normal, the horizon excluded; the statistical model is "
                         f"lit from above){hint}")
    return mu


#: Gauss-Legendre nodes per bin in the outgoing elevation and azimuth for :func:`lobe_bins`.
BIN_NODES = 16


def lobe_bins(wi, alpha: float, mu_edges, phi_edges, nodes: int = BIN_NODES) -> np.ndarray:
    """Fractions of a unit-energy GGX lobe (roughness ``alpha > 0``, incident ``wi``) leaving
    into each ``(mu, phi)`` bin, shape ``(n_mu, n_phi)``: the lobe
    ``D G2 / (4 wi.z wo.z E(wi.z, alpha))`` integrated with ``nodes x nodes`` Gauss-Legendre
    nodes per bin in (theta_o, phi_o). Over the whole hemisphere they sum to 1 up to the
    quadrature error (below 1e-4 for alpha >= 0.05 on 18 x 36 bins)."""
    from ..kernels.fgd import ggx_lobe
    if not (isinstance(alpha, (int, float, np.number)) and math.isfinite(alpha) and alpha > 0):
        raise ValueError(f"alpha must be a GGX roughness > 0, got {alpha!r}")
    wi = unit_directions("wi", wi)
    if wi.shape != (3,) or wi[2] <= 0.0:
        raise ValueError(f"wi must be one direction of shape (3,) above the surface (wi.z > 0), "
                         f"got shape {wi.shape}" + (f", wi.z = {wi[2]:g}" if wi.shape == (3,)
                                                     else ""))
    mu_edges = bin_edges("mu_edges", mu_edges, 0.0, 1.0)
    phi_edges = bin_edges("phi_edges", phi_edges, 0.0, 2.0 * np.pi)
    x, w = np.polynomial.legendre.leggauss(nodes)
    t_edges = np.arccos(np.clip(mu_edges, 0.0, 1.0))          # decreasing in theta
    t0, t1 = t_edges[1:], t_edges[:-1]
    th = 0.5 * (t0 + t1)[:, None] + 0.5 * (t1 - t0)[:, None] * x          # (n_mu, nodes)
    wt = 0.5 * (t1 - t0)[:, None] * w
    p0, p1 = phi_edges[:-1], phi_edges[1:]
    ph = 0.5 * (p0 + p1)[:, None] + 0.5 * (p1 - p0)[:, None] * x          # (n_phi, nodes)
    wp_ = 0.5 * (p1 - p0)[:, None] * w
    T = th[:, None, :, None]
    P = ph[None, :, None, :]
    wo = np.stack(np.broadcast_arrays(np.sin(T) * np.cos(P), np.sin(T) * np.sin(P),
                                      np.cos(T)), axis=-1)
    f = ggx_lobe(np.broadcast_to(wi, wo.shape).reshape(-1, 3), wo.reshape(-1, 3), alpha)
    f = f.reshape(wo.shape[:-1]) * np.cos(T) * np.sin(T)
    bins = np.einsum("ijab,ia,jb->ij", f, wt, wp_)
    return bins / _ggx_albedo(round(float(wi[2]), 12), alpha)


class StatisticalBSDF:
    """Belcour's statistical model of a scene, with the evaluation interface of
    :class:`layersim.BSDF` (``eval``, ``albedo``, ``bin_energies``, ``specular``).

    Parameters
    ----------
    scene : Scene, dict or path
        GGX interfaces and absorbing media (:func:`~layersim.statistical.stack.
        statistical_stacks` says what is refused).
    """

    def __init__(self, scene):
        from ..scene import as_scene
        self.scene = as_scene(scene, "StatisticalBSDF")
        self._stacks = statistical_stacks(self.scene)
        self.info = {"model": "Belcour 2018 statistical model (Bati et al. 2021 variant)"}

    @property
    def channels(self) -> int:
        return len(self._stacks)

    @property
    def opaque(self) -> bool:
        return self.scene.opaque

    @functools.lru_cache(maxsize=256)
    def _stats(self, mu: float):
        return [add_stack(s, mu, self.scene.top_ior) for s in self._stacks]

    def lobes(self, theta_i: float) -> list[Lobe]:
        """The lobes at incidence ``theta_i`` (radians from the normal, in ``[0, pi/2)``), top
        first; interfaces no light reaches have none.

        Raises
        ------
        TypeError, ValueError
            For an angle that is not one real number in ``[0, pi/2)``
            (:func:`incidence_cosine`).
        InfeasibleError
            Where the model has no finite lobe width: near grazing incidence the variance of
            light refracted back out through an interface diverges (Belcour 2018's
            transmission variance grows without bound as the refracted direction nears the
            horizon), and the lobes below it are undefined (NaN) in the model.
        """
        return self._lobes(incidence_cosine(theta_i))

    def _lobes(self, mu: float) -> list[Lobe]:
        stats = self._stats(mu)
        count = min(len(st.lobes) for st in stats)
        out = []
        for j in range(count):
            e = np.array([st.lobes[j][0] for st in stats])
            v = np.array([st.lobes[j][1] for st in stats])
            layer = stats[0].lobes[j][2]
            if np.any(np.isnan(v)):
                raise InfeasibleError(
                    f"Belcour's statistical model has no finite width for the lobe of layer "
                    f"{layer} at theta_i = {math.degrees(math.acos(mu)):.4g} deg: the variance "
                    "of the light refracted back out through the layers above diverges near "
                    "grazing incidence; use a smaller angle or the exact solve "
                    "(layersim.solve)")
            out.append(Lobe(e, v, np.array([roughness(x) for x in v]), layer))
        return out

    def _squeeze(self, x):
        x = np.asarray(x, dtype=np.float64)
        return x[..., 0] if self.channels == 1 else x

    @staticmethod
    def _above(wi: np.ndarray) -> np.ndarray:
        """``wi`` (validated unit vectors) checked to lie above the surface."""
        if np.any(wi[..., 2] <= 0):
            raise ValueError("the statistical model is lit from above only (wi.z > 0)")
        return wi

    def _check(self, wi):
        """``wi`` as unit vectors (..., 3) above the surface (as :class:`layersim.BSDF`
        takes them: :func:`layersim.solved.directions.unit_directions`)."""
        return self._above(unit_directions("wi", wi))

    def eval(self, wi, wo) -> np.ndarray:
        """Sum of the rough lobes, 1/sr without the cosine, shape ``(...)`` (``(..., 3)`` RGB);
        ``wi`` and ``wo`` are unit vectors (..., 3), broadcast together, ``wi.z > 0``."""
        from ..kernels.fgd import ggx_lobe
        fi, fo, shape = direction_pairs(wi, wo)
        self._above(fi)
        out = np.zeros((fi.shape[0], self.channels))
        for mu in np.unique(np.round(fi[:, 2], 12)):
            sel = np.round(fi[:, 2], 12) == mu
            for lobe in self._lobes(float(mu)):
                for c in range(self.channels):
                    a = float(lobe.roughness[c])
                    if a <= 0.0 or lobe.energy[c] <= 0.0:
                        continue
                    out[sel, c] += (lobe.energy[c] / _ggx_albedo(float(mu), a)
                                    * ggx_lobe(fi[sel], fo[sel], a))
        return self._squeeze(out.reshape(shape + (self.channels,)))

    def specular(self, wi) -> dict:
        """Mirror deltas of smooth lobes: ``{"top": (energy, wo), "bottom": (0, -wi)}``."""
        wi = self._check(wi)
        e = np.zeros(wi.shape[:-1] + (self.channels,))
        for idx in np.ndindex(wi.shape[:-1]):
            for lobe in self._lobes(round(float(wi[idx][2]), 12)):
                e[idx] += np.where(lobe.roughness <= 0.0, lobe.energy, 0.0)
        mirror = wi * np.array([-1.0, -1.0, 1.0])
        return {"top": (self._squeeze(e), mirror),
                "bottom": (self._squeeze(np.zeros_like(e)), -wi)}

    def albedo(self, wi):
        """``(R, T)``: the model's total reflected energy (sum of its lobes) and the energy it
        transmits through the stack (0 for an opaque stack)."""
        wi = self._check(wi)
        R = np.zeros(wi.shape[:-1] + (self.channels,))
        T = np.zeros_like(R)
        for idx in np.ndindex(wi.shape[:-1]):
            stats = self._stats(round(float(wi[idx][2]), 12))
            R[idx] = [st.R0i for st in stats]
            T[idx] = [0.0 if (st.cos is None or self.opaque) else st.T0i for st in stats]
        return self._squeeze(R), self._squeeze(T)

    def bin_energies(self, wi, mu_edges, phi_edges) -> dict:
        """Energy leaving into each ``(mu, phi)`` bin of the top side (the lobes integrated
        with :func:`lobe_bins`; a smooth lobe lands in its mirror direction's bin); the bottom
        side is zeros (the model has no transmitted distribution)."""
        wi = self._check(wi)
        mu_edges, phi_edges = bin_arguments(wi, mu_edges, phi_edges)
        top = np.zeros((mu_edges.size - 1, phi_edges.size - 1, self.channels))
        mirror = np.array([-wi[0], -wi[1], wi[2]])
        phi_m = np.mod(np.arctan2(mirror[1], mirror[0]), 2 * np.pi)
        i_m = min(max(np.searchsorted(mu_edges, mirror[2], "right") - 1, 0), mu_edges.size - 2)
        j_m = min(max(np.searchsorted(phi_edges, phi_m, "right") - 1, 0), phi_edges.size - 2)
        for lobe in self._lobes(round(float(wi[2]), 12)):
            for c in range(self.channels):
                a = float(lobe.roughness[c])
                if a <= 0.0:
                    top[i_m, j_m, c] += lobe.energy[c]
                else:
                    top[..., c] += lobe.energy[c] * lobe_bins(wi, a, mu_edges, phi_edges)
        return {"top": self._squeeze(top), "bottom": self._squeeze(np.zeros_like(top))}


def lobes(scene, theta_i: float) -> list[Lobe]:
    """Belcour's statistical lobes of ``scene`` at incidence ``theta_i`` (radians from the
    normal, in ``[0, pi/2)``): a list, top first, of :class:`Lobe` with ``energy`` and
    ``roughness`` per channel. Raises as :meth:`StatisticalBSDF.lobes`; the angle is checked
    before the scene is read."""
    incidence_cosine(theta_i)
    return StatisticalBSDF(scene).lobes(theta_i)
