"""The RGL material format (Dupuy & Jakob 2018) that Mitsuba 3's ``measured`` plug-in and
pbrt-v4's ``MeasuredBxDF`` load: writer, reader and a numpy evaluation of the file as both
renderers reconstruct it.

**Reflection only.** The format holds the reflection of one side: renderers treat the
material as one-sided (Mitsuba: black from behind; pbrt-v4: the same table from both sides)
and it has no transmission. The writer tabulates the top-side reflection of the solved BSDF;
what a stack transmits and how it reflects light from below are not in the file (the export
says so when the stack transmits).

Fields (a :mod:`layersim.bsdffile.tensorfile`; float32 unless said)
-------------------------------------------------------------------
=============== ========================= ====================================================
``description`` uint8 (len,)              UTF-8 text
``jacobian``    uint8 (1,)                1: values are divided by ``D(h) / (4 sigma(wi))``
``theta_i``     (T,)                      incident elevations of the slices (radians)
``phi_i``       (P,)                      incident azimuths; ``P <= 2``: isotropic (one slice
                                          row, half-vector azimuths relative to ``phi_i``);
                                          else ``2 pi / (phi_i[-1] - phi_i[0])`` is the
                                          symmetry reduction (pbrt-v4 accepts only 1)
``ndf``         (Np, Nt)                  ``D`` in 1/sr at ``(u, v)`` nodes of the half vector
``sigma``       (Np, Nt)                  projected area ``sigma(wi)`` at ``(u, v)`` of ``wi``
``vndf``        (P, T, Hp, Ht)            visible-normal density in ``(u, v)`` per slice
``luminance``   (P, T, n, n)              density of the sample square per slice (sampling)
``spectra``     (P, T, L, n, n)           remainder ``R`` per wavelength on the sample square
``wavelengths`` (L,)                      nm, increasing
``rgb``         (P, T, 3, n, n)           instead of ``spectra``/``wavelengths``: Mitsuba 3's
                                          RGB flavour (its RGB variants only)
=============== ========================= ====================================================

Reconstruction (Mitsuba 3 ``measured.cpp``, pbrt-v4 ``MeasuredBxDF::f``): for ``wi`` (toward
the camera) and ``wo`` (toward the light), ``h = normalize(wi + wo)``,
``u = sqrt(2 theta / pi)``, ``v = (phi + pi) / (2 pi)`` (:mod:`layersim.bsdffile.rgl_ndf`);
the visible-normal warp of the slice at ``(phi_i, theta_i)`` (a
:class:`~layersim.bsdffile.marginal2d.Marginal2D`, linear between slices) is inverted at
``(u_h, v_h)`` to a point ``s`` of the unit square, and

    f(wi, wo) cos(theta_o) = R(s; phi_i, theta_i, lambda) D(u_h, v_h) / (4 sigma(u_i, v_i)),

``R`` bilinear in ``s`` and linear in ``phi_i``, ``theta_i``, ``lambda`` (clamped at the
ends). Sampling draws ``s`` from ``luminance``, warps it through the VNDF and reflects ``wi``
about ``h``; the density of ``wo`` is ``vndf(u_h) luminance(s) / (8 pi^2 u_h sin(theta_h)
(wi . h))``.

How layersim fills it (:func:`build`)
-------------------------------------
``D`` is the retro-reflection NDF of the solved BSDF (:mod:`layersim.bsdffile.rgl_ndf`, which
says why), ``vndf`` is ``D(h) max(0, wi . h)`` times the Jacobian ``u sin(theta_h)`` of the
``(u, v)`` square. Points of the ``n x n`` sample square of every slice are warped to their
half vectors exactly as the renderers warp them, and ``R(s)`` is the solved BSDF there,
``f cos(theta_o) 4 sigma(wi) / D(h)`` with ``D`` and ``sigma`` as the renderer interpolates
them: at the nodes first, then the node values are fitted by weighted least squares to the
BSDF at four points per cell, so that the bilinear interpolant the renderers use has the
least L2 error over the outgoing hemisphere (:mod:`layersim.bsdffile.rgl_fit`, which says
why node values alone are not enough). What is left, :func:`reconstruction_error` measures.
``luminance`` is the Rec. 709 luminance (RGB) or the value (one channel) of ``R``, so that
sampling follows ``f cos(theta_o)``. Incident elevations:
``theta_i = THETA_MAX (1 - (1 - k / (T - 1))^2)``, dense toward grazing (:func:`_slices`;
renderers clamp above the last one, 89.9 degrees); anisotropic BSDFs get ``P`` azimuths
over ``[-pi, pi]`` (reduction 1, the only one pbrt-v4 reads).

Colour
------
The renderers interpolate ``spectra`` in wavelength. One channel is written as a constant
spectrum (nodes at 360 and 830 nm). Channels with wavelengths (``[stack] wavelengths``,
``wavelengths=``) are written at those wavelengths, linear between them. Three channels
without wavelengths are RGB: ``color="spectral"`` writes each direction's spectrum as
``sum_k c_k B_k(lambda)`` with three fixed smooth basis spectra whose sRGB values under D65
are the unit vectors (:mod:`layersim.bsdffile.rgl_color`), so that a spectral renderer
returns the channels; ``color="rgb"`` writes the ``rgb`` field that Mitsuba 3's RGB variants
read exactly (pbrt-v4 does not read it).

References: Dupuy & Jakob 2018, "An adaptive parameterization for efficient material
acquisition and rendering", ACM TOG 37(6); Mitsuba 3 ``src/bsdfs/measured.cpp``; pbrt-v4
``src/pbrt/bxdfs.cpp`` (``MeasuredBxDFData::Create``, ``MeasuredBxDF``).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..solved.bsdf import BSDF
from ..errors import InfeasibleError
from . import rgl_color, rgl_fit
from .marginal2d import Marginal2D
from .rgl_ndf import FLOOR, THETA_MAX, direction, retro_ndf, theta2u, u2phi, u2theta
from .rgl_error import ERROR_SAMPLES, channel_values, reconstruction_error
from .rgl_table import RGLTable, read

__all__ = ["DEFAULT_RESOLUTION", "RGLExport", "RGLTable", "build", "channel_values", "export",
           "read", "reconstruction_error", "resolution_grid"]

#: Side of the sample square per slice (``n``) when none is given: benchmarks/features/
#: rgl_export.txt (see :func:`resolution_grid`).
DEFAULT_RESOLUTION = 32
#: Rec. 709 luminance weights (the sampling weight of the RGB flavour).
LUMA = np.array([0.2126, 0.7152, 0.0722])


def resolution_grid(n: int, anisotropic: bool) -> dict:
    """The table sizes of resolution ``n`` (the sample square's side): ``n / 2`` incident
    elevations, ``n / 2 + 1`` incident azimuths (anisotropic) and ``2 n`` nodes per side of
    the NDF and VNDF tables (the warp's own resolution limits how narrow a lobe it
    follows)."""
    if not 4 <= n <= 256:
        raise ValueError(f"resolution {n}: must be within [4, 256]")
    return {"n": n, "theta_i": max(n // 2, 4), "phi_i": n // 2 + 1 if anisotropic else 1,
            "ndf_theta": 2 * n, "ndf_phi": 2 * n if anisotropic else 2}


@dataclass
class RGLExport:
    """What :func:`export` wrote: the table, the file, its size, the time it took, the
    reconstruction error (relative L2 of ``f cos(theta_o)``, :func:`reconstruction_error`)
    over all incident directions and within 80 degrees of the normal (grazing incidence
    carries most of the error and most of its scatter), and notes (e.g. the transmission
    the format cannot hold)."""

    path: Path
    table: RGLTable
    error: float
    error_to_80: float
    seconds: float
    notes: list

    @property
    def bytes(self) -> int:
        return self.path.stat().st_size


def check_exportable(bsdf) -> list:
    """Refuse what the format cannot hold (before any work); return notes on what it drops."""
    if not isinstance(bsdf, BSDF):
        raise TypeError("the RGL export takes a solved BSDF (from layersim.solve or BSDF.load), "
                        f"got {type(bsdf).__name__}")
    for c, op in enumerate(bsdf.operators):
        if bsdf.boundary or "Rt" in op.delta:
            raise InfeasibleError(
                f"channel {c}: this BSDF has a mirror (delta) reflection on its top side (a "
                "smooth interface, roughness 0), which an RGL file cannot hold (it tabulates "
                "a function of the directions); give the top interface a roughness > 0, or "
                "keep the solved BSDF (BSDF.save)")
    if bsdf.channels not in (1, 3):
        raise ValueError(f"the RGL export takes one or three channels, this BSDF has "
                         f"{bsdf.channels}")
    if bsdf.opaque:
        return []
    return ["the stack transmits light, and the RGL format holds reflection only: the file "
            "has the top-side reflection; its transmission and its reflection of light "
            "arriving from below are not in it (renderers show the back side black "
            "(Mitsuba 3) or mirror the top side (pbrt-v4))"]


def colour_mode(channels: int, wavelengths, color: str):
    """``(to_spectra, lam)``: how channel values become the file's ``spectra`` (a function of
    an array (..., channels) returning (..., len(lam))) and its wavelengths (None for the
    ``rgb`` field). See the module docstring, "Colour"."""
    if color not in ("spectral", "rgb"):
        raise ValueError(f"color {color!r}: must be 'spectral' or 'rgb'")
    if color == "rgb":
        if wavelengths is not None:
            raise ValueError("color 'rgb' writes channels, not wavelengths: leave wavelengths "
                             "out (or write color='spectral')")
        return (lambda v: np.repeat(v, 3, axis=-1) if channels == 1 else v), None
    if wavelengths is not None:
        lam = np.asarray(wavelengths, np.float64).ravel()
        if lam.size != channels or not np.all(np.isfinite(lam)) or np.any(lam <= 0) \
                or len(np.unique(lam)) != lam.size:
            raise ValueError(f"wavelengths {', '.join(f'{x:g}' for x in lam)}: give "
                             f"{channels} distinct positive value(s) in nm, one per channel")
        order = np.argsort(lam)
        return (lambda v: v[..., order]), lam[order]
    if channels == 1:
        return (lambda v: np.repeat(v, 2, axis=-1)), np.array([360.0, 830.0])
    return rgl_color.to_spectra, rgl_color.WAVELENGTHS


#: Incident elevations of ``T`` slices as functions of ``x = k / (T - 1)``: "grazing" (the
#: default) is dense toward grazing, where a layered BSDF changes fastest (Fresnel, the lobe
#: moving toward the horizon); benchmarks/features/rgl_export.txt compares the three.
SPACINGS = {"grazing": lambda x: THETA_MAX * (1.0 - (1.0 - x) ** 2),
            "uniform": lambda x: THETA_MAX * x,
            "cosine": lambda x: np.arccos(1.0 - x * (1.0 - np.cos(THETA_MAX)))}


def _slices(grid: dict, spacing: str = "grazing"):
    """Incident nodes: ``theta_i`` (T,) by :data:`SPACINGS`, ``phi_i`` (P,) and the
    directions (P, T, 3)."""
    theta_i = SPACINGS[spacing](np.linspace(0.0, 1.0, grid["theta_i"]))
    phi_i = np.linspace(-np.pi, np.pi, grid["phi_i"]) if grid["phi_i"] > 1 else np.zeros(1)
    return theta_i, phi_i, direction(theta_i[None, :], phi_i[:, None])


def _vndf(ndf: np.ndarray, wi: np.ndarray, size: int, isotropic: bool) -> np.ndarray:
    """Visible-normal densities (P, T, size, size) in ``(u, v)`` of the slices' ``wi``:
    ``D(h) max(0, wi . h) u sin(theta_h)`` (``v`` relative to ``phi_i`` when isotropic, as
    the renderers evaluate ``D`` at that ``v``)."""
    u, v = np.meshgrid(np.linspace(0, 1, size), np.linspace(0, 1, size), indexing="xy")
    d = Marginal2D(ndf, normalize=False).eval(np.stack([u.ravel(), v.ravel()], -1))
    theta = u2theta(u)
    phi = u2phi(v)[None, None] + (np.arctan2(wi[..., 1], wi[..., 0])[..., None, None]
                                  if isotropic else 0.0)
    h = direction(theta[None, None], phi)
    cos = np.maximum(np.einsum("ptk,ptyxk->ptyx", wi, h), 0.0)
    return d.reshape(size, size) * cos * u * np.sin(theta)


def _warped(bsdf, wi, table: RGLTable, params, s: np.ndarray):
    """The BSDF at the points ``s`` (N, 2) of every slice's sample square, warped to half
    vectors as the renderers warp them: ``f cos(theta_o)`` (P T N, channels), whether ``wo``
    is above the horizon (P T N,), ``J = D(h) / (4 sigma(wi))`` and the density of ``wo``
    under the warp (both 1/sr, (P T N,))."""
    count = len(s)
    s = np.tile(s, (wi.shape[0] * wi.shape[1], 1))
    par = tuple(np.repeat(p.reshape(-1), count) for p in params)
    u_m, density = table.warp("vndf").sample(s, par)
    wi_r = np.repeat(wi.reshape(-1, 3), count, axis=0)
    theta = u2theta(u_m[:, 0])
    h = direction(theta, u2phi(u_m[:, 1]) + (par[0] if table.isotropic else 0.0))
    cos_ih = np.sum(wi_r * h, -1)
    wo = 2 * cos_ih[:, None] * h - wi_r
    up = wo[:, 2] > 0
    f = np.zeros((len(wo), bsdf.channels))
    for a in range(0, len(wo), 1 << 16):            # bounded memory in eval
        sl = slice(a, a + (1 << 16))
        ok = up[sl]
        w = wo[sl][ok] / np.linalg.norm(wo[sl][ok], axis=-1, keepdims=True)
        val = np.asarray(bsdf.eval(w, wi_r[sl][ok])).reshape(len(w), -1)
        f[np.arange(len(wo))[sl][ok]] = val * w[:, 2:3]
    u_i = np.stack([theta2u(par[1]), (par[0] + np.pi) / (2 * np.pi)], -1)
    jac = table.warp("ndf").eval(u_m) / (4 * table.warp("sigma").eval(u_i))
    dwo = np.maximum(2 * np.pi ** 2 * u_m[:, 0] * np.sin(theta), 1e-6) * 4 * cos_ih
    return f, up, jac, density / np.maximum(dwo, 1e-30)


def _remainder(bsdf, wi, table: RGLTable, params, n: int,
               per_cell: int = rgl_fit.PER_CELL) -> np.ndarray:
    """``R`` (P, T, n, n, channels) at the nodes of each slice's sample square: the BSDF's
    ``f cos(theta_o) 4 sigma(wi) / D(h)`` there (:func:`fill_hidden` below the horizon),
    then fitted by least squares over each cell (:mod:`layersim.bsdffile.rgl_fit`)."""
    P, T = wi.shape[:2]
    x = np.linspace(0.0, 1.0, n)
    nodes = np.stack([g.ravel() for g in np.meshgrid(x, x, indexing="xy")], -1)
    f, up, jac, _ = _warped(bsdf, wi, table, params, nodes)
    r0 = fill_hidden((f / np.maximum(jac, 1e-30)[:, None]).reshape(P, T, n, n, -1),
                     up.reshape(P, T, n, n))
    if per_cell == 0:                         # node values only (a study's baseline)
        return r0
    pts = rgl_fit.cell_points(n, per_cell)
    A = rgl_fit.bilinear_matrix(pts, n)
    f, up, jac, density = _warped(bsdf, wi, table, params, pts)
    omega = np.where(up, 1.0 / np.maximum(density, 1e-30), 0.0)
    shape = (P * T, len(pts))
    f, jac, omega = f.reshape(shape + (-1,)), jac.reshape(shape), omega.reshape(shape)
    out = np.empty_like(r0)
    for k, (p, t) in enumerate(np.ndindex(P, T)):
        out[p, t] = rgl_fit.fit_slice(A, jac[k], f[k], omega[k],
                                      r0[p, t].reshape(n * n, -1)).reshape(n, n, -1)
    return out


def _fill_along(r: np.ndarray, valid: np.ndarray, axis: int):
    """Nodes not ``valid`` take the value of the nearest valid node before them along
    ``axis`` of (P, T, n, n) (else the nearest after); returns the values and validity."""
    n = r.shape[axis]
    shape = [1] * valid.ndim
    shape[axis] = n
    idx = np.arange(n).reshape(shape)
    fwd = np.maximum.accumulate(np.where(valid, idx, -1), axis=axis)
    bwd = np.flip(np.minimum.accumulate(np.flip(np.where(valid, idx, n), axis), axis), axis)
    src = np.where(fwd >= 0, fwd, np.minimum(bwd, n - 1))
    ok = np.take_along_axis(valid, src, axis)
    return np.take_along_axis(r, src[..., None], axis), ok


def fill_hidden(r: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Give the nodes whose reflected direction lies below the horizon (``valid`` False) the
    value of a valid neighbour, first along ``x`` (elevation) then along ``y``.

    The renderers never return those directions (they require ``cos(theta_o) > 0``), so the
    values are free; but the bilinear interpolant uses them between a node below the
    horizon and one above: a zero there would pull the whole last cell toward zero, and
    the last cells span most of a lobe's tail (the warp leaves the tail few nodes)."""
    out, ok = _fill_along(r, valid, axis=3)
    rows = ok.any(axis=3, keepdims=True)
    out2, _ = _fill_along(out, np.broadcast_to(rows, ok.shape), axis=2)
    return np.where(rows[..., None], out, out2)


