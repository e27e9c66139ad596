"""The microfacet distribution that parameterises an RGL file, derived from a solved BSDF by
retro-reflection as Dupuy & Jakob 2018 do, and the unit-square coordinates the format uses.

An RGL file stores a BSDF as ``f(wi, wo) cos(theta_o) = R(s) D(h) / (4 sigma(wi))``: ``D`` a
normal distribution, ``sigma(w) = int D(m) max(0, m . w) dm`` its projected area (so that
``D(h) / (4 sigma(wi))`` is the density of ``wo`` when the half vector ``h`` is drawn from the
visible normals of ``wi``, Heitz 2014), and ``R`` a smooth remainder tabulated on a grid that
the visible-normal warp places (:mod:`layersim.bsdffile.rgl`). Any positive ``D`` gives an
exact file at the grid nodes; a ``D`` close to the BSDF's lobe puts the nodes where the lobe
is and leaves ``R`` nearly constant (close to the Fresnel factor for one microfacet interface).

Why retro-reflection (the first step of Dupuy & Jakob 2018's acquisition, which measures
retro-reflection to obtain the NDF before anything else; section and equation numbers are
not quoted here because the paper was not at hand when this was written): for a microfacet
BSDF at ``wi = wo = w`` the half vector is ``w`` itself and, masking and shadowing of one
direction being the same event, ``G2(w, w) = G1(w) = cos(theta) / sigma(w)``, so
``f(w, w) = F D(w) / (4 cos(theta) sigma(w))``, that is ``D(w) ∝ f(w, w) cos(theta)
sigma(w)``. ``sigma`` depends on ``D``: the fixed point is found by power iteration from
``sigma = 1``, normalising ``int D(m) cos(theta_m) dm = 1`` at every step
(:data:`ITERATIONS`). For a layered stack this is not the top interface's ``D`` but a
distribution shaped like the whole reflection lobe (a coating's peak on the broader lobe of
what lies under it), which is what the grid needs; the top interface's own ``D`` would be
exact only for a single interface and would put no nodes where a rough base's lobe is.

Coordinates (both readers): ``u = sqrt(2 theta / pi)`` (nodes dense near the normal, where
narrow lobes are), ``v = (phi + pi) / (2 pi)``; a table of shape ``(n_phi, n_theta)`` has
its node ``[i, j]`` at ``(u, v) = (j / (n_theta - 1), i / (n_phi - 1))``, bilinear between.
The solid angle is ``dw = 2 pi^2 u sin(theta) du dv``.
"""

from __future__ import annotations

import numpy as np

from .marginal2d import Marginal2D

#: Power-iteration steps of the retro-reflection NDF: for rough gold and coated gold the
#: table changes by 2e-2 (relative L2) after one step, 3e-5 after two and 5e-10 after four
#: (tests/test_export_rgl.py checks that a fifth changes it by less than 1e-6).
ITERATIONS = 4
#: Largest elevation (radians) at which the BSDF is evaluated: the horizon itself has no
#: reflection to measure, so nodes beyond take this elevation's value.
THETA_MAX = np.radians(89.9)
#: Floor added to the retro-reflection signal, relative to its largest value. Near grazing
#: a solved BSDF is smooth in azimuth where a microfacet one is not, so ``f`` stays large
#: where the half vector is far from the normal and ``D`` tiny; ``R = f cos 4 sigma / D``
#: then jumps by orders of magnitude between neighbouring nodes, and its bilinear
#: interpolation against an exponentially falling ``D`` overshoots by as much. The floor
#: bounds ``R``; it costs the lobe the few nodes the warp gives the floor
#: (benchmarks/features/rgl_export.txt compares 0, 1e-3, 1e-2).
FLOOR = 1e-3


def u2theta(u):
    return np.square(u) * (np.pi / 2)


def theta2u(theta):
    return np.sqrt(np.asarray(theta) * (2 / np.pi))


def u2phi(v):
    return (2 * np.asarray(v) - 1) * np.pi


def phi2u(phi):
    return (np.asarray(phi) + np.pi) / (2 * np.pi)


