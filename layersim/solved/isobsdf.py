"""Evaluation, energy fractions and bin energies of solved isotropic stacks.

:class:`layersim.solved.bsdf.BSDF` evaluates a channel whose operator is an
:class:`~layersim.operators.operator.IsoOperator` with an :class:`IsoEvaluator` (the registry
:data:`layersim.solved.bsdf.EVALUATORS`). Conventions are those of :mod:`layersim.solved.bsdf`:
``mu_in = wi.z``, ``mu_out = -wo.z``, ``dphi = phi(wo) - phi(wi) - pi``.

* ``eval``: cubic spline interpolation of the coefficients between ordinates and the cosine
  series in ``dphi`` (:mod:`layersim.kernels.fourier_eval`);
* ``albedo``: the discretisation's own quadrature at the ordinates, interpolated linearly in the
  incident elevation;
* ``bins``: the spline interpolant integrated exactly in elevation and analytically in azimuth,
  scaled to the quadrature's energy of the same (smooth) part; the unscattered beam goes to the
  forward bin.
"""

from __future__ import annotations

import math

import numpy as np

from .evaluator import Evaluator
from .directions import azimuth
from ..operators.interpolation import (bin_quadrature, block_taps, closed_bin, hat_weights,
                                       side_energies, spline_weights)
from ..kernels import fourier_eval
from ..operators.operator import BLOCKS, order_weight

_BLOCK_ID = {name: k for k, name in enumerate(BLOCKS)}


class SeriesTable:
    """All blocks of one operator as per-pair cosine series (see
    :mod:`layersim.kernels.fourier_eval`), unscattered deltas removed from the diagonals."""

    def __init__(self, op):
        h = op.h
        fw = op.grid.flux_weight
        self.h = h
        counts = np.zeros(len(BLOCKS) * h * h, np.int64)
        entries = []
        for b, name in enumerate(BLOCKS):
            blk = op.blocks[name]
            if blk is None:
                continue
            delta = op.delta.get(name)
            for l, mat in enumerate(blk):
                coo = mat.tocoo()
                vals = coo.data / (order_weight(l) * fw[coo.col])
                if delta is not None:
                    diag = coo.row == coo.col
                    vals = vals.copy()
                    vals[diag] -= delta[coo.row[diag]] / (order_weight(l) * fw[coo.row[diag]])
                p = b * h * h + coo.row.astype(np.int64) * h + coo.col
                entries.append((p, np.full(p.size, l, np.int64), vals))
        if entries:
            p = np.concatenate([e[0] for e in entries])
            l = np.concatenate([e[1] for e in entries])
            v = np.concatenate([e[2] for e in entries])
            np.maximum.at(counts, p, l + 1)
        else:
            p = l = np.zeros(0, np.int64)
            v = np.zeros(0)
        self.offsets = np.zeros(counts.size + 1, np.int64)
        np.cumsum(counts, out=self.offsets[1:])
        self.coef = np.zeros(int(self.offsets[-1]))
        self.coef[self.offsets[p] + l] = v

    def base(self, name: str) -> int:
        return _BLOCK_ID[name] * self.h * self.h


