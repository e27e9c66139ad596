"""Directional albedo tables of single-scattering rough interfaces, computed from
:mod:`layersim.kernels.physics` by :data:`layersim.kernels.compensation.albedo_kernel` and kept
in memory and in ``settings().cache_dir`` (``LAYERSIM_CACHE_DIR``).

Resolution: :data:`NODES` incident directions uniform in the polar angle from 0 to 90 degrees
(0.5 degree steps; the node on the horizon takes the value at ``mu = MU_HORIZON``), each
integrated with :data:`N_U` Gauss-Legendre nodes in the cumulative slope probability and
:data:`N_PHI` trapezoid nodes in the slope azimuth. Between nodes the tables are interpolated
linearly in the polar angle (:func:`interpolate`), by the solver and the random walk alike.
Accuracy (``tests/test_compensation.py``): in the smooth limit (Beckmann alpha 0.005, eta 1.5,
0-80 degrees) ``E_R + E_T`` is 1 to 1e-15 and ``E_R`` the Fresnel reflectance to 7e-5 from
outside and 7.5e-4 from inside (away from the critical angle, where the roughness blurs the
steep rise); a rough conductor's table (alpha 0.5) agrees with the solver's projected albedo to
2e-4.
"""

from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass

import numpy as np

from .. import tablecache
from ..kernels import compensation as kcomp
from ..kernels.physics import DISTRIBUTION_CODES, SHADOWING_CODES
from ..kernels.runtime import ensure_init

import warp as wp

#: Table nodes (uniform in the polar angle, 0 to 90 degrees); the walk's constant.
NODES = int(kcomp.TABLE_NODES)
#: Cosine at which the horizon node is evaluated (the integrand divides by mu).
MU_HORIZON = 1e-3
#: Gauss-Legendre nodes in the slope probability and trapezoid nodes in the slope azimuth.
N_U = 160
N_PHI = 161
#: Version of the table definition, part of the cache key.
VERSION = 1


def nodes() -> np.ndarray:
    """Cosines of the table nodes, shape (NODES,), decreasing from 1 to 0 (the polar angle
    uniform from 0 to 90 degrees)."""
    return np.cos(np.linspace(0.0, 0.5 * np.pi, NODES))


def interpolate(table: np.ndarray, mu) -> np.ndarray:
    """Table values at cosines ``mu`` (any shape), linear in the polar angle (as the walk's
    :func:`layersim.kernels.compensation.table_value`)."""
    x = np.arccos(np.clip(np.asarray(mu, float), 0.0, 1.0)) * (NODES - 1) / (0.5 * np.pi)
    i = np.minimum(x.astype(int), NODES - 2)
    t = x - i
    return table[i] * (1.0 - t) + table[i + 1] * t


def hemispherical_integral(table: np.ndarray) -> float:
    """``2 pi int_0^1 v(mu) mu dmu`` of the interpolated table ``v`` (exact to rounding: an
    8-point Gauss-Legendre rule on every segment, on which ``v`` is linear in the angle)."""
    x, w = np.polynomial.legendre.leggauss(8)
    edges = np.linspace(0.0, 0.5 * np.pi, NODES)
    a, b = edges[:-1, None], edges[1:, None]
    theta = 0.5 * (a + b) + 0.5 * (b - a) * x[None, :]
    t = (theta - a) / (b - a)
    v = table[:-1, None] * (1.0 - t) + table[1:, None] * t
    return float(2.0 * np.pi * np.sum(0.5 * (b - a) * w * v * np.cos(theta) * np.sin(theta)))


@dataclass(frozen=True)
class Albedos:
    """Single-scattering albedos at the table nodes (:func:`nodes`), shape (NODES,) each:
    reflected and transmitted energy for light from the top (``r_top``, ``t_top``) and from
    the bottom (``r_bottom``, ``t_bottom``; zero for a conductor)."""

    r_top: np.ndarray
    t_top: np.ndarray
    r_bottom: np.ndarray
    t_bottom: np.ndarray


