"""A solved stack's BSDF on whole wavefronts of rays, in Mitsuba 3's terms (numpy only).

This module holds the arithmetic of the plug-in (:mod:`layersim.mitsuba.plugin`) without any
Dr.Jit type, so that it is testable and reusable on its own. Rows are rays: directions are
``(N, 3)`` float64 unit vectors in the local shading frame (``z`` the normal), ``wi`` being
Mitsuba's ``si.wi`` and ``wo`` its ``wo``.

Conventions (Mitsuba 3, ``include/mitsuba/render/bsdf.h``; layersim, docs/conventions.md)
--------------------------------------------------------------------------------------------
* Mitsuba's ``eval`` is ``f(wi, wo) |cos theta_o|``: layersim's ``eval`` times ``|wo.z|``.
* Transport modes. In ``TransportMode.Importance`` Mitsuba's ``wi`` points toward the light,
  exactly layersim's ``wi``, so the value is layersim's ``f(wi, wo)``. In
  ``TransportMode.Radiance`` ``wi`` points toward the camera and light arrives along ``wo``,
  so the value is layersim's ``f(wo, wi)``; by generalized reciprocity (docs/conventions.md)
  ``f(wo, wi) = f(wi, wo) eta_wi^2 / eta_wo^2``, ``eta_w`` the index of the medium that holds
  ``w``. Both modes therefore evaluate the solved series with the same argument order and
  differ by the factor ``(eta_wi / eta_wo)^2`` in transmission, the ``1 / eta^2`` of Mitsuba's
  ``roughdielectric`` (``bs.eta = eta_wo / eta_wi``). Evaluating one order keeps ``eval``,
  ``pdf`` and ``sample`` exactly consistent (``weight = eval / pdf``).
* Components (:data:`GLOSSY_R` ... :data:`DELTA_T`): the smooth part of the solved series in
  reflection and in transmission, and the delta parts of :meth:`layersim.solved.bsdf.BSDF.specular`
  (mirror reflection of smooth interfaces, unscattered transmission), which ``eval`` and
  ``pdf`` leave out (0) and ``sample`` draws as discrete events.
* Sampling picks a component with ``u1`` in proportion to the (luminance) energy each carries
  from ``wi`` among those enabled (``P_smooth``, ``P_delta``), then, for the smooth part,
  draws ``wo`` with layersim's own sampler (:mod:`layersim.solved.sampling`, Jakob et al. 2014,
  sec. 7) from ``u2``. The smooth density is ``P_smooth pdf_layersim``; a delta sample has
  ``pdf = P_delta`` and weight ``energy / P_delta`` (Mitsuba's ``dielectric`` convention).
* A smooth-part sample that lands in a disabled lobe (``ctx`` restricted to reflection or to
  transmission) keeps its density and gets weight 0: the estimator of the restricted BSDF
  stays unbiased.
"""

from __future__ import annotations

import numpy as np

from ..solved.channels import luminance

#: Component indices, in the order of the plug-in's ``m_components``.
GLOSSY_R, GLOSSY_T, DELTA_R, DELTA_T = range(4)


def as_channels(x, channels: int) -> np.ndarray:
    """``x`` of shape ``(N,)`` (one channel) or ``(N, C)`` as ``(N, channels)``."""
    x = np.asarray(x, float)
    return x[:, None] if x.ndim == 1 else x


def lum(x: np.ndarray) -> np.ndarray:
    """Luminance of ``(N, C)`` values: the channel itself for one channel, Rec. 709 for three
    (:data:`layersim.solved.channels.LUMINANCE`, the weights layersim's sampler uses)."""
    return x[:, 0] if x.shape[1] == 1 else luminance(x)


def side_index(bsdf, w: np.ndarray) -> np.ndarray:
    """Index of refraction of the medium holding each direction ``w`` (N, 3): the medium
    above the stack for ``w.z > 0``, the one below otherwise (outside a smooth boundary, its
    outside index)."""
    op = bsdf.operators[0]
    top = bsdf.boundary.get("top", op.eta_top)
    bottom = bsdf.boundary.get("bottom", op.eta_bottom if op.eta_bottom is not None else top)
    return np.where(w[:, 2] > 0, top, bottom)


def transport_factor(bsdf, wi: np.ndarray, wo: np.ndarray, radiance: bool) -> np.ndarray:
    """``(eta_wi / eta_wo)^2`` in radiance mode, 1 in importance mode (N,): the ratio of
    Mitsuba's value to layersim's ``f(wi, wo)`` (module docstring)."""
    if not radiance:
        return np.ones(wi.shape[0])
    return (side_index(bsdf, wi) / side_index(bsdf, wo)) ** 2