class IsoEvaluator(Evaluator):
    """Evaluation of one isotropic operator (one channel of a BSDF); directions are validated,
    flattened arrays (Q, 3) in the public convention.

    Parameters
    ----------
    op : IsoOperator
    """

    table_class = SeriesTable

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """f(wi, wo) (1/sr), shape (Q,)."""
        mu_in, mu_out = wi[:, 2], -wo[:, 2]
        dphi = azimuth(wo) - azimuth(wi) - np.pi
        table = self.table
        out = np.zeros(mu_in.size)
        for sel, pair, weight in block_taps(self.op, table, mu_in, mu_out):
            out[sel] = fourier_eval.eval_series(table.offsets, table.coef, pair, weight,
                                                dphi[sel])
        return out

    def node_energy(self, name: str, weight: np.ndarray | None = None,
                    wi: np.ndarray | None = None) -> np.ndarray:
        """Energy fraction per incident node through block ``name`` (order 0 + delta), each
        outgoing node counted with ``weight`` (h,) (default 1; :mod:`layersim.solved.boundary`
        passes the transmittance of a smooth boundary); the same for every incident azimuth, so
        ``wi`` is not used. Shape (h,)."""
        op = self.op
        fw = op.grid.flux_weight
        blk = op.blocks[name]
        if blk is None:
            return np.zeros(op.h)
        return (blk[0].T @ (fw if weight is None else weight * fw)) / fw

    def albedo(self, wi: np.ndarray):
        """(R, T), each (Q,)."""
        return side_energies(wi[:, 2], self.op.grid.mu,
                             lambda name, q: self.node_energy(name))

    def bins(self, wi: np.ndarray, mu_edges: np.ndarray, phi_edges: np.ndarray,
             exits: dict | None = None, deltas: bool = True, taps=None) -> dict:
        """Bin energies for one incident direction ``wi`` (3,) (see
        :meth:`layersim.solved.bsdf.BSDF.bin_energies`).

        ``exits`` (optional, per side ``"top"`` / ``"bottom"``) replaces the elevation
        integral of a side by an object with ``points(edges) -> (mu, weight, bin)`` (points in
        the operator's cosines, weights including ``mu dmu``) and ``weight(mu)``, the fraction
        of the radiance at ``mu`` that leaves (:class:`layersim.solved.boundary.Exit`).
        ``deltas=False`` leaves the delta parts out; ``taps`` (two arrays of 4) replaces the linear
        interpolation weights of the incident elevation."""
        op = self.op
        grid = op.grid
        mu_in = wi[2]
        phi_in = math.atan2(wi[1], wi[0])
        ii, wi_ = hat_weights(grid.mu, np.array([abs(mu_in)])) if taps is None else taps
        ii, wi_ = ii[0], wi_[0]
        exits = exits or {}
        # phi integrals of cos(l (phi_o - phi_in - pi)) over each phi bin
        m = op.m
        l = np.arange(m)[:, None]
        a = phi_edges[None, :] - phi_in - np.pi
        with np.errstate(divide="ignore", invalid="ignore"):
            prim = np.where(l == 0, a, np.sin(l * a) / np.where(l == 0, 1, l))
        phi_int = np.diff(prim, axis=1)                                  # (m, n_phi)
        top_from = ("Rt", "Ttb") if mu_in > 0 else ("Tbt", "Rb")
        out = {}
        for side, name in zip(("top", "bottom"), top_from):
            E = np.zeros((mu_edges.size - 1, phi_edges.size - 1))
            blk = op.blocks[name]
            if blk is not None:
                ex = exits.get(side)
                if ex is None:
                    pts, gw, bin_of = bin_quadrature(grid.mu, mu_edges)
                    gw = gw * pts
                    full_pts, full_w, _ = bin_quadrature(grid.mu, np.array([0.0, 1.0]))
                    full_w = full_w * full_pts
                    g = np.ones(grid.h)
                else:
                    pts, gw, bin_of = ex.points(mu_edges)
                    full_pts, full_w, _ = ex.points(np.array([0.0, 1.0]))
                    g = ex.weight(grid.mu)
                io, wo_ = spline_weights(grid.mu, pts)
                full_io, full_wo = spline_weights(grid.mu, full_pts)
                fw = grid.flux_weight
                delta = op.delta.get(name)
                # F[l, a] = sum_b w_b f_l(a, b): incident interpolation, then elevation integral
                F = np.empty((m, grid.h))
                for order, mat in enumerate(blk):
                    col = mat[:, ii].toarray() / (order_weight(order) * fw[ii])[None, :]
                    if delta is not None:
                        col[ii, np.arange(4)] -= delta[ii] / (order_weight(order) * fw[ii])
                    F[order] = col @ wi_
                vals = np.einsum("pk,lpk->lp", wo_, F[:, io])            # (m, points)
                M = np.zeros((m, mu_edges.size - 1))
                np.add.at(M.T, bin_of, (vals * gw[None, :]).T)
                E = M.T @ phi_int
                # scale to the quadrature's energy of the same (smooth) part
                interp = np.sum(np.einsum("pk,pk->p", full_wo, F[0][full_io]) * full_w)
                quad = np.sum(F[0] * g * fw)
                if interp != 0.0:
                    E *= quad / interp
                if delta is not None and deltas:
                    energy = float(np.dot(wi_, delta[ii]))
                    kmu = closed_bin(mu_edges, abs(mu_in))
                    kphi = closed_bin(phi_edges, (phi_in + np.pi) % (2 * np.pi))
                    if kmu is not None and kphi is not None:
                        E[kmu, kphi] += energy
            out[side] = E
        return out
