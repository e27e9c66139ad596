"""Smooth dielectric boundaries of a stack, applied where the BSDF is evaluated.

A stack whose top (or bottom) interface is smooth is solved on the Snell-matched grid
(:func:`layersim.operators.quadrature.snell_matched`) in the directions just inside that boundary,
with the boundary's internal reflection in the blocks (:func:`layersim.ingredients.smooth.
boundary_reflector`); the BSDF's ``boundary[side]`` records the index outside. Refraction maps an
outside cosine ``x`` to ``mu = sqrt(1 - (1 - x^2) / eta^2)`` (``eta`` = inside / outside) and
keeps the azimuth; the grid's nodes in the escape cone are exactly the images of a quadrature in
``x``, so that every sum over what leaves is that quadrature's sum. In the radiance convention
(``docs/conventions.md``) light that enters through a boundary and leaves through one sees::

    f(wi, wo) = (1 - F(x_i)) (1 - F(x_o)) / eta_o^2  f_inside(mu_i, mu_o, phi)

``eta_o`` the relative index of the boundary it leaves through (1 on a side without a
boundary, where the factor ``(1 - F)`` is 1 too), plus the boundary's own mirror reflection
``F(x_i)``, a delta. Energies use ``1 - F`` without the ``eta^2`` (radiance is compressed into
the smaller solid angle). :class:`BoundaryEvaluator` wraps the evaluator of the inside
operator with these factors. A near-specular rough boundary (the BSDF's ``lobes``,
:mod:`layersim.solved.lobe`) replaces ``1 - F`` by its rough transmittance and the mirror reflection
by its microfacet reflection lobe. A lobe on a side without a boundary (a bare near-specular
conductor) replaces the operator's own delta reflection on that side.
"""

from __future__ import annotations

import math

import numpy as np

from ..operators.interpolation import bin_quadrature, closed_bin, hat_weights, spline_weights
from ..kernels.fresnel import fresnel
from .lobe import NearSpecularLobe


