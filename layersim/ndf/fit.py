"""Partial NDF from single-view measurements (Wang et al. 2008 sec. 5.1, eq. 10-12).

With the view o fixed and the lights i sweeping the hemisphere, the half vectors cover only the
region Omega = {h : reflect(o, h) . n > 0} (eq. 10). Over it, inverting the microfacet BRDF with
F = 1 gives

    D(h) = 4 f(i(h), o) (i(h) . n) (o . n) / (S(i(h)) S(o)),   i(h) = reflect(o, h)     (eq. 11)

and S follows from D by eq. (5). The two are updated in turn from S = 1 until S stops changing.
S needs D over the whole hemisphere, but D is known only over Omega: with D = 0 outside, S comes out
biased (the "unconstrained" variant, after Ngan et al. 2005). The isotropically constrained
variant replaces S(k) by its minimum over the azimuth of k at the same elevation, which the paper
finds closest to the truth (its Fig. 5). The confidence of each node is
W(h) = [reflect(o, h) . n]_+^(1/2) (eq. 12).

The measured values are scattered over light directions; they are carried to the grid of normals
by C1 cubic interpolation (Clough-Tocher) over the orthographic projection (i_x, i_y) of the light
directions, so that each node h reads the data at its own i(h). Nodes whose i(h) lies outside the
measured lights, or beyond ``max_light_theta``, stay undetermined (W = 0, D = NaN).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CloughTocher2DInterpolator

from ..kernels.fresnel import fresnel
from . import microfacet as mf
from .halfgrid import HalfGrid
from .measurements import Measurements


@dataclass
class PartialNDF:
    """A partial NDF and its confidence (the tuple Psi = <D, W> of Wang et al. 2008 sec. 5.2).

    Attributes
    ----------
    grid : HalfGrid
    d : array (n_theta, n_phi), D in 1/sr times the specular coefficient; NaN where W = 0
    w : array (n_theta, n_phi), confidence W >= 0 (eq. 12); 0 where undetermined
    residual : relative RMS difference between the fitted model and the data it was fitted to
    channel_scale : array (C,), least-squares scale of each channel relative to the fitted model
    channels : tuple of channel names
    notes : list of str, what the fit did (iterations, coverage, excluded data)
    shadow_view : S(o) of the view at convergence (nan when not fitted from a view)
    """

    grid: HalfGrid
    d: np.ndarray
    w: np.ndarray
    residual: float = float("nan")
    channel_scale: np.ndarray = field(default_factory=lambda: np.ones(1))
    channels: tuple = ("value",)
    notes: list = field(default_factory=list)
    shadow_view: float = float("nan")

    @property
    def coverage(self) -> float:
        """Fraction of the hemisphere's solid angle where D is determined (W > 0)."""
        wts = self.grid.weights
        return float(np.sum(wts * (self.w > 0)) / np.sum(wts))

    @property
    def complete(self) -> bool:
        """True when every node of the grid is determined."""
        return bool(np.all(self.w > 0))


def _shadow_fn(grid, d, constrained, n_theta_k=46):
    """S(k) of eq. (5) from D (NaN -> 0), tabulated on rings of k (the grid's azimuths); with
    ``constrained``, its minimum over the azimuth of k (Wang et al. 2008 sec. 5.1)."""
    theta_k = np.minimum(np.linspace(0.0, 0.5 * np.pi, n_theta_k), np.radians(89.5))
    s = np.clip(mf.shadowing_rings(grid, np.nan_to_num(d), theta_k), 1e-6, 1.0)
    if constrained:
        s_theta = s.min(axis=1)
        return lambda v: np.interp(np.arccos(np.clip(v[..., 2], 0, 1)), theta_k, s_theta)
    ring = HalfGrid(n_theta_k, grid.n_phi)          # its last row holds S at 89.5 degrees
    return lambda v: ring.lookup(s, v)


