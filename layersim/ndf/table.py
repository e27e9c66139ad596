"""Tabulated microfacet normal distributions (Wang et al. 2008, sec. 3, eq. (1)-(5)).

A table holds D(h) (1/sr) on a grid of half-vector elevations ``theta`` (radians, increasing,
from 0 to pi/2) and azimuths ``phi`` (radians, increasing, covering [0, 2 pi), periodic), values
``D[i, j] = D(theta_i, phi_j)``. Between the nodes D is bilinear in (theta, phi); in azimuth the
last node connects to the first across 2 pi. Everything derived here (normalisation, shadowing,
sampling) is computed for that bilinear function exactly, so that the projection and the random
walk, which both interpolate the same nodes, see one distribution.

* Normalisation (Wang et al. 2008, sec. 3): the projected area ``int D(h) (h.n) dw_h`` over the
  upper hemisphere is 1. The integral of the bilinear D against ``cos sin dtheta dphi`` is exact
  (:func:`theta_weights`); the table is divided by it.
* Shadowing (Wang et al. 2008, eq. (4)-(5), after Ashikhmin et al. 2000): ``G(i, o) = S(i) S(o)``
  with ``S(k) = (k.n) / int_{h.k > 0} (h.k) D(h) dw_h``. For a distribution with the Smith
  microsurface profile this is Smith's ``G1 = 1 / (1 + Lambda)``; it is tabulated once on a
  (theta_k, phi_k) grid (:func:`shadow_grid`) and interpolated bilinearly.
* Sampling: cells are chosen with probability ``P_ij`` (their share of the projected area);
  within a cell ``sin^2 theta`` and ``phi`` are uniform, so the density of normals is
  ``P_ij 2 cos(theta) / ((sin^2 theta_{i+1} - sin^2 theta_i) dphi_j)`` per steradian, close to
  ``D cos`` (:mod:`layersim.kernels.tabulated`).

The kernels read one flat float array (:meth:`NDFTable.packed`, layout in :data:`HEADER`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import SceneError

__all__ = ["NDFTable", "load_ndf", "from_arrays", "theta_weights", "sampled_table"]

#: Shadowing grid (:func:`shadow_grid`): elevations (crowding toward the horizon, both ends
#: included) and azimuths (uniform, periodic, 3 deg; an even count). Interpolated S of a
#: Beckmann (0.3, 0.15) table is within 4e-4 of Smith's closed form up to 89.5 deg
#: (tests/test_tabulated_ndf.py).
SHADOW_THETA, SHADOW_PHI = 181, 120
#: Layout of :meth:`NDFTable.packed`: four counts, then the arrays in this order.
HEADER = ("n_theta", "n_phi", "n_shadow_theta", "n_shadow_phi")
#: Largest table (nodes) accepted: the shadowing pass is O(nodes x shadow nodes).
MAX_NODES = 1 << 17
#: Slope-median ratio of a Beckmann lobe: median |tan(theta) cos(phi)| = 0.4769 alpha
#: (Gaussian slopes of variance alpha^2 / 2), used to give a table an equivalent roughness.
_BECKMANN_MEDIAN = 0.47693627620446987


def _hat_weights(theta: np.ndarray, prim0, prim1) -> tuple[np.ndarray, np.ndarray]:
    """Per theta cell ``[a, b]``, ``int hat(t) g(t) dt`` of the hat falling from ``a`` and of the
    one rising to ``b``, from the primitives ``prim0`` of ``g`` and ``prim1`` of ``t g``."""
    a, b = theta[:-1], theta[1:]
    m0 = prim0(b) - prim0(a)
    w_b = (prim1(b) - prim1(a) - a * m0) / (b - a)
    return m0 - w_b, w_b


def _cos_sin(theta):
    """Hat weights against ``cos t sin t`` (projected area)."""
    return _hat_weights(theta, lambda t: 0.5 * np.sin(t) ** 2,
                        lambda t: -t * np.cos(2 * t) / 4 + np.sin(2 * t) / 8)


def _sin(theta):
    """Hat weights against ``sin t`` (solid angle)."""
    return _hat_weights(theta, lambda t: -np.cos(t), lambda t: np.sin(t) - t * np.cos(t))


def _node_weights(cells) -> np.ndarray:
    w_a, w_b = cells
    w = np.zeros(w_a.size + 1)
    w[:-1] += w_a
    w[1:] += w_b
    return w


def theta_weights(theta: np.ndarray) -> np.ndarray:
    """Weights ``w`` with ``int_0^{theta_max} g(t) cos t sin t dt = sum_i w_i g(theta_i)`` for
    ``g`` piecewise linear between the nodes (exact), shape (len(theta),)."""
    return _node_weights(_cos_sin(theta))


def _dphi(phi: np.ndarray) -> np.ndarray:
    """Azimuthal cell widths, the last one wrapping across 2 pi, shape (n_phi,)."""
    return np.diff(np.append(phi, phi[0] + 2.0 * np.pi))


@dataclass(frozen=True, eq=False)
class NDFTable:
    """A validated, normalised NDF table with its shadowing and sampling tables.

    Attributes
    ----------
    theta : ndarray, shape (T,)
        Elevations of the half vector (radians), ``theta[0] = 0``, ``theta[-1] = pi/2``.
    phi : ndarray, shape (P,)
        Azimuths (radians), increasing, in [0, 2 pi).
    D : ndarray, shape (T, P)
        Normalised NDF values (1/sr).
    source : str
        Where the table came from (file path or ``"inline"``), for messages and reports.
    scale : float
        Factor the input was multiplied by to normalise it.
    shadow : ndarray, shape (SHADOW_THETA, SHADOW_PHI)
        ``S(k)`` on the uniform shadowing grid (Wang et al. 2008, eq. (5)).
    """

    theta: np.ndarray
    phi: np.ndarray
    D: np.ndarray
    source: str = "inline"
    scale: float = 1.0
    shadow: np.ndarray = field(default=None, repr=False)

    # ---- evaluation (host, float64; the kernels do the same in kernels/tabulated.py) -----

    def eval(self, theta_h, phi_h) -> np.ndarray:
        """Bilinear D (1/sr) at half-vector angles (radians, broadcast); 0 below the horizon."""
        return _bilinear(self.theta, self.phi, self.D, np.asarray(theta_h, float),
                         np.asarray(phi_h, float))

    def shadowing(self, k) -> np.ndarray:
        """Tabulated ``S(k)`` for unit directions ``k`` of shape (..., 3) (uses |k.z|)."""
        k = np.asarray(k, float)
        th = np.arctan2(np.hypot(k[..., 0], k[..., 1]), np.abs(k[..., 2]))
        ph = np.arctan2(k[..., 1], k[..., 0]) % (2.0 * np.pi)
        tg, pg = shadow_grid()
        return _bilinear(_shadow_x(tg), pg, self.shadow, _shadow_x(th), ph)

    def cell_probabilities(self) -> np.ndarray:
        """Projected-area share ``P[i, j]`` of cell (theta_i..theta_{i+1}, phi_j..phi_{j+1})
        under the bilinear D, shape (T - 1, P); sums to 1."""
        wa, wb = _cos_sin(self.theta)
        Dn = np.roll(self.D, -1, axis=1)          # right neighbour, wrapping in phi
        side = 0.5 * (self.D + Dn) * _dphi(self.phi)[None, :]
        return wa[:, None] * side[:-1] + wb[:, None] * side[1:]

    # ---- derived numbers -------------------------------------------------------------

    def principal_axes(self) -> tuple[float, float, float]:
        """``(alpha_u, alpha_v, angle)``: the Beckmann roughness with the same median slope
        (projected-area weighted) along the axis of largest median slope, at azimuth ``angle``
        (radians, in [0, pi), 2 deg steps), and along the axis across it. What the planner
        sizes ``n``, ``md`` and ``ms`` by; a rotated lobe keeps its roughness ratio."""
        th = 0.5 * (self.theta[:-1] + self.theta[1:])
        ph = self.phi + 0.5 * _dphi(self.phi)
        P = self.cell_probabilities().ravel()
        t = np.tan(th)[:, None]
        sx, sy = (t * np.cos(ph)[None, :]).ravel(), (t * np.sin(ph)[None, :]).ravel()

        def median(psi):
            slope = np.abs(sx * np.cos(psi) + sy * np.sin(psi))
            order = np.argsort(slope)
            c = np.cumsum(P[order])
            med = slope[order][min(np.searchsorted(c, 0.5), slope.size - 1)]
            return max(float(med) / _BECKMANN_MEDIAN, 1e-3)

        angles = np.radians(np.arange(0.0, 180.0, 2.0))
        meds = np.array([median(a) for a in angles])
        k = int(np.argmax(meds))
        return float(meds[k]), float(meds[(k + angles.size // 2) % angles.size]), float(angles[k])

    def equivalent_alpha(self) -> tuple[float, float]:
        """``(alpha_u, alpha_v)`` of :meth:`principal_axes`."""
        return self.principal_axes()[:2]

    def describe(self) -> str:
        au, av, angle = self.principal_axes()
        axis = f" along {np.degrees(angle):.3g} deg" if au != av and angle else ""
        return (f"tabulated NDF {self.theta.size} x {self.phi.size} ({self.source}), "
                f"equivalent Beckmann alpha=({au:.3g}, {av:.3g}){axis}")

    def packed(self, dtype=np.float32) -> np.ndarray:
        """Flat array for the kernels: the counts of :data:`HEADER`, ``theta``, ``phi``,
        ``D`` (row-major), ``S`` (row-major on :func:`shadow_grid`), the marginal CDF of theta
        cells (T values, from 0 to 1) and the conditional CDFs of phi cells per theta cell
        ((T - 1) x (P + 1) values, each from 0 to 1)."""
        P = self.cell_probabilities()
        rows = P.sum(axis=1)
        marg = np.concatenate([[0.0], np.cumsum(rows)])
        marg /= marg[-1]
        cond = np.zeros((P.shape[0], P.shape[1] + 1))
        cond[:, 1:] = np.cumsum(P, axis=1)
        cond /= np.where(rows > 0, rows, 1.0)[:, None]
        cond[rows <= 0, 1:] = 1.0       # never chosen: any valid CDF
        head = [self.theta.size, self.phi.size, *self.shadow.shape]
        return np.concatenate([head, self.theta, self.phi, self.D.ravel(), self.shadow.ravel(),
                               marg, cond.ravel()]).astype(dtype)


def shadow_grid() -> tuple[np.ndarray, np.ndarray]:
    """Nodes ``(theta_k, phi_k)`` of the shadowing table (radians): uniform in azimuth, and
    uniform in ``x = 1 - sqrt(1 - theta / (pi/2))`` in elevation, so that the nodes crowd
    toward the horizon, where S falls to 0 within a few degrees (``theta = (pi/2)(1 -
    (1 - x)^2)``, spacing 1 deg at the normal and 0.003 deg at the horizon for 181 nodes)."""
    x = np.linspace(0.0, 1.0, SHADOW_THETA)
    return (0.5 * np.pi * (1.0 - (1.0 - x) ** 2),
            np.arange(SHADOW_PHI) * (2.0 * np.pi / SHADOW_PHI))


def _shadow_x(theta):
    """Elevation coordinate of the shadowing grid (:func:`shadow_grid`)."""
    return 1.0 - np.sqrt(np.maximum(1.0 - theta / (0.5 * np.pi), 0.0))


def _bilinear(theta, phi, values, th, ph):
    th, ph = np.broadcast_arrays(th, ph % (2.0 * np.pi))
    i = np.clip(np.searchsorted(theta, th, side="right") - 1, 0, theta.size - 2)
    ti = np.clip((th - theta[i]) / (theta[i + 1] - theta[i]), 0.0, 1.0)
    j = np.searchsorted(phi, ph, side="right") - 1          # -1: before phi[0], wraps
    j = np.where(j < 0, phi.size - 1, j)
    j1 = (j + 1) % phi.size
    lo = phi[j]
    width = _dphi(phi)[j]
    tj = ((ph - lo) % (2.0 * np.pi)) / width
    v = ((1 - ti) * ((1 - tj) * values[i, j] + tj * values[i, j1])
         + ti * ((1 - tj) * values[i + 1, j] + tj * values[i + 1, j1]))
    return np.where(th <= 0.5 * np.pi, v, 0.0)


def _shadow_table(theta, phi, D) -> np.ndarray:
    """``S(k)`` (Wang et al. 2008, eq. (5)) on :func:`shadow_grid`, shape (SHADOW_THETA,
    SHADOW_PHI): node quadrature of ``(h.k)+ D(h)`` with the exact bilinear weights."""
    wts = (_node_weights(_sin(theta))[:, None] * _dphi_nodes(phi)[None, :] * D).ravel()
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    H = np.stack([(st * np.cos(phi)[None, :]).ravel(), (st * np.sin(phi)[None, :]).ravel(),
                  np.broadcast_to(ct, D.shape).ravel()], axis=1)
    tg, pg = shadow_grid()
    # D is symmetric under a rotation by pi (from_arrays), hence so is S: half the azimuths
    pg = pg[:SHADOW_PHI // 2]
    K = np.stack([(np.sin(tg)[:, None] * np.cos(pg)[None, :]).ravel(),
                  (np.sin(tg)[:, None] * np.sin(pg)[None, :]).ravel(),
                  np.broadcast_to(np.cos(tg)[:, None], (tg.size, pg.size)).ravel()], axis=1)
    keep = wts != 0.0
    # float32 products (S to ~1e-6, far below the interpolation error), float64 sums
    H, wts = H[keep].astype(np.float32), wts[keep]
    den = np.empty(K.shape[0])
    step = max(1, (1 << 22) // max(H.shape[0], 1))
    for a in range(0, K.shape[0], step):
        dots = H @ K[a:a + step].T.astype(np.float32)
        np.maximum(dots, 0.0, out=dots)
        den[a:a + step] = wts @ dots
    S = np.where(den > 0, K[:, 2] / np.maximum(den, 1e-300), 0.0)
    # S > 1 would mean the visible projected area is below the geometric one (a distribution
    # whose mean slope is not zero); the product S(i) S(o) must not create energy
    S = np.minimum(S, 1.0).reshape(tg.size, pg.size)
    return np.concatenate([S, S], axis=1)


def _dphi_nodes(phi: np.ndarray) -> np.ndarray:
    """Trapezoid weights of the periodic azimuth nodes (exact for the piecewise linear D)."""
    d = _dphi(phi)
    return 0.5 * (d + np.roll(d, 1))


#: Largest relative L2 difference between D(theta, phi) and D(theta, phi + pi) that is averaged
#: away (measurement noise); larger asymmetry is refused.
SYMMETRY_TOLERANCE = 1e-3


def _point_symmetric(phi: np.ndarray, D: np.ndarray, bad) -> np.ndarray:
    """``D`` made exactly symmetric under the rotation by pi about the normal, which the
    coupled-mode basis assumes (Zeltner & Jakob 2018, eq. (9)-(10): mode ``k`` couples to
    ``k + 2 s`` only); refuses tables that are not (up to :data:`SYMMETRY_TOLERANCE`)."""
    n = phi.size
    if n % 2 or np.max(np.abs(np.roll(phi, -(n // 2)) - phi - np.where(
            np.arange(n) < n - n // 2, np.pi, -np.pi))) > 1e-9:
        raise bad("phi must hold an even number of azimuths with phi[j + len(phi)/2] = "
                  "phi[j] + pi (the solver's coupled-mode basis represents NDFs symmetric "
                  "under a rotation by pi about the normal)")
    turned = np.roll(D, -(n // 2), axis=1)
    diff = np.linalg.norm(turned - D) / max(np.linalg.norm(D), 1e-300)
    if diff > SYMMETRY_TOLERANCE:
        raise bad(f"D(theta, phi + pi) differs from D(theta, phi) by {diff:.3g} (relative L2; "
                  f"the limit is {SYMMETRY_TOLERANCE:g}): the solver's coupled-mode basis "
                  "represents only NDFs symmetric under a rotation by pi about the normal; "
                  "symmetrise the table (0.5 (D(phi) + D(phi + pi))) if that is intended")
    return 0.5 * (D + turned)


def from_arrays(theta, phi, D, source: str = "inline", layer: int | None = None,
                kind: str | None = None, fld: str = "ndf") -> NDFTable:
    """Validate and normalise a table given as arrays (see the module docstring).

    Raises
    ------
    SceneError
        Naming ``source``, the layer and the field, if the arrays have the wrong shape, are not
        finite, negative, not increasing, do not span the hemisphere, or integrate to zero.
    """
    def bad(msg):
        return SceneError(f"NDF table {source}: {msg}", layer=layer, kind=kind, field=fld)

    try:
        theta = np.asarray(theta, dtype=float)
        phi = np.asarray(phi, dtype=float)
        D = np.asarray(D, dtype=float)
    except (TypeError, ValueError) as exc:
        raise bad(f"theta, phi and D must be numeric arrays ({exc})") from None
    if theta.ndim != 1 or theta.size < 2 or phi.ndim != 1 or phi.size < 1:
        raise bad("theta and phi must be 1-D arrays (at least 2 and 1 values)")
    if D.shape != (theta.size, phi.size):
        raise bad(f"D must have shape (len(theta), len(phi)) = ({theta.size}, {phi.size}), "
                  f"got {D.shape}")
    if D.size > MAX_NODES:
        raise bad(f"{D.size} nodes exceed the limit of {MAX_NODES}; resample the table")
    for name, a in (("theta", theta), ("phi", phi), ("D", D)):
        if not np.all(np.isfinite(a)):
            raise bad(f"{name} has non-finite values")
    if np.any(np.diff(theta) <= 0) or np.any(np.diff(phi) <= 0):
        raise bad("theta and phi must be strictly increasing")
    if abs(theta[0]) > 1e-9 or abs(theta[-1] - 0.5 * np.pi) > 1e-9:
        raise bad(f"theta must run from 0 to pi/2 (radians), got {theta[0]:g} .. {theta[-1]:g}")
    if phi[0] < 0 or phi[-1] >= 2 * np.pi:
        raise bad(f"phi must lie in [0, 2 pi) (radians), got {phi[0]:g} .. {phi[-1]:g}")
    if np.any(D < 0):
        raise bad("D must be non-negative")
    theta = theta.copy()
    theta[0], theta[-1] = 0.0, 0.5 * np.pi
    D = _point_symmetric(phi, D, bad)
    area = float(np.sum(theta_weights(theta)[:, None] * _dphi_nodes(phi)[None, :] * D))
    if not area > 0 or not math.isfinite(area):
        raise bad("the projected area int D(h) (h.n) dw is zero: D cannot be normalised")
    D = D / area
    return NDFTable(theta, phi, D, source=source, scale=1.0 / area,
                    shadow=_shadow_table(theta, phi, D))


def load_ndf(path, layer: int | None = None, kind: str | None = None,
             fld: str = "ndf") -> NDFTable:
    """Read an ``.npz`` NDF file with arrays ``theta``, ``phi`` and ``D`` (see the module
    docstring) and validate and normalise it (:func:`from_arrays`).

    Raises
    ------
    SceneError
        Naming the file (and the layer and field, when given) if it cannot be read or is not a
        valid table.
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in ("theta", "phi", "D") if k not in z.files]
            if missing:
                raise SceneError(f"NDF file {path}: missing array(s) {', '.join(missing)} "
                                 "(an NDF file holds theta, phi and D)", layer=layer, kind=kind,
                                 field=fld)
            arrays = z["theta"], z["phi"], z["D"]
    except (OSError, ValueError) as exc:
        raise SceneError(f"cannot read NDF file {path}: {exc}", layer=layer, kind=kind,
                         field=fld) from None
    return from_arrays(*arrays, source=str(path), layer=layer, kind=kind, fld=fld)


def sampled_table(ndf, n_theta: int = 91, n_phi: int = 180) -> NDFTable:
    """Table of an NDF function sampled on a uniform grid: ``ndf(theta, phi)`` (broadcast,
    radians, 1/sr) at ``n_theta`` elevations from 0 to pi/2 and ``n_phi`` azimuths
    ``2 pi j / n_phi``; validated and normalised as a file would be."""
    theta = np.linspace(0.0, 0.5 * np.pi, n_theta)
    phi = np.arange(n_phi) * (2.0 * np.pi / n_phi)
    D = np.asarray(ndf(theta[:, None], phi[None, :]), float) * np.ones((n_theta, n_phi))
    return from_arrays(theta, phi, D, source=f"sampled {n_theta} x {n_phi}")