class Exit:
    """Leaving through one smooth boundary of relative index ``eta`` (inside / outside > 1):
    the elevation integral of bins in the outside cosine (:meth:`points`) and the transmittance
    of inside radiance at ``mu`` (:meth:`weight`)."""

    def __init__(self, eta: float, nodes: np.ndarray, lobe: NearSpecularLobe | None = None):
        self.eta = float(eta)
        self.lobe = lobe
        self.mu_c = math.sqrt(1.0 - 1.0 / self.eta**2)
        # outside images of the escaping nodes: the pieces of the inside spline
        self.x_nodes = self.outside(nodes[nodes > self.mu_c])

    def inside(self, x):
        """Inside cosine of the outside cosine ``x`` (>= 0)."""
        return np.sqrt(1.0 - (1.0 - np.asarray(x, float) ** 2) / self.eta**2)

    def outside(self, mu):
        """Outside cosine of the inside cosine ``mu`` (0 under total internal reflection)."""
        return np.sqrt(np.clip(1.0 - self.eta**2 * (1.0 - np.asarray(mu, float) ** 2), 0, 1))

    def transmittance(self, x) -> np.ndarray:
        """``1 - F`` at outside cosines ``x`` (a near-specular boundary: its rough
        transmittance, :meth:`layersim.solved.lobe.NearSpecularLobe.transmittance`)."""
        if self.lobe is not None:
            return self.lobe.transmittance(x)
        return 1.0 - fresnel(np.asarray(x, float), self.eta)

    def leaving(self, mu) -> np.ndarray:
        """Fraction of the power of inside radiance at ``mu`` (> mu_c) that leaves: the
        transmittance at its outside image (reciprocity)."""
        return self.transmittance(self.outside(mu))

    def weight(self, mu) -> np.ndarray:
        """Fraction of the power of inside radiance at ``mu`` that leaves (0 below mu_c)."""
        mu = np.asarray(mu, float)
        return np.where(mu > self.mu_c, self.leaving(mu), 0.0)

    def points(self, edges: np.ndarray):
        """Inside cosines, weights ``(1 - F(x)) mu dmu = (1 - F(x)) x dx / eta^2`` and bins of
        the integral over the outside elevation bins ``edges``: exact in ``x`` (Gauss-Legendre
        between the images of the nodes)."""
        x, w, b = bin_quadrature(self.x_nodes, edges)
        mu = self.inside(x)
        return mu, w * x * self.leaving(mu) / self.eta**2, b

    def to_inside(self, w: np.ndarray) -> np.ndarray:
        """Public directions (Q, 3) on this side, refracted to the inside (same azimuth)."""
        z = np.sign(w[:, 2]) * self.inside(np.abs(w[:, 2]))
        return np.concatenate([w[:, :2] / self.eta, z[:, None]], axis=1)

    def to_outside(self, w: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`to_inside` (directions inside the escape cone)."""
        z = np.sign(w[:, 2]) * self.outside(np.abs(w[:, 2]))
        return np.concatenate([w[:, :2] * self.eta, z[:, None]], axis=1)


class BoundaryEvaluator:
    """Evaluation of an operator with smooth boundaries, wrapping the evaluator ``inner`` of
    its inside blocks; same interface as :class:`layersim.solved.isobsdf.IsoEvaluator`.

    Parameters
    ----------
    op : layersim.operators.operator.Operator
        The stack's operator, its blocks inside the boundaries.
    inner : evaluator
        The evaluator of ``op`` (:data:`layersim.solved.bsdf.EVALUATORS`).
    boundary : dict
        ``{"top" | "bottom": index of the medium outside}``
        (:attr:`layersim.solved.bsdf.BSDF.boundary`).
    lobes : dict
        ``{"top": parameters of a NearSpecularLobe}`` or empty
        (:attr:`layersim.solved.bsdf.BSDF.lobes`).
    """

    def __init__(self, op, inner, boundary: dict, lobes: dict):
        self.op = op
        self.inner = inner
        eta_in = {"top": op.eta_top, "bottom": op.eta_bottom}
        self.lobes = {side: NearSpecularLobe(**p) for side, p in lobes.items()}
        self.exits = {side: Exit(eta_in[side] / outside, op.grid.mu, self.lobes.get(side))
                      for side, outside in boundary.items()}

    @property
    def table(self):
        return self.inner.table

    def _side(self, w):
        return np.where(w[:, 2] > 0, "top", "bottom")

    def _map(self, w: np.ndarray):
        """Inside directions of ``w`` (Q, 3) and the boundary's ``1 - F`` (1 off boundaries;
        a near-specular boundary's transmitted energy, :mod:`layersim.solved.lobe`)."""
        w_in, t = w.copy(), np.ones(w.shape[0])
        for side, ex in self.exits.items():
            sel = self._side(w) == side
            if sel.any():
                w_in[sel] = ex.to_inside(w[sel])
                # a near-specular boundary: its transmitted energy in this very direction
                # (it depends on the azimuth where the roughness is anisotropic)
                t[sel] = (ex.transmittance(np.abs(w[sel, 2])) if ex.lobe is None else
                          ex.lobe.energies(w[sel])[1])
        return w_in, t

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        wi_in, ti = self._map(wi)
        wo_in, to = self._map(wo)
        scale = np.ones(wo.shape[0])
        for side, ex in self.exits.items():
            scale[self._side(wo) == side] = 1.0 / ex.eta**2
        f = self.inner.eval(wi_in, wo_in) * ti * to * scale
        lobe = self.lobes.get("top")
        return f if lobe is None else f + lobe.eval(wi, wo)

    def _weight(self, name: str):
        """Transmittance of the boundary that block ``name`` leaves through, per node (None:
        no boundary on that side)."""
        side = "top" if name in ("Rt", "Tbt") else "bottom"
        ex = self.exits.get(side)
        return None if ex is None else ex.weight(self.op.grid.mu)

    def _taps(self, wi: np.ndarray):
        """Interpolation taps (Q, 4) of the incident elevation into the nodes. On a side with
        a boundary: cubic (:func:`~layersim.operators.interpolation.spline_weights`) in the outside
        cosine between the images of the escaping nodes, since what the stack does is smooth in
        it (Fresnel factors and path lengths are), and linear interpolation there is the
        largest error against Monte Carlo (docs/performance.md). Elsewhere linear in ``mu``.
        Every energy (smooth part and delta) uses
        the same taps, whose weights sum to 1, so that energy is conserved where the nodes
        conserve it."""
        mu = self.op.grid.mu
        idx, w = hat_weights(mu, np.abs(wi[:, 2]))
        for side, ex in self.exits.items():
            sel = np.flatnonzero(self._side(wi) == side)
            if sel.size:
                escape = np.flatnonzero(mu > ex.mu_c)
                k, ws = spline_weights(ex.x_nodes, np.abs(wi[sel, 2]))
                idx[sel], w[sel] = escape[k], ws
        return idx, w

    def _energies(self, wi: np.ndarray, delta: bool):
        """Per query, the energies that leave through the same side and the other side of the
        inside blocks: all (``delta=False``) or the delta parts only, before the incident
        boundary's transmittance."""
        idx, w = self._taps(wi)
        wi_in, _ = self._map(wi)
        top = wi[:, 2] > 0
        same, other = np.zeros(wi.shape[0]), np.zeros(wi.shape[0])
        for sel, rname, tname in ((top, "Rt", "Ttb"), (~top, "Rb", "Tbt")):
            for out, name in ((same, rname), (other, tname)):
                if self.op.blocks[name] is None or not sel.any():
                    continue
                g = self._weight(name)
                if delta:
                    e = self.op.delta.get(name)
                    if e is None:
                        continue
                    e = e if g is None else e * g
                else:       # (h,), or (Q, h) where it depends on the incident azimuth
                    e = self.inner.node_energy(name, g, wi_in[sel])
                e = np.broadcast_to(e, (int(sel.sum()), e.shape[-1]))
                out[sel] = np.sum(w[sel] * np.take_along_axis(e, idx[sel], axis=1), axis=1)
        return same, other

    def _own_delta(self, wi: np.ndarray) -> np.ndarray:
        """Per query, the delta reflection that a lobe on a side without a boundary replaces
        (0 elsewhere)."""
        own = np.zeros(wi.shape[0])
        bare = [side for side in self.lobes if side not in self.exits]
        if bare:
            same, _ = self._energies(wi, delta=True)
            for side in bare:
                sel = (wi[:, 2] > 0) == (side == "top")
                own[sel] = same[sel]
        return own

    def albedo(self, wi: np.ndarray):
        _, ti = self._map(wi)
        R, T = self._energies(wi, delta=False)
        R = R - self._own_delta(wi)
        # the boundary's own reflection: the mirror's F, or a near-specular lobe's energy
        own = 1.0 - ti
        lobe = self.lobes.get("top")
        top = wi[:, 2] > 0
        if lobe is not None and top.any():
            own[top] = lobe.energies(wi[top])[0]
        # cubic weights can undershoot where an energy vanishes: clipped there
        return np.maximum(R * ti + np.where(top, own, 1.0 - ti), 0.0), np.maximum(T * ti, 0.0)

    def specular(self, wi: np.ndarray) -> dict:
        wi_in, ti = self._map(wi)
        same, other = (np.maximum(e, 0.0) for e in self._energies(wi, delta=True))
        same = same - np.maximum(self._own_delta(wi), 0.0)
        top = wi[:, 2] > 0
        mirror = wi * np.array([-1.0, -1.0, 1.0])
        out = {}
        for side, is_same in (("top", top), ("bottom", ~top)):
            energy = np.where(is_same, same, other) * ti
            # inside directions: mirror image, or straight on
            wo = np.where(is_same[:, None], wi_in * np.array([-1.0, -1.0, 1.0]), -wi_in)
            ex = self.exits.get(side)
            if ex is not None:
                wo = ex.to_outside(wo)
            if ex is not None and side not in self.lobes:   # the boundary's own mirror
                wo = np.where(is_same[:, None], mirror, wo)
                energy = energy + np.where(is_same, 1.0 - ti, 0.0)
            out[side] = (energy, wo)
        return out

    def bins(self, wi: np.ndarray, mu_edges: np.ndarray, phi_edges: np.ndarray) -> dict:
        wi_in, ti = self._map(wi[None, :])
        out = self.inner.bins(wi_in[0], mu_edges, phi_edges, exits=self.exits, deltas=False,
                              taps=self._taps(wi[None, :]))
        out = {side: E * ti[0] for side, E in out.items()}
        for side, (energy, wo) in self.specular(wi[None, :]).items():
            kmu = closed_bin(mu_edges, abs(wo[0, 2]))
            # + 0.0 turns -0.0 into 0.0: along the normal the azimuth is a convention, 0 here
            kphi = closed_bin(phi_edges,
                              math.atan2(wo[0, 1] + 0.0, wo[0, 0] + 0.0) % (2 * np.pi))
            if kmu is not None and kphi is not None and energy[0] > 0:
                out[side][kmu, kphi] += energy[0]
        for side, lobe in self.lobes.items():
            if (wi[2] > 0) == (side == "top"):
                out[side] += lobe.bins(wi, mu_edges, phi_edges)
        return out
