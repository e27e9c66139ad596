"""Node values of an RGL slice by weighted least squares (the L2 error the export reports).

Within one slice (one incident direction ``wi``) a renderer reconstructs
``F(wo) = f(wi, wo) cos(theta_o)`` as ``J(h) sum_k w_k(s) R_k``: ``R_k`` the values at the
nodes of the ``n x n`` sample square, ``w_k(s)`` the bilinear weights at the point ``s`` that
the visible-normal warp maps to the half vector ``h`` of ``(wi, wo)``, and
``J = D(h) / (4 sigma(wi))``. Taking ``R_k`` as the BSDF's value at the nodes makes the file
exact there, but where ``R`` varies faster than the grid (near grazing, where a solved BSDF is
smooth in azimuth and a microfacet lobe is not) the bilinear interpolant between exact nodes
is far off. Instead the ``R_k`` minimise the error of the reconstruction over the outgoing
hemisphere,

    sum_p omega_p (J_p sum_k w_k(s_p) R_k - F_p)^2 + lam sum_k (R_k - R0_k)^2,

over points ``s_p`` at the centres of a ``m (n - 1)`` square grid (``m x m`` per cell),
``omega_p = 1 / p(wo_p)`` the solid angle each point stands for (``p`` the density of ``wo``
under the warp), ``F_p = 0`` outside nothing: points whose ``wo`` is below the horizon are left
out (renderers never evaluate them). The small ``lam`` (relative to the mean diagonal) ties
nodes that no point constrains to their point values ``R0``. Values are clipped at zero
afterwards (pbrt-v4 clamps negative spectra; a BSDF is not negative).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

#: Points per cell side of the fit (``m``): with 1 there are fewer points than nodes and the
#: regularisation decides the fit; benchmarks/features/rgl_export.txt compares 1, 2 and 3.
PER_CELL = 2
#: Tikhonov weight toward the node values, relative to the normal matrix's mean diagonal.
LAMBDA = 1e-6


def cell_points(n: int, per_cell: int = PER_CELL) -> np.ndarray:
    """Points (N, 2) of the sample square at the centres of a ``per_cell (n - 1)`` grid."""
    g = (np.arange(per_cell * (n - 1)) + 0.5) / (per_cell * (n - 1))
    sx, sy = np.meshgrid(g, g, indexing="xy")
    return np.stack([sx.ravel(), sy.ravel()], -1)


def bilinear_matrix(s: np.ndarray, n: int) -> sp.csr_matrix:
    """``w_k(s_p)`` (N, n^2): bilinear weights of the ``n x n`` nodes (row-major, ``y``
    slowest) at the points ``s`` (N, 2)."""
    x, y = s[:, 0] * (n - 1), s[:, 1] * (n - 1)
    i = np.minimum(x.astype(int), n - 2)
    j = np.minimum(y.astype(int), n - 2)
    fx, fy = x - i, y - j
    cols = np.stack([j * n + i, j * n + i + 1, (j + 1) * n + i, (j + 1) * n + i + 1], -1)
    w = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], -1)
    rows = np.repeat(np.arange(len(s)), 4)
    return sp.csr_matrix((w.ravel(), (rows, cols.ravel())), shape=(len(s), n * n))


def fit_slice(A: sp.csr_matrix, jac: np.ndarray, f: np.ndarray, omega: np.ndarray,
              r0: np.ndarray) -> np.ndarray:
    """Node values (n^2, C) minimising the weighted error (module docstring).

    Parameters
    ----------
    A : sparse (N, n^2)
        Bilinear weights of the points (:func:`bilinear_matrix`).
    jac : ndarray (N,)
        ``J = D(h) / (4 sigma(wi))`` at the points (1/sr).
    f : ndarray (N, C)
        ``f cos(theta_o)`` of the solved BSDF at the points (1/sr).
    omega : ndarray (N,)
        Solid angle per point (sr); 0 leaves a point out.
    r0 : ndarray (n^2, C)
        Node values the regularisation ties to.
    """
    B = sp.diags(jac) @ A
    M = (B.T @ sp.diags(omega) @ B).tocsc()
    reg = LAMBDA * max(float(M.diagonal().mean()), 1e-300)
    rhs = B.T @ (omega[:, None] * f) + reg * r0
    sol = spsolve(M + reg * sp.identity(M.shape[0], format="csc"), rhs)
    return np.maximum(np.asarray(sol).reshape(r0.shape), 0.0)