def _compute(eta: float, k: float, alpha: float, dist: str, unit_fresnel: bool,
             shadowing: str) -> Albedos:
    ensure_init()
    dev = wp.get_device("cpu")
    mu = np.maximum(nodes(), MU_HORIZON)
    x, w = np.polynomial.legendre.leggauss(N_U)
    un, uw = 0.5 * (x + 1.0), 0.5 * w
    out = []
    for side in (1.0, -1.0):
        if side < 0 and k > 0:
            out += [np.zeros(NODES), np.zeros(NODES)]
            continue
        r = wp.zeros((NODES, N_U), dtype=wp.float64, device=dev)
        t = wp.zeros((NODES, N_U), dtype=wp.float64, device=dev)
        wp.launch(kcomp.albedo_kernel, dim=(NODES, N_U), device=dev,
                  inputs=[wp.array(mu, dtype=wp.float64, device=dev), wp.float64(side),
                          wp.array(un, dtype=wp.float64, device=dev),
                          wp.array(uw, dtype=wp.float64, device=dev), N_PHI,
                          wp.float64(eta), wp.float64(k), wp.float64(alpha),
                          int(DISTRIBUTION_CODES[dist]), int(SHADOWING_CODES[shadowing]),
                          int(unit_fresnel)],
                  outputs=[r, t])
        out += [r.numpy().sum(axis=1), t.numpy().sum(axis=1)]
    return Albedos(*out)


def _cache_path(key: str):
    digest = hashlib.sha256(key.encode()).hexdigest()[:24]
    return tablecache.path("compensation", f"albedo-{digest}.npz")


@functools.lru_cache(maxsize=256)
def albedos(eta: float, k: float, alpha: float, dist: str,
            unit_fresnel: bool = False, shadowing: str = "separable") -> Albedos:
    """Albedo tables of an isotropic rough interface of relative index ``eta + i k`` (``k >
    0``: conductor), roughness ``alpha``, distribution ``dist`` and Smith term ``shadowing``
    (:func:`layersim.kernels.physics.smith_g2`); with ``unit_fresnel`` the conductor's Fresnel
    factor is 1. Read from the disk cache when present, else computed (about a second on one
    CPU core) and stored there."""
    # the separable term keeps the key it had before the shadowing choice (its cached tables)
    key = (f"v{VERSION} n{NODES} u{N_U} p{N_PHI} h{MU_HORIZON!r} eta{eta!r} k{k!r} "
           f"a{alpha!r} {dist} unit{int(unit_fresnel)}"
           + ("" if shadowing == "separable" else f" {shadowing}"))
    path = _cache_path(key)
    fields = ("r_top", "t_top", "r_bottom", "t_bottom")
    stored = tablecache.read(path)
    # a file of another key (or of missing fields) is recomputed and replaced
    if stored is not None and str(stored.get("key")) == key and all(f in stored for f in fields):
        return Albedos(*(stored[f] for f in fields))
    tab = _compute(eta, k, alpha, dist, unit_fresnel, shadowing)
    tablecache.write(path, key=key, **{f: getattr(tab, f) for f in fields})
    return tab


@functools.lru_cache(maxsize=256)
def fresnel_average(eta: float, k: float) -> float:
    """Hemispherical average ``2 int_0^1 F(mu) mu dmu`` of a conductor's Fresnel reflectance
    (256-point Gauss-Legendre rule in ``mu^2``, as layerlab's ``fresnelConductorIntegral``
    with more nodes)."""
    ensure_init()
    dev = wp.get_device("cpu")
    x, w = np.polynomial.legendre.leggauss(256)
    s = 0.5 * (x + 1.0)
    out = wp.zeros(s.size, dtype=wp.float64, device=dev)
    wp.launch(kcomp.fresnel_kernel, dim=s.size, device=dev,
              inputs=[wp.array(np.sqrt(s), dtype=wp.float64, device=dev), wp.float64(eta),
                      wp.float64(k)], outputs=[out])
    return float(np.sum(0.5 * w * out.numpy()))
