"""From a ``.bsdf`` table back to layersim operators: the quadrature rule of the nodes and the
operators of one channel in either representation (:meth:`FourierTable.to_bsdf`)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from ..aniso import basis
from ..aniso.operator import AnisoOperator
from ..errors import FileFormatError
from ..operators.operator import BLOCKS, Grid, IsoOperator, order_weight


def identify_grid(mu32: np.ndarray, rule: str | None) -> Grid:
    """The quadrature rule whose positive nodes are ``mu32`` (float32 precision)."""
    n = 2 * mu32.size
    rules = [rule] if rule else ["gauss-lobatto", "gauss-legendre"]
    for name in rules:
        try:
            grid = Grid.make(name, n)
        except ValueError:
            continue
        if np.max(np.abs(grid.mu - mu32)) <= 2e-7:
            return grid
    raise FileFormatError(f"the file's {mu32.size} positive nodes are not those of a "
                          f"{' or '.join(rules)} rule with n = {n}; layersim needs the "
                          "quadrature weights to rebuild the operators (FourierTable.eval "
                          "evaluates the file directly)")


def isotropic_operator(grid, ours_of, pair, order, a, present, eta_top, eta_bottom, delta):
    """An IsoOperator from the file's cosine series ``a_l = f_l |mu_o|`` of one channel: file
    ``pair`` and ``order`` ``l`` of every coefficient ``a``."""
    h = grid.h
    ours = ours_of[pair]
    sel = ours >= 0
    b, rest = np.divmod(ours[sel], h * h)
    o, i = np.divmod(rest, h)
    l = order[sel]
    m = max(int(order.max()) + 1 if order.size else 1, 1)
    vals = a[sel] / grid.mu[o] * order_weight(l) * grid.flux_weight[i]
    blocks = {}
    for k, name in enumerate(BLOCKS):
        if name not in present:
            blocks[name] = None
            continue
        mats = []
        for j in range(m):
            s = (b == k) & (l == j)
            mat = sps.csr_matrix((vals[s], (o[s], i[s])), shape=(h, h))
            if name in delta:
                mat = mat + sps.diags(np.asarray(delta[name], float), format="csr")
            mats.append(mat.tocsr())
        blocks[name] = mats
    return IsoOperator(grid, blocks, eta_top, eta_bottom, delta)


def coupled_operator(grid, ours_of, pair, s, d, c, md, present, eta_top, eta_bottom, delta):
    """An AnisoOperator from the file's complex ``c_sd = f_{d,s} |mu_o|`` of one channel (file
    ``pair``, ``s``, ``d >= 0`` of every coefficient), with at least ``md`` orders."""
    h = grid.h
    ours = ours_of[pair]
    sel = (ours >= 0) & (c != 0)                 # the boxes are dense: skip their zeros
    ours, s, d, c = ours[sel], s[sel], d[sel], c[sel]
    b, rest = np.divmod(ours, h * h)
    o, i = np.divmod(rest, h)
    f = c / grid.mu[o]
    # the d = 0 row evaluates to sum_s Re(c_s0 e^{i s phi_s}): f_{0,s} = (c_s0 + conj c_-s0) / 2
    row0 = d == 0
    f = np.where(row0, 0.5 * f, f)
    b, o, i, s, d = (np.concatenate([v, v[row0]]) for v in (b, o, i, s, d))
    s[s.size - int(row0.sum()):] *= -1
    f = np.concatenate([f, np.conj(f[row0])])
    # complex operator entries B_{l,k}/(2 pi w_i |mu_i|) of the upper half (l > 0, or l = 0 and
    # k >= 0): (d, s) itself or its conjugate (-d, -s); of the d = 0 row only s >= 0
    l, k = d + s, d - s
    upper = (l > 0) | ((l == 0) & (k >= 0))
    keep = (d > 0) | upper
    b, o, i, l, k, f, upper = (v[keep] for v in (b, o, i, l, k, f, upper))
    l, k, f = np.where(upper, l, -l), np.where(upper, k, -k), np.where(upper, f, np.conj(f))
    md = max(md, int(np.abs(np.concatenate([l, k, [0]])).max()) + 1)
    rows, cols, vals, src = basis.real_entries(l, k, f)
    vals = vals * 2.0 * np.pi * grid.flux_weight[i[src]]
    S = basis.n_slots(md)
    blocks = {}
    for n, name in enumerate(BLOCKS):
        if name not in present:
            blocks[name] = None
            continue
        e = b[src] == n
        mat = sps.csr_matrix((vals[e], (rows[e] * h + o[src][e], cols[e] * h + i[src][e])),
                             shape=(S * h, S * h))
        if name in delta:
            mat = mat + sps.diags(np.tile(np.asarray(delta[name], float), S), format="csr")
        blocks[name] = mat.tocsr()
    return AnisoOperator(grid, md, blocks, eta_top, eta_bottom, delta)
