"""Bin energies of one specular path: traced where its quadrature nodes are dense, ``eval``
integrated over the bin where they are sparse.

The traced nodes of :func:`.trace.trace_path` resolve the core of a lobe, but a bin in its far
tail (a GGX lobe's ``r^-4`` tail reaches bins 0.1 away) receives few of them: there the bin's
energy is the integral of the path's own ``f |mu| dOmega`` over the bin (Gauss-Legendre in
``|cos theta_o|`` and ``phi_o``, :data:`BIN_RULE` and twice as many nodes per axis), which is
smooth away from the core, wherever the two rules agree (:data:`AGREE`). A bin is traced if it
holds at least :data:`DENSE` nodes or its rules disagree (a lobe's flank crosses it).
"""

from __future__ import annotations

import numpy as np

from .trace import trace_path

__all__ = ["path_bins", "direction_bin", "DENSE", "BIN_RULE"]

#: A bin holding at least this many traced nodes takes the traced energy.
DENSE = 256
#: Gauss-Legendre nodes per bin and axis of the integral of ``f`` over a sparse bin (and
#: twice as many: the integral is used where the two agree within :data:`AGREE`).
BIN_RULE = 12
AGREE = 0.02


def direction_bin(wo: np.ndarray, mu_edges, phi_edges):
    """The bin ``(i, j)`` of one direction (3,), or ``(None, None)`` outside the edges."""
    mu = abs(wo[2])
    phi = np.arctan2(wo[1] + 0.0, wo[0] + 0.0) % (2 * np.pi)   # + 0.0: -0.0 is azimuth 0
    i = np.searchsorted(mu_edges, mu, side="right") - 1
    j = np.searchsorted(phi_edges, phi, side="right") - 1
    if mu == mu_edges[-1]:
        i -= 1
    if not (0 <= i < mu_edges.size - 1 and 0 <= j < phi_edges.size - 1):
        return None, None
    return i, j


def _traced(model, x, p, count: int, mu_edges, phi_edges):
    """Traced energy (n_mu, n_phi, C) and node count (n_mu, n_phi) per bin."""
    po, w = trace_path(model, x, p, count)
    wo = model.exit_direction(po, x.path.exit_top)
    keep = np.linalg.norm(wo, axis=1) > 0
    mu = np.abs(wo[keep, 2])
    # (+ 0.0: a direction along the normal has azimuth 0, not pi from -0.0)
    phi = np.arctan2(wo[keep, 1] + 0.0, wo[keep, 0] + 0.0) % (2 * np.pi)
    n, _, _ = np.histogram2d(mu, phi, bins=[mu_edges, phi_edges])
    E = np.stack([np.histogram2d(mu, phi, bins=[mu_edges, phi_edges],
                                 weights=w[keep, c] / count)[0]
                  for c in range(w.shape[1])], axis=-1)
    return E, n


def _integrated(model, x, p, cells, mu_edges, phi_edges, rule: int) -> np.ndarray:
    """``int f |mu| dOmega`` (K, C) of the path over the bins ``cells`` (K, 2), with
    ``rule`` Gauss-Legendre nodes per axis."""
    g, gw = np.polynomial.legendre.leggauss(rule)
    g, gw = 0.5 * (g + 1.0), 0.5 * gw
    i, j = cells[:, 0], cells[:, 1]
    m0, dm = mu_edges[i], np.diff(mu_edges)[i]
    f0, df = phi_edges[j], np.diff(phi_edges)[j]
    mu = (m0[:, None, None] + dm[:, None, None] * g[None, :, None]) * np.ones((1, 1, g.size))
    phi = (f0[:, None, None] + df[:, None, None] * g[None, None, :]) * np.ones((1, g.size, 1))
    w = (dm * df)[:, None, None] * gw[None, :, None] * gw[None, None, :]
    st = np.sqrt(np.clip(1.0 - mu ** 2, 0.0, 1.0))
    n = model.n_side(x.path.exit_top)
    po = n * np.stack([st * np.cos(phi), st * np.sin(phi)], axis=-1).reshape(-1, 2)
    pi = np.broadcast_to(p, po.shape)
    f = model.eval_path(x, pi, po) * (mu * w).reshape(-1, 1)
    return f.reshape(cells.shape[0], -1, f.shape[-1]).sum(axis=1)


def path_bins(model, x, p: np.ndarray, count: int, mu_edges, phi_edges) -> np.ndarray:
    """Energy (n_mu, n_phi, C) of the path ``x`` per bin of its exit side, for light entering
    with wave vector ``p`` (2,), traced on ``count`` nodes where they are dense."""
    E, n = _traced(model, x, p, count, mu_edges, phi_edges)
    cells = np.argwhere(n < DENSE)
    if cells.size:
        a = _integrated(model, x, p, cells, mu_edges, phi_edges, BIN_RULE)
        b = _integrated(model, x, p, cells, mu_edges, phi_edges, 2 * BIN_RULE)
        # a bin that a lobe's flank crosses is not integrated by the rule: its two orders
        # disagree, and it keeps its traced energy
        ok = np.all(np.abs(a - b) <= AGREE * np.abs(b) + 1e-9, axis=1)
        E[cells[ok, 0], cells[ok, 1]] = b[ok]
    return E
