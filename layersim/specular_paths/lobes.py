"""The lobe of a specular path: the exit wave vector's deviation, linear in the slopes.

At a facet of small slope ``sigma`` (horizontal components in the stack's frame), a propagation
direction of horizontal wave vector ``p`` leaves with ``p + c sigma`` to first order:

* reflection in gap ``a``: ``n_a d' = n_a d - 2 n_a (d.m) m`` gives ``c = 2 n_a mu_a``;
* refraction from gap ``a`` to gap ``b``: the tangential wave vector is kept along the facet,
  ``n_b d_b = n_a d_a - kappa m`` with ``kappa = n_b mu_b - n_a mu_a`` at zero slope, so
  ``c = |n_a mu_a - n_b mu_b|``

(the sign of ``c`` does not matter: slopes are even). Later events keep a deviation already
made (flat faces keep ``p``), so a path's deviation is ``Delta p = sum_e c_e R_e diag(alpha_e)
x_e`` over its near-specular events (``R_e`` the face's rotation, ``x_e`` unit-roughness slopes,
Heitz 2014), whose density :mod:`.shape` gives: Belcour 2018's addition of the variances of
narrow lobes (sec. 5, eq. 21-23), exact in shape as ``alpha -> 0`` up to the variation of the
Fresnel and Smith terms across the lobe. The ``c_e`` are evaluated at the midpoint ``p_bar =
(p_i + p_o) / 2``, which makes ``f`` reciprocal and is exact for one reflection (the
half-vector slope is ``-(wi_h + wo_h) / (mu_i + mu_o)``). The density of ``p_o`` per unit area
of wave vectors is that of ``Delta p``; since ``d^2 p = n^2 mu dOmega``, the BSDF of the path
is ``f = E n_exit^2 density(Delta p)`` (radiance convention, ``docs/conventions.md``).

For Beckmann events alone the sum is Gaussian, ``g(r) = exp(-r^2) / pi``, used in closed form.
Otherwise the radial shape depends on the events' relative scales, which vary with ``|p|``: it is
tabulated at :data:`P_NODES` values of ``|p|`` and interpolated linearly (a mixture of the two
neighbouring shapes, which the sampler draws from exactly).
"""

from __future__ import annotations

import numpy as np

from .shape import cumulative, g_of_r, radial_shape, sample_t

__all__ = ["PathLobe", "P_NODES"]

#: Values of ``|p|`` (over [0, the path's smallest gap index)) at which a shape is tabulated.
P_NODES = 9


