"""Evaluation, energy fractions and bin energies of solved anisotropic stacks.

:class:`layersim.solved.bsdf.BSDF` evaluates a channel whose operator is an
:class:`~layersim.aniso.operator.AnisoOperator` with an :class:`AnisoEvaluator` (the registry
:data:`layersim.solved.bsdf.EVALUATORS`). Conventions are those of
:mod:`layersim.solved.bsdf` (one place converts public directions to the solver's):
``mu_in = wi.z``, ``mu_out = -wo.z``, and the *propagation* azimuths
``phi_i = atan2(-wi.y, -wi.x)``, ``phi_o = atan2(wo.y, wo.x)`` in the stack frame,
``phi_d = phi_o - phi_i``, ``phi_s = phi_o + phi_i``.

* ``eval``: cubic spline interpolation of the coefficients between ordinates (as for isotropic
  stacks) and the 2-D series of Zeltner & Jakob 2018 eq. (7)
  (:mod:`layersim.kernels.fourier_eval2d`).
* ``albedo``: the discretisation's own quadrature. A collimated beam from node ``i`` at
  azimuth ``phi_i`` delivers ``sum_b E[b, i] v_b(phi_i)`` (``v = (1, 2 cos k phi,
  2 sin k phi)``, :meth:`AnisoOperator.albedo_slots`): the directional albedo of an anisotropic
  stack depends on the incident azimuth through the orders ``|k| <= 2 ms`` coupled to order 0.
  Linear interpolation in the incident elevation, as for isotropic stacks.
* ``bin_energies``: spline interpolant integrated exactly in elevation and analytically in
  azimuth, scaled to the quadrature's energy of the same (smooth) part; the unscattered beam goes
  to the forward bin.
"""

from __future__ import annotations

import math

import numpy as np

from ..solved.evaluator import Evaluator
from ..operators.interpolation import (bin_quadrature, block_taps, closed_bin, hat_weights,
                                       side_energies, spline_weights)
from ..kernels import fourier_eval2d
from ..operators.operator import BLOCKS
from . import basis

_BLOCK_ID = {name: k for k, name in enumerate(BLOCKS)}