def valid_incident(bsdf, wi: np.ndarray, active: np.ndarray) -> np.ndarray:
    """Rows from which light can enter: active, off the horizon, and from above where the
    stack is opaque (N,) bool."""
    ok = active & (wi[:, 2] != 0.0)
    return ok & (wi[:, 2] > 0.0) if bsdf.opaque else ok


def component_probabilities(bsdf, wi: np.ndarray, enabled) -> tuple:
    """Probabilities with which :func:`sample` picks the smooth part and each delta part.

    Parameters
    ----------
    bsdf : layersim.solved.bsdf.BSDF
    wi : ndarray (N, 3)
        Valid incident directions (:func:`valid_incident`).
    enabled : sequence of 4 bool
        Whether each component (:data:`GLOSSY_R` ... :data:`DELTA_T`) is enabled; a
        component the stack lacks must be disabled (the plug-in's flags are ``Empty`` there),
        so that stacks without deltas skip the albedo and delta evaluation.

    Returns
    -------
    p : ndarray (N, 3)
        ``[P_smooth, P_delta_reflect, P_delta_transmit]``, summing to 1 where any enabled
        component carries energy (0 otherwise).
    deltas : ndarray (N, 2, C)
        The energy fraction (per channel) of the mirror and straight-through delta parts.
    deltas_wo : ndarray (N, 2, 3)
        Their directions.
    """
    C = bsdf.channels
    if not (enabled[DELTA_R] or enabled[DELTA_T]):
        glossy = float(enabled[GLOSSY_R] or enabled[GLOSSY_T])
        p = np.zeros((wi.shape[0], 3))
        p[:, 0] = glossy
        return p, np.zeros((wi.shape[0], 2, C)), np.zeros((wi.shape[0], 2, 3))
    R, T = bsdf.albedo(wi)
    spec = bsdf.specular(wi)
    top, bottom = (as_channels(spec[s][0], C) for s in ("top", "bottom"))
    up = (wi[:, 2] > 0)[:, None]
    d_r, d_t = np.where(up, top, bottom), np.where(up, bottom, top)
    smooth = np.maximum(lum(as_channels(R, C) + as_channels(T, C)) - lum(d_r) - lum(d_t), 0.0)
    glossy = enabled[GLOSSY_R] or enabled[GLOSSY_T]
    e = np.stack([smooth * glossy, lum(d_r) * enabled[DELTA_R], lum(d_t) * enabled[DELTA_T]],
                 axis=1)
    total = e.sum(axis=1, keepdims=True)
    p = np.divide(e, total, out=np.zeros_like(e), where=total > 0)
    wo_r = np.where(up, spec["top"][1], spec["bottom"][1])
    wo_t = np.where(up, spec["bottom"][1], spec["top"][1])
    return p, np.stack([d_r, d_t], axis=1), np.stack([wo_r, wo_t], axis=1)


def lobe_enabled(wi: np.ndarray, wo: np.ndarray, enabled) -> np.ndarray:
    """Whether the smooth lobe (reflection or transmission) of each pair is enabled (N,)."""
    reflect = wi[:, 2] * wo[:, 2] > 0
    return np.where(reflect, bool(enabled[GLOSSY_R]), bool(enabled[GLOSSY_T]))


def eval_pdf(bsdf, wi, wo, active, radiance: bool, enabled, want=(True, True)) -> tuple:
    """Mitsuba's ``eval`` and ``pdf`` of the smooth part on a wavefront.

    Parameters
    ----------
    bsdf : layersim.solved.bsdf.BSDF
    wi, wo : ndarray (N, 3)
        Unit directions (Mitsuba's ``si.wi`` and ``wo``), local frame.
    active : ndarray (N,) bool
    radiance : bool
        ``ctx.mode == TransportMode.Radiance``.
    enabled : sequence of 4 bool
        Enabled components (:func:`component_probabilities`).
    want : (bool, bool)
        Whether to compute the value and the pdf (the other stays 0): Mitsuba's ``eval`` and
        ``pdf`` need only one of them.

    Returns
    -------
    value : ndarray (N, C)
        ``f |wo.z|`` (unitless per sr of ``wo``), 0 for inactive rows, disabled lobes and the
        horizon; the delta parts are not included.
    pdf : ndarray (N,)
        ``P_smooth pdf_layersim(wi, wo)`` in 1/sr (the density :func:`sample` draws ``wo``
        with).
    """
    ok = valid_incident(bsdf, wi, active) & (wo[:, 2] != 0.0)
    ok &= lobe_enabled(wi, wo, enabled)
    C = bsdf.channels
    value, pdf = np.zeros((wi.shape[0], C)), np.zeros(wi.shape[0])
    if not ok.any():
        return value, pdf
    a, b = wi[ok], wo[ok]
    if want[0]:
        f = as_channels(bsdf.eval(a, b), C)
        value[ok] = f * (np.abs(b[:, 2]) * transport_factor(bsdf, a, b, radiance))[:, None]
    if want[1]:
        p, _, _ = component_probabilities(bsdf, a, enabled)
        pdf[ok] = p[:, 0] * np.asarray(bsdf.pdf(a, b), float).reshape(-1)
    return value, pdf