def _data_on_grid(meas: Measurements, grid: HalfGrid, max_light_theta: float, eta):
    """T(h) = 4 f (i . n)(o . n) / F at the grid nodes (eq. 11 without S), their i(h) and the
    mask of determined nodes; also the mask of the lights used."""
    o, lights = meas.view, meas.lights
    y = meas.values.mean(axis=1)
    cos_max = np.cos(max_light_theta)
    keep = lights[:, 2] > cos_max
    if keep.sum() < 16:
        raise ValueError(f"{meas.source}: field 'lights': only {int(keep.sum())} light "
                         f"directions within {np.degrees(max_light_theta):.0f} degrees of the "
                         "normal; fitting needs at least 16 (raise --max-light-theta?)")
    li, yi = lights[keep], y[keep]
    hq = mf.half_vector(li, o)
    fres = 1.0 if eta is None else fresnel(np.sum(li * hq, -1), eta)
    tq = 4.0 * yi * li[:, 2] * o[2] / fres
    interp = CloughTocher2DInterpolator(li[:, :2], tq, fill_value=np.nan)
    hg = grid.directions()
    ig = mf.reflect(o, hg)
    tg = interp(ig[..., :2])
    det = (ig[..., 2] > cos_max) & np.isfinite(tg)
    return np.where(det, np.maximum(tg, 0.0), np.nan), ig, det, keep


def fit_partial_ndf(meas: Measurements, grid: HalfGrid | None = None, constrained: bool = True,
                    max_light_theta_deg: float = 80.0, eta: float | None = None,
                    max_iter: int = 60, tol: float = 1e-6) -> PartialNDF:
    """Fit the partial NDF of one view by the alternating D / S iteration of eq. (11) and (5).

    Parameters
    ----------
    meas : Measurements of one view
    grid : HalfGrid of the result (default 91 x 180)
    constrained : True for the isotropically constrained S (Wang et al. 2008), False for S from
        the partial D alone (Ngan et al. 2005)
    max_light_theta_deg : lights farther than this from the normal are excluded (the paper
        excludes near-grazing data, where the Fresnel term dominates)
    eta : divide the data by the Fresnel term of eq. (3) with this index; None assumes F = 1
        as the paper's fit does
    max_iter, tol : iteration limit and the relative change of S at which it stops

    Returns
    -------
    PartialNDF, with D in 1/sr times the specular coefficient (the data's scale)
    """
    grid = grid or HalfGrid()
    if not 0.0 < max_light_theta_deg < 90.0:
        raise ValueError(f"max_light_theta_deg = {max_light_theta_deg}: must lie in (0, 90)")
    tg, ig, det, keep = _data_on_grid(meas, grid, np.radians(max_light_theta_deg), eta)
    o = meas.view
    s_i, s_o = np.ones(tg.shape), 1.0
    for it in range(1, max_iter + 1):
        d = tg / (s_i * s_o)
        shadow = _shadow_fn(grid, d, constrained)
        new_i, new_o = np.where(det, shadow(ig), 1.0), float(shadow(o))
        change = max(np.max(np.abs(new_i - s_i) / new_i), abs(new_o - s_o) / new_o)
        s_i, s_o = new_i, new_o
        if change < tol:
            break
    d = tg / (s_i * s_o)
    w = np.where(det, np.sqrt(np.maximum(ig[..., 2], 0.0)), 0.0)
    residual, scale = _residual(meas, keep, grid, d, shadow, eta)
    notes = [f"{'constrained' if constrained else 'unconstrained'} shadowing, {it} iterations "
             f"(last relative change of S {change:.1e})",
             f"{int(keep.sum())} of {len(meas.lights)} lights used "
             f"(theta <= {max_light_theta_deg:g} deg)"]
    part = PartialNDF(grid, d, w, residual, scale, meas.channels, notes, s_o)
    part.notes.append(f"coverage {100 * part.coverage:.1f} % of the hemisphere, relative RMS "
                      f"residual {residual:.2e}")
    return part


def _residual(meas, keep, grid, d, shadow, eta):
    """Relative RMS of model minus data (channel mean) over the used lights whose h is
    determined, and the least-squares scale of each channel against the model."""
    li, vals = meas.lights[keep], meas.values[keep]
    yi = vals.mean(axis=1)
    f = mf.specular_brdf(li, np.broadcast_to(meas.view, li.shape),
                         lambda h: grid.lookup(d, h), shadow, eta)
    ok = np.isfinite(f)
    res = float(np.sqrt(np.sum((f[ok] - yi[ok]) ** 2) / np.sum(yi[ok] ** 2)))
    scale = (vals[ok] * f[ok, None]).sum(axis=0) / max(np.sum(f[ok] ** 2), 1e-300)
    return res, scale