class SeriesTable2D:
    """All blocks of one operator as per-pair runs of complex ``f_{d,s}`` (layout of
    :mod:`layersim.kernels.fourier_eval2d`), unscattered deltas removed."""

    def __init__(self, op):
        h = op.h
        md = op.md
        self.h = h
        mode = basis.slot_mode(md)
        is_sin = basis.slot_is_sin(md)
        fw = op.grid.flux_weight
        P, L, K, RE, IM = [], [], [], [], []
        for b_id, name in enumerate(BLOCKS):
            if op.blocks[name] is None:
                continue
            G = op.coefficients(name).tocoo()
            g = G.data.copy()
            if name in op.delta:
                diag = G.row == G.col
                g[diag] -= op.delta[name][G.row[diag] % h] / (2.0 * np.pi * fw[G.row[diag] % h])
            a, b = G.row // h, G.col // h
            o, i = G.row % h, G.col % h
            pair = b_id * h * h + o * h + i
            la, lb, sa, sb = mode[a], mode[b], is_sin[a], is_sin[b]
            half = 0.5 * g
            m = (la > 0) & (lb > 0)
            # (l, k)
            re = np.where(sa == sb, half, 0.0)
            im = np.where(~sa & sb, half, np.where(sa & ~sb, -half, 0.0))
            P.append(pair[m]); L.append(la[m]); K.append(lb[m]); RE.append(re[m]); IM.append(im[m])
            # (l, -k)
            re = np.where(~sa & ~sb, half, np.where(sa & sb, -half, 0.0))
            im = np.where(sa != sb, -half, 0.0)
            P.append(pair[m]); L.append(la[m]); K.append(-lb[m]); RE.append(re[m]); IM.append(im[m])
            m = (la > 0) & (lb == 0)
            P.append(pair[m]); L.append(la[m]); K.append(lb[m])
            RE.append(np.where(sa[m], 0.0, half[m])); IM.append(np.where(sa[m], -half[m], 0.0))
            m = (la == 0) & (lb > 0)
            P.append(pair[m]); L.append(la[m]); K.append(lb[m])
            RE.append(np.where(sb[m], 0.0, g[m])); IM.append(np.where(sb[m], g[m], 0.0))
            m = (la == 0) & (lb == 0)
            P.append(pair[m]); L.append(la[m]); K.append(lb[m])
            RE.append(0.5 * g[m]); IM.append(np.zeros(int(m.sum())))   # f_00 stored halved
        p = np.concatenate(P) if P else np.zeros(0, np.int64)
        l = np.concatenate(L).astype(np.int64) if L else np.zeros(0, np.int64)
        k = np.concatenate(K).astype(np.int64) if K else np.zeros(0, np.int64)
        re = np.concatenate(RE) if RE else np.zeros(0)
        im = np.concatenate(IM) if IM else np.zeros(0)
        d, s = (l + k) // 2, (l - k) // 2
        keep = (re != 0.0) | (im != 0.0)
        p, d, s, re, im = p[keep], d[keep], s[keep], re[keep], im[keep]
        span = 2 * md + 1
        key = (p * span + (s + md)) * span + (d + md)
        ukey, inv = np.unique(key, return_inverse=True)
        cre = np.zeros(ukey.size)
        cim = np.zeros(ukey.size)
        np.add.at(cre, inv, re)
        np.add.at(cim, inv, im)
        up = ukey // (span * span)
        us = (ukey // span) % span - md
        ud = ukey % span - md
        # runs: one per (pair, s), dense in d (gaps filled with zeros)
        ps = up * span + (us + md)
        brk = np.flatnonzero(np.diff(ps)) + 1
        first = np.concatenate([[0], brk]) if ukey.size else np.zeros(0, np.int64)
        last = np.concatenate([brk, [ukey.size]]) - 1 if ukey.size else np.zeros(0, np.int64)
        self.run_s = us[first].astype(np.int32)
        self.run_d0 = ud[first].astype(np.int32)
        self.run_len = (ud[last] - ud[first] + 1).astype(np.int32)
        self.run_start = np.zeros(first.size, np.int64)
        if first.size:
            np.cumsum(self.run_len[:-1], out=self.run_start[1:])
        total = int(self.run_len.sum()) if first.size else 0
        self.coef_re = np.zeros(total)
        self.coef_im = np.zeros(total)
        run_of = np.repeat(np.arange(first.size), last - first + 1)
        pos = self.run_start[run_of] + (ud - self.run_d0[run_of])
        self.coef_re[pos] = cre
        self.coef_im[pos] = cim
        n_pairs = len(BLOCKS) * h * h
        self.run_offsets = np.searchsorted(up[first], np.arange(n_pairs + 1)).astype(np.int64)

    def base(self, name: str) -> int:
        return _BLOCK_ID[name] * self.h * self.h


def _prop_azimuths(wi, wo):
    phi_i = np.arctan2(-wi[:, 1], -wi[:, 0])
    phi_o = np.arctan2(wo[:, 1], wo[:, 0])
    return phi_i, phi_o


def _v(md: int, phi) -> np.ndarray:
    """Incident weights ``v_b(phi)`` = (1, 2 cos k phi, 2 sin k phi), shape (S,) + phi.shape."""
    phi = np.asarray(phi, float)
    mode = basis.slot_mode(md)
    is_sin = basis.slot_is_sin(md)
    arg = mode.reshape((-1,) + (1,) * phi.ndim) * phi[None]
    v = np.where(is_sin.reshape((-1,) + (1,) * phi.ndim), 2.0 * np.sin(arg), 2.0 * np.cos(arg))
    v[0] = 1.0
    return v


def node_energy(op, name: str, phi_in: np.ndarray) -> np.ndarray:
    """Energy fraction through block ``name`` for a beam from each node at propagation azimuth
    ``phi_in`` (per query): shape (Q, h)."""
    E = op.albedo_slots()[name]                          # (S, h)
    return np.einsum("sh,sq->qh", E, _v(op.md, phi_in))


class AnisoEvaluator(Evaluator):
    """Evaluation of one coupled operator (one channel of a BSDF); directions are validated,
    flattened arrays (Q, 3) in the public convention.

    Parameters
    ----------
    op : AnisoOperator
    """

    table_class = SeriesTable2D

    def eval(self, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
        """f(wi, wo) (1/sr), shape (Q,)."""
        table = self.table
        mu_in, mu_out = wi[:, 2], -wo[:, 2]
        phi_i, phi_o = _prop_azimuths(wi, wo)
        out = np.zeros(mu_in.size)
        for sel, pair, weight in block_taps(self.op, table, mu_in, mu_out):
            out[sel] = fourier_eval2d.eval_series2d(table, pair, weight,
                                                     phi_o[sel] - phi_i[sel],
                                                     phi_o[sel] + phi_i[sel])
        return out

    def node_energy(self, name: str, weight: np.ndarray | None = None,
                    wi: np.ndarray | None = None) -> np.ndarray:
        """Energy fraction through block ``name`` for beams from each node at the propagation
        azimuths of ``wi`` (Q, 3): shape (Q, h); each outgoing node counted with ``weight``
        (h,) (default 1; :mod:`layersim.solved.boundary` passes a boundary's transmittance)."""
        op = self.op
        phi_in = np.arctan2(-wi[:, 1], -wi[:, 0])
        if weight is None:
            return node_energy(op, name, phi_in)
        fw = op.grid.flux_weight
        h = op.h
        E = ((op.blocks[name][:h].T @ (weight * fw)) / np.tile(fw, op.slots)).reshape(op.slots, h)
        return np.einsum("sh,sq->qh", E, _v(op.md, phi_in))

    def albedo(self, wi: np.ndarray):
        """(R, T), each (Q,), for azimuth-dependent incidence (module docstring)."""
        op = self.op
        phi_in = np.arctan2(-wi[:, 1], -wi[:, 0])
        return side_energies(wi[:, 2], op.grid.mu,
                             lambda name, q: None if op.blocks[name] is None
                             else node_energy(op, name, phi_in[q]))

    def bins(self, wi: np.ndarray, mu_edges: np.ndarray, phi_edges: np.ndarray,
             exits: dict | None = None, deltas: bool = True, taps=None) -> dict:
        """Bin energies for one incident direction ``wi`` (3,) (see
        :meth:`layersim.solved.bsdf.BSDF.bin_energies`; ``exits``, ``deltas``, ``taps`` as for
        :meth:`layersim.solved.isobsdf.IsoEvaluator.bins`)."""
        op = self.op
        grid = op.grid
        h, md, S = op.h, op.md, op.slots
        fw = grid.flux_weight
        mu_in = wi[2]
        phi_in_prop = math.atan2(-wi[1], -wi[0])
        ii, wi_ = hat_weights(grid.mu, np.array([abs(mu_in)])) if taps is None else taps
        ii, wi_ = ii[0], wi_[0]
        v = _v(md, np.array(phi_in_prop))                      # (S,)
        exits = exits or {}
        # azimuth integrals of u_a(phi_o) = 1, cos l phi, sin l phi over each phi bin
        mode = basis.slot_mode(md)[:, None].astype(float)
        is_sin = basis.slot_is_sin(md)[:, None]
        e0, e1 = phi_edges[None, :-1], phi_edges[None, 1:]
        with np.errstate(divide="ignore", invalid="ignore"):
            ci = (np.sin(mode * e1) - np.sin(mode * e0)) / mode
            si = (np.cos(mode * e0) - np.cos(mode * e1)) / mode
        phi_int = np.where(is_sin, si, ci)
        phi_int[0] = (e1 - e0)[0]
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
                    g = np.ones(h)
                else:
                    pts, gw, bin_of = ex.points(mu_edges)
                    full_pts, full_w, _ = ex.points(np.array([0.0, 1.0]))
                    g = ex.weight(grid.mu)
                io, wo_ = spline_weights(grid.mu, pts)
                full_io, full_wo = spline_weights(grid.mu, full_pts)
                G = op.coefficients(name)
                F = np.zeros((S, h))
                delta = op.delta.get(name)
                for tap, wt in zip(ii, wi_):
                    if wt == 0.0:
                        continue
                    cols = np.arange(S) * h + tap
                    sub = G[:, cols].toarray()                         # (S h, S)
                    if delta is not None:
                        for a in range(S):
                            sub[a * h + tap, a] -= delta[tap] / (2.0 * np.pi * fw[tap])
                    F += wt * (sub @ v).reshape(S, h)
                vals = np.einsum("pk,apk->ap", wo_, F[:, io])           # (S, points)
                M = np.zeros((S, mu_edges.size - 1))
                np.add.at(M.T, bin_of, (vals * gw[None, :]).T)
                E = M.T @ phi_int
                interp = 2.0 * np.pi * np.sum(np.einsum("pk,pk->p", full_wo, F[0][full_io])
                                              * full_w)
                quad = 2.0 * np.pi * np.sum(F[0] * g * fw)
                if interp != 0.0:
                    E *= quad / interp
                if delta is not None and deltas:
                    energy = float(np.dot(wi_, delta[ii]))
                    kmu = closed_bin(mu_edges, abs(mu_in))
                    kphi = closed_bin(phi_edges, (math.atan2(wi[1], wi[0]) + np.pi) % (2 * np.pi))
                    if kmu is not None and kphi is not None:
                        E[kmu, kphi] += energy
            out[side] = E
        return out