def _luminance(r: np.ndarray) -> np.ndarray:
    """Sampling weight (P, T, n, n) from the remainder (P, T, n, n, channels): its
    luminance, floored at 1e-4 of each slice's largest so that no cell where the
    interpolated BSDF is positive has zero density."""
    lum = np.maximum(r @ LUMA if r.shape[-1] == 3 else r[..., 0], 0.0)
    top = lum.max(axis=(2, 3), keepdims=True)
    return np.where(top > 0, np.maximum(lum, 1e-4 * top), 1.0)


def build(bsdf: BSDF, resolution: int | None = None, wavelengths=None,
          color: str = "spectral", description: str = "", *, theta_spacing: str = "grazing",
          ndf_floor: float = FLOOR, per_cell: int = rgl_fit.PER_CELL) -> RGLTable:
    """The RGL table of the top-side reflection of ``bsdf`` (module docstring).

    Parameters
    ----------
    bsdf : BSDF
        A solved BSDF without a mirror reflection on top (one or three channels).
    resolution : int, optional
        Side ``n`` of each slice's sample square (:func:`resolution_grid`; default
        :data:`DEFAULT_RESOLUTION`).
    wavelengths : sequence of float, optional
        Vacuum wavelength (nm) of each channel (``[stack] wavelengths``).
    color : {"spectral", "rgb"}
        The ``spectra`` field (Mitsuba 3 spectral variants, pbrt-v4) or the ``rgb`` field
        (Mitsuba 3 RGB variants).
    theta_spacing, ndf_floor, per_cell
        Design choices, for studies (benchmarks/features/rgl_export.py): the incident
        elevations (:data:`SPACINGS`), the NDF's floor (:data:`rgl_ndf.FLOOR`) and the fit's
        points per cell side (:data:`rgl_fit.PER_CELL`; 0: node values, no fit).
    """
    check_exportable(bsdf)
    to_spectra, lam = colour_mode(bsdf.channels, wavelengths, color)
    grid = resolution_grid(DEFAULT_RESOLUTION if resolution is None else int(resolution),
                           bsdf.anisotropic)
    theta_i, phi_i, wi = _slices(grid, theta_spacing)

    def retro(w):
        return np.asarray(bsdf.eval(w, w)).reshape(w.shape[:-1] + (-1,)).mean(axis=-1)

    ndf, sigma = retro_ndf(retro, grid["ndf_theta"], grid["ndf_phi"], floor=ndf_floor)
    n, size = grid["n"], grid["ndf_theta"]
    table = RGLTable(theta_i=theta_i, phi_i=phi_i, ndf=ndf, sigma=sigma,
                     vndf=_vndf(ndf, wi, size, not bsdf.anisotropic),
                     luminance=np.ones(wi.shape[:2] + (n, n)), spectra=None, wavelengths=lam,
                     description=description)
    params = np.meshgrid(phi_i, theta_i, indexing="ij")
    r = _remainder(bsdf, wi, table, params, n, per_cell)
    table.spectra = np.moveaxis(to_spectra(r), -1, 2)
    table.luminance = _luminance(r)
    return table


def export(bsdf: BSDF, path, resolution: int | None = None, wavelengths=None,
           color: str = "spectral", samples: int = ERROR_SAMPLES, seed: int = 0,
           name: str = "") -> RGLExport:
    """Write the top-side reflection of ``bsdf`` as an RGL file (Mitsuba 3 ``measured``,
    pbrt-v4 ``measured``) and measure its reconstruction error (:func:`build`,
    :func:`reconstruction_error`). A stack that transmits is written with a warning: the
    format holds reflection only."""
    start = time.perf_counter()
    notes = check_exportable(bsdf)
    for note in notes:
        warnings.warn(note, stacklevel=2)
    text = (f"layersim RGL export{': ' + name if name else ''}; top-side reflection only; "
            f"resolution {DEFAULT_RESOLUTION if resolution is None else resolution}")
    table = build(bsdf, resolution, wavelengths, color, description=text)
    path = table.write(path)
    seconds = time.perf_counter() - start
    error = reconstruction_error(bsdf, table, wavelengths, samples, seed)
    error_80 = reconstruction_error(bsdf, table, wavelengths, samples, seed,
                                    max_theta_i=np.radians(80.0))
    return RGLExport(Path(path), table, error, error_80, seconds, notes)