def direction(theta, phi) -> np.ndarray:
    """Unit vectors (..., 3) at elevation ``theta`` and azimuth ``phi`` (radians)."""
    st = np.sin(theta)
    return np.stack(np.broadcast_arrays(st * np.cos(phi), st * np.sin(phi), np.cos(theta)),
                    axis=-1)


def table_directions(n_theta: int, n_phi: int) -> np.ndarray:
    """The directions (n_phi, n_theta, 3) of a table's nodes (module docstring)."""
    u = np.linspace(0.0, 1.0, n_theta)
    v = np.linspace(0.0, 1.0, n_phi)
    return direction(u2theta(u)[None, :], u2phi(v)[:, None])


def _quadrature(n: int):
    """Midpoint nodes (m, 3) and solid-angle weights (m,) over the hemisphere, ``n x 2n``
    cells in ``(u, v)``."""
    u = (np.arange(n) + 0.5) / n
    v = (np.arange(2 * n) + 0.5) / (2 * n)
    uu, vv = np.meshgrid(u, v, indexing="xy")
    theta = u2theta(uu)
    w = 2 * np.pi ** 2 * uu * np.sin(theta) / (n * 2 * n)
    pts = np.stack([uu.ravel(), vv.ravel()], axis=-1)
    return pts, direction(theta, u2phi(vv)).reshape(-1, 3), w.ravel()


def projected_area(ndf: np.ndarray, dirs: np.ndarray, quad: int = 128) -> np.ndarray:
    """``sigma(w) = int D(m) max(0, m . w) dm`` (dimensionless) of the bilinear table ``ndf``
    (n_phi, n_theta) in 1/sr at ``dirs`` (..., 3), by a midpoint rule of ``quad x 2 quad``
    cells in ``(u, v)``."""
    pts, m, w = _quadrature(quad)
    dm = Marginal2D(ndf, normalize=False).eval(pts) * w
    flat = dirs.reshape(-1, 3)
    out = np.empty(len(flat))
    for a in range(0, len(flat), 256):           # (256 x m) blocks bound the memory
        out[a:a + 256] = np.maximum(flat[a:a + 256] @ m.T, 0.0) @ dm
    return out.reshape(dirs.shape[:-1])


def retro_ndf(retro, n_theta: int, n_phi: int, quad: int = 128, floor: float = FLOOR):
    """The retro-reflection NDF and its projected area (module docstring).

    Parameters
    ----------
    retro : callable
        ``retro(w)`` -> ``f(w, w)`` in 1/sr for directions (..., 3) (one value per direction:
        the channels' mean).
    n_theta, n_phi : int
        Table size; ``n_phi = 2`` for an isotropic BSDF (azimuth-independent, evaluated at
        ``phi = 0``).
    floor : float
        :data:`FLOOR`, relative to the largest retro-reflection.

    Returns
    -------
    ndf, sigma : ndarray, shape (n_phi, n_theta)
        ``D`` in 1/sr normalised to unit projected area toward the normal, and ``sigma`` at
        the table's own directions.
    """
    dirs = table_directions(n_theta, n_phi)
    theta = np.minimum(u2theta(np.linspace(0.0, 1.0, n_theta)), THETA_MAX)
    phi = u2phi(np.linspace(0.0, 1.0, n_phi)) if n_phi > 2 else np.zeros(n_phi)
    probe = direction(theta[None, :], phi[:, None])
    shape = np.maximum(np.asarray(retro(probe), np.float64), 0.0)
    if not np.any(shape > 0):
        raise ValueError("the BSDF reflects nothing back toward the light at any direction: "
                         "no normal distribution can be derived (is it a transmitting "
                         "layer without reflection?)")
    shape = (shape + floor * shape.max()) * probe[..., 2]
    sigma = np.ones_like(shape)
    for _ in range(ITERATIONS):
        ndf = shape * sigma
        ndf = ndf / projected_area(ndf, np.array([0.0, 0.0, 1.0]), quad)
        sigma = projected_area(ndf, dirs, quad)
    return ndf, sigma