class PathLobe:
    """The lobe of one path with near-specular events ``rough`` (``(face, what, gap_a,
    gap_b)``, :meth:`layersim.specular_paths.paths.Path.rough`) in a chain of gap indices
    ``n``."""

    def __init__(self, rough: list, n: tuple):
        self.n = np.asarray(n, float)
        self.events = rough
        gaps = {g for _, _, a, b in rough for g in (a, b)}
        self.p_max = min(self.n[g] for g in gaps) * (1.0 - 1e-9)
        self.ggx = np.array([f.distribution == "ggx" for f, *_ in rough])
        self.p_nodes = np.linspace(0.0, self.p_max * (1.0 - 1e-6), P_NODES)
        self.h = np.stack([radial_shape(b, self.ggx) for b in self._beta(self.p_nodes)])
        self.C = cumulative(self.h)
        # Beckmann events only: the sum is exactly Gaussian, evaluated and drawn in closed
        # form (the table, linear in t, is coarse in a Gaussian's far tail)
        self.gaussian = not self.ggx.any()

    def _scales(self, pn: np.ndarray) -> np.ndarray:
        """The ``c_e`` (Q, E) at ``|p|`` values ``pn`` (Q,)."""
        mu = np.sqrt(np.clip(1.0 - (pn[:, None] / self.n[None, :]) ** 2, 0.0, 1.0))
        out = []
        for _, what, a, b in self.events:
            if what == "R":
                out.append(2.0 * self.n[a] * mu[:, a])
            else:
                out.append(np.abs(self.n[a] * mu[:, a] - self.n[b] * mu[:, b]))
        return np.stack(out, axis=1)

    def _beta(self, pn: np.ndarray) -> np.ndarray:
        c = self._scales(pn)
        tr = np.array([f.alpha_u ** 2 + f.alpha_v ** 2 for f, *_ in self.events])
        m = c ** 2 * tr[None, :]
        return np.sqrt(m / np.maximum(m.sum(axis=1, keepdims=True), 1e-300))

    def matrix(self, p: np.ndarray) -> np.ndarray:
        """The summed scale matrix ``M = sum_e c_e^2 R_e diag(alpha_e^2) R_e^T`` (Q, 2, 2)
        at wave vectors ``p`` (Q, 2)."""
        c = self._scales(np.linalg.norm(p, axis=1))
        M = np.zeros((p.shape[0], 2, 2))
        for e, (f, *_rest) in enumerate(self.events):
            cr, sr = np.cos(f.rotation), np.sin(f.rotation)
            R = np.array([[cr, -sr], [sr, cr]])
            A = R @ np.diag([f.alpha_u ** 2, f.alpha_v ** 2]) @ R.T
            M += (c[:, e] ** 2)[:, None, None] * A[None]
        return M

    def mixture(self, pn: np.ndarray):
        """The shape node below each ``|p|`` (Q,) and the weight of the node above it."""
        x = np.clip(pn / self.p_nodes[-1], 0.0, 1.0) * (P_NODES - 1)
        j = np.minimum(np.floor(x).astype(int), P_NODES - 2)
        return j, x - j

    def density(self, dp: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Density (per unit area of wave vectors) of ``Delta p`` (Q, 2) for a lobe whose
        scales are taken at ``p`` (Q, 2): the mixture of the two shapes around ``|p|``; 0
        where ``|p|`` is beyond the path's gaps."""
        pn = np.linalg.norm(p, axis=1)
        M = self.matrix(p)
        det = np.maximum(M[:, 0, 0] * M[:, 1, 1] - M[:, 0, 1] ** 2, 1e-300)
        r2 = (M[:, 1, 1] * dp[:, 0] ** 2 - 2 * M[:, 0, 1] * dp[:, 0] * dp[:, 1]
              + M[:, 0, 0] * dp[:, 1] ** 2) / det
        if self.gaussian:
            g = np.exp(-r2) / np.pi
        else:
            j, a = self.mixture(pn)
            g = (1.0 - a) * g_of_r(self.h, r2, j) + a * g_of_r(self.h, r2, j + 1)
        return np.where(pn < self.p_max, g / np.sqrt(det), 0.0)

    def whiten_root(self, p: np.ndarray) -> np.ndarray:
        """``M^(1/2)`` (Q, 2, 2), mapping whitened coordinates to ``Delta p``."""
        w, V = np.linalg.eigh(self.matrix(p))
        return V @ (np.sqrt(np.maximum(w, 0.0))[:, :, None] * np.swapaxes(V, 1, 2))

    def sample(self, p: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``Delta p`` (Q, 2) drawn from the lobe at ``p`` (Q, 2) with uniforms ``u`` (Q, 3):
        the shape node by ``u[:, 0]`` (the mixture of :meth:`shape`), ``t`` by ``u[:, 1]``,
        the azimuth by ``u[:, 2]``."""
        if self.gaussian:
            r = np.sqrt(-np.log1p(-np.minimum(u[:, 1], 1.0 - 1e-16)))
        else:
            j, a = self.mixture(np.linalg.norm(p, axis=1))
            j = j + (u[:, 0] < a)
            t = sample_t(self.h, self.C, j, u[:, 1])
            r = np.sqrt(t / (1.0 - t))
        phi = 2.0 * np.pi * u[:, 2]
        x = np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)
        return np.einsum("qij,qj->qi", self.whiten_root(p), x)