def sample(bsdf, wi, u1, u2, active, radiance: bool, enabled) -> dict:
    """Mitsuba's ``sample`` on a wavefront (module docstring).

    Parameters
    ----------
    wi : ndarray (N, 3)
    u1 : ndarray (N,)
        Uniform variate in [0, 1) that picks the component.
    u2 : ndarray (N, 2)
        Uniform variates in [0, 1) for the direction within the smooth part.
    active, radiance, enabled
        As in :func:`eval_pdf`.

    Returns
    -------
    dict
        ``wo`` (N, 3), ``weight`` (N, C) (``eval / pdf``; for deltas ``energy / P``),
        ``pdf`` (N,) (1/sr, or the discrete probability of a delta), ``component`` (N,) int
        (:data:`GLOSSY_R` ...), ``eta`` (N,) (``eta_wo / eta_wi``, 1 in reflection). Rows
        with nothing drawn have ``pdf = 0`` and ``weight = 0``.
    """
    N, C = wi.shape[0], bsdf.channels
    out = {"wo": np.zeros((N, 3)), "weight": np.zeros((N, C)), "pdf": np.zeros(N),
           "component": np.zeros(N, np.int64), "eta": np.ones(N)}
    rows = np.flatnonzero(valid_incident(bsdf, wi, active))
    if rows.size == 0:
        return out
    p, energy, d_wo = component_probabilities(bsdf, wi[rows], enabled)
    cdf = np.cumsum(p, axis=1)
    pick = np.minimum((u1[rows, None] >= cdf).sum(axis=1), 2)
    pick[cdf[:, -1] <= 0] = -1
    _fill_smooth(bsdf, out, wi, u2, rows[pick == 0], p[pick == 0, 0], radiance, enabled)
    for k in (1, 2):
        sel = pick == k
        r = rows[sel]
        out["wo"][r] = d_wo[sel, k - 1]
        out["pdf"][r] = p[sel, k]
        f = transport_factor(bsdf, wi[r], out["wo"][r], radiance)
        out["weight"][r] = energy[sel, k - 1] * (f / p[sel, k])[:, None]
        out["component"][r] = DELTA_R if k == 1 else DELTA_T
    _set_eta(bsdf, out, wi)
    return out


def _fill_smooth(bsdf, out, wi, u2, rows, p_smooth, radiance, enabled) -> None:
    """Rows ``rows`` of :func:`sample`'s ``out`` from layersim's sampler of the smooth part,
    chosen with probability ``p_smooth`` (per row)."""
    if rows.size == 0:
        return
    a = wi[rows]
    s = bsdf.sample(a, np.clip(u2[rows], 0.0, np.nextafter(1.0, 0.0)))
    pdf = np.asarray(s.pdf, float).reshape(-1)
    ok = (pdf > 0) & lobe_enabled(a, s.wo, enabled)
    f = transport_factor(bsdf, a, s.wo, radiance) * ok
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(ok, f / p_smooth, 0.0)
    out["wo"][rows] = s.wo
    out["pdf"][rows] = np.where(pdf > 0, pdf * p_smooth, 0.0)
    out["weight"][rows] = as_channels(s.weight, bsdf.channels) * scale[:, None]
    out["component"][rows] = np.where(a[:, 2] * s.wo[:, 2] > 0, GLOSSY_R, GLOSSY_T)


def _set_eta(bsdf, out, wi) -> None:
    """``eta = eta_wo / eta_wi`` in transmission (Mitsuba's ``BSDFSample3f.eta``), else 1."""
    wo = out["wo"]
    crosses = (wi[:, 2] * wo[:, 2] < 0)
    ratio = side_index(bsdf, wo) / side_index(bsdf, wi)
    out["eta"] = np.where(crosses, ratio, 1.0)
