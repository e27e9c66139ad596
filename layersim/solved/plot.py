"""Pictures of a solved BSDF (matplotlib, Agg, PNG): the four blocks of the scattering operator
and hemispherical slices for one incident direction.

:func:`plot_blocks`
    Like layerlab's ``plot_layer`` (Jakob's layerlab tutorial sec. 4.2): the BSDF of each block
    as an image over ``(mu_i, mu_o)`` in the discrete-ordinates convention (``mu > 0``
    propagates down), arranged ``Rb | Ttb`` over ``Tbt | Rt`` (``mu_o`` upward), for one Fourier
    order ``l`` (the coefficient ``f_l``) or at one azimuth difference ``phi_d`` (the series
    summed), multiplied by ``|mu_i mu_o|`` to keep grazing values in range; each panel has its
    own colour scale, 0 to its 99th percentile by default (``percentile``): the colour bar
    says so and ends in an arrow where brighter values saturate. Opaque stacks show ``Rt``
    only.
:func:`plot_slices`
    ``f(wi, wo)`` over the outgoing hemispheres, on the projected unit disk (``wo.x, wo.y``,
    viewed from above; the transmission disk shows ``wo.z < 0``). On that disk the area element
    is ``|cos theta_o| d omega``, so the picture is the scattered energy density: integrated over
    a disk it gives the albedo of that side. Markers: the incident direction (x) and the
    specular / straight-through directions (+). RGB slices are colour images with a luminance
    scale beside them.

Both accept anything with ``eval(wi, wo)``, ``channels`` and ``opaque`` (a
:class:`layersim.BSDF` or a :class:`layersim.bsdffile.FourierTable`); Fourier orders need a
``BSDF``; for an anisotropic one they are those of its rotational average
(:meth:`~layersim.aniso.operator.AnisoOperator.rotational_average`, the ``s = 0`` terms). RGB shows
the luminance in the block plot and colour images in the slices. Figures are drawn with matplotlib's
object API and the Agg canvas: no global backend is changed.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colors import ListedColormap, Normalize
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from .bsdf import BSDF
from .channels import LUMINANCE
from ..operators.interpolation import spline_weights

#: Panel order of layerlab's plot_layer: (block, mu_i range, mu_o range).
PANELS = (("Tbt", (-1, 0), (-1, 0)), ("Rt", (0, 1), (-1, 0)),
          ("Rb", (-1, 0), (0, 1)), ("Ttb", (0, 1), (0, 1)))
_TITLES = {"Rt": r"$R^{t}$", "Rb": r"$R^{b}$", "Ttb": r"$T^{tb}$", "Tbt": r"$T^{bt}$"}


def _scalar(values: np.ndarray, channels: int, channel) -> np.ndarray:
    if channels == 1:
        return values
    if channel in (None, "luminance", "Y"):
        return values @ LUMINANCE
    return values[..., int(channel)]


def _directions(mu_in, mu_out, dphi):
    """wi, wo with ``wi.z = mu_in``, ``wo.z = -mu_out`` and propagation azimuth difference
    ``dphi`` (the inverse of the conversion in :mod:`layersim.solved.bsdf`)."""
    si = np.sqrt(np.maximum(0.0, 1.0 - mu_in ** 2))
    so = np.sqrt(np.maximum(0.0, 1.0 - mu_out ** 2))
    wi = np.stack([si, np.zeros_like(si), mu_in], axis=-1)
    phi_o = math.pi + dphi
    wo = np.stack([so * np.cos(phi_o), so * np.sin(phi_o) * np.ones_like(so), -mu_out], axis=-1)
    return wi, wo


def _order_coefficient(bsdf: BSDF, c: int, name: str, l: int, mu_out, mu_in) -> np.ndarray:
    """Interpolated ``f_l(mu_out, mu_in)`` of block ``name`` (1/sr), as ``eval`` interpolates."""
    op = bsdf.operators[c]
    if op.blocks[name] is None:
        return np.zeros(mu_out.shape)
    table = bsdf.series_table(c)
    h = op.h
    io, wo_ = spline_weights(op.grid.mu, np.abs(mu_out).ravel())
    ii, wi_ = spline_weights(op.grid.mu, np.abs(mu_in).ravel())
    pair = table.base(name) + (io[:, :, None] * h + ii[:, None, :]).reshape(-1, 16)
    weight = (wo_[:, :, None] * wi_[:, None, :]).reshape(-1, 16)
    start, end = table.offsets[pair], table.offsets[pair + 1]
    has = l < end - start
    vals = np.where(has, table.coef[np.where(has, start + l, 0)], 0.0)
    return np.sum(weight * vals, axis=1).reshape(mu_out.shape)


def block_images(bsdf, order: int | None = None, phi_d: float = 0.0, samples: int = 200,
                 channel=None) -> dict:
    """The four panels of :func:`plot_blocks` as arrays: ``{block: (samples, samples)}`` indexed
    ``[mu_o, mu_i]`` (both increasing over the panel's range), already multiplied by
    ``|mu_i mu_o|``."""
    out = {}
    for name, (i0, i1), (o0, o1) in PANELS:
        # open grids: the ordinates' end points (mu = 0) are on the horizon
        mu_i = i0 + (np.arange(samples) + 0.5) * (i1 - i0) / samples
        mu_o = o0 + (np.arange(samples) + 0.5) * (o1 - o0) / samples
        MI, MO = np.meshgrid(mu_i, mu_o)
        if order is None:
            wi, wo = _directions(MI, MO, phi_d)
            vals = _scalar(np.asarray(bsdf.eval(wi, wo)), bsdf.channels, channel)
        else:
            if not isinstance(bsdf, BSDF):
                raise TypeError("Fourier orders need a layersim BSDF (a .bsdf file converts with "
                                "FourierTable.to_bsdf())")
            if order < 0:
                raise ValueError(f"order must be >= 0, got {order}")
            bsdf = bsdf.rotational_average()    # order l of it: the s = 0 terms if coupled
            per = np.stack([_order_coefficient(bsdf, c, name, order, MO, MI)
                            for c in range(bsdf.channels)], axis=-1)
            vals = _scalar(per if bsdf.channels > 1 else per[..., 0], bsdf.channels, channel)
        out[name] = vals * np.abs(MI * MO)
    return out


def _save(fig: Figure, path) -> Path:
    path = Path(path)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=fig.dpi)
    return path


def present_blocks(bsdf) -> list[str]:
    """The blocks that ``bsdf`` has: all four, or ``Rt`` only for an opaque stack (the others
    are left out of its operator: nothing arrives from below or leaves through the base)."""
    if getattr(bsdf, "opaque", False):
        return ["Rt"]
    return [name for name, _, _ in PANELS]


def colour_scale(vals: np.ndarray, signed: bool, percentile: float) -> tuple:
    """The colour range of one block panel: ``(vmax, extend, note)``. ``vmax`` is the
    ``percentile`` of the values (of their magnitude when ``signed``; the range is then
    ``[-vmax, vmax]``, else ``[0, vmax]``), as layerlab's ``plot_layer`` scales each panel;
    ``extend`` is matplotlib's colour-bar arrow for the sides where values exceed the range
    (``"neither"`` when none do) and ``note`` says what was clipped ("" when nothing was)."""
    vmax = float(np.percentile(np.abs(vals) if signed else vals, percentile))
    vmax = vmax if vmax > 0 else float(np.abs(vals).max() or 1.0)
    over = float(vals.max()) > vmax * (1 + 1e-12)
    under = signed and float(vals.min()) < -vmax * (1 + 1e-12)
    extend = {(True, True): "both", (True, False): "max", (False, True): "min"}.get(
        (over, under), "neither")
    note = ""
    if over or under:
        note = (f"clipped at {percentile:g}th percentile, max {'|value| ' if signed else ''}"
                f"{float(np.abs(vals).max()):.3g}")
    return vmax, extend, note


def plot_blocks(bsdf, path, order: int | None = None, phi_d: float = 0.0, samples: int = 200,
                channel=None, title: str | None = None, percentile: float = 99.0) -> Path:
    """Draw the blocks of the operator into a PNG at ``path``: ``Rb | Ttb`` over ``Tbt | Rt``,
    so that together they cover the ``(mu_i, mu_o)`` square with ``mu_i`` to the right and
    ``mu_o`` upward (layerlab's ``plot_layer`` stacks the rows the other way round); an opaque
    stack has ``Rt`` only, drawn alone.

    Parameters
    ----------
    bsdf : layersim.BSDF or FourierTable
    path : path-like
    order : int, optional
        Show the Fourier coefficient ``f_l`` of this order (signed for ``l >= 1``: diverging
        colour map; anisotropic BSDFs: of their rotational average); default: the BSDF at
        azimuth difference ``phi_d``.
    phi_d : float
        Azimuth difference of the propagation directions (radians; 0 = specular / straight
        through) when ``order`` is None.
    samples : int
        Pixels per panel side.
    channel : None, "luminance" or int
        RGB: what to show (default luminance).
    percentile : float
        Each panel's colour scale ends at this percentile of its values (of their magnitude
        for signed orders), as layerlab's ``plot_layer`` does at 99, so that a narrow peak
        does not leave the rest of the panel dark; brighter values saturate, which the colour
        bar's label and arrow show. 100 shows the full range.
    """
    if not (isinstance(percentile, (int, float)) and 0.0 < percentile <= 100.0):
        raise ValueError(f"percentile must be in (0, 100], got {percentile!r}")
    images = block_images(bsdf, order, phi_d, samples, channel)
    names = present_blocks(bsdf)
    signed = order is not None and order > 0
    quantity = (rf"$f_{{{order}}}\,|\mu_i\,\mu_o|$" if order is not None
                else r"$f\,|\mu_i\,\mu_o|$")
    single = len(names) == 1
    fig = Figure(figsize=(5.6, 4.8) if single else (8.8, 7.6), dpi=100, layout="constrained")
    axes = np.atleast_2d(fig.subplots(1, 1) if single else fig.subplots(2, 2))
    for name, (i0, i1), (o0, o1) in PANELS:
        if name not in names:
            continue
        ax = axes[0, 0] if single else axes[0 if o0 >= 0 else 1, 0 if i0 < 0 else 1]
        vals = images[name]
        vmax, extend, note = colour_scale(vals, signed, percentile)
        im = ax.imshow(vals, extent=[i0, i1, o0, o1], origin="lower", aspect="equal",
                       cmap="RdBu_r" if signed else "viridis",
                       vmin=-vmax if signed else 0.0, vmax=vmax, interpolation="nearest")
        ax.set_title(_TITLES[name])
        ax.set_xlabel(r"$\mu_i$ (incident)")
        ax.set_ylabel(r"$\mu_o$ (outgoing)")
        fig.colorbar(im, ax=ax, shrink=0.85, extend=extend,
                     label=quantity + " [1/sr]" + (f"\n{note}" if note else ""))
    what = (f"Fourier order $l = {order}$: " + quantity if order is not None else
            quantity + rf" at $\phi_d = {math.degrees(phi_d):g}^\circ$")
    if bsdf.channels == 3:
        what += (" (luminance)" if channel in (None, "luminance", "Y")
                 else f" (channel {'RGB'[int(channel)]})")
    if single:
        what += "\nopaque: only $R^{t}$ exists"
    fig.suptitle((title + ": " if title else "") + what)
    return _save(fig, path)


def slice_images(bsdf, wi, resolution: int = 256):
    """``f(wi, wo)`` on the projected unit disk of each side: ``{"reflection": img,
    "transmission": img or None}``, images (res, res) or (res, res, 3), NaN outside the disk;
    row 0 is ``wo.y = -1`` (draw with ``origin="lower"``)."""
    wi = np.asarray(wi, float)
    c = (np.arange(resolution) + 0.5) / resolution * 2.0 - 1.0
    X, Y = np.meshgrid(c, c)
    r2 = X * X + Y * Y
    inside = r2 < 1.0
    z = np.sqrt(np.maximum(0.0, 1.0 - r2))
    sides = {"reflection": 1.0, "transmission": -1.0}
    out = {}
    for side, sgn in sides.items():
        if side == "transmission" and getattr(bsdf, "opaque", False):
            out[side] = None
            continue
        zz = sgn * np.sign(wi[2]) * z
        wo = np.stack([X, Y, zz], axis=-1)[inside]
        wo /= np.linalg.norm(wo, axis=-1, keepdims=True)
        vals = np.asarray(bsdf.eval(wi, wo))
        shape = (resolution, resolution) + vals.shape[1:]
        img = np.full(shape, np.nan)
        img[inside] = vals
        out[side] = img
    return out


def _srgb(lin: np.ndarray) -> np.ndarray:
    """sRGB encoding of linear values in [0, 1]."""
    return np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)


#: Decades of ``f`` that ``log`` pictures show below the largest value.
LOG_DECADES = 4


def _log_tone(rgb: np.ndarray, lum: np.ndarray, top: float):
    """Linear RGB colours ``rgb`` (..., 3) of luminance ``lum`` (...) scaled so that their
    luminance becomes its position on a log scale over :data:`LOG_DECADES` decades below
    ``top`` (0 at ``top / 10^LOG_DECADES`` and below, 1 at ``top``), keeping each colour's
    chromaticity; returns the scaled colours and the matching colour-bar norm (LogNorm)."""
    from matplotlib.colors import LogNorm
    floor = top * 10.0 ** -LOG_DECADES
    level = np.clip(np.log10(np.maximum(lum, floor) / floor) / LOG_DECADES, 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = np.where(lum > 0, level / np.where(lum > 0, lum, 1.0), 0.0)
    return rgb * gain[..., None], LogNorm(floor, top)


def plot_slices(bsdf, wi, path, resolution: int = 256, log: bool = False,
                title: str | None = None) -> Path:
    """Draw hemispherical slices of ``f(wi, .)`` on the projected unit disk into a PNG.

    Parameters
    ----------
    bsdf : layersim.BSDF or FourierTable
    wi : array_like (3,)
        Unit direction toward the light (local frame).
    path : path-like
    resolution : int
        Pixels per disk side.
    log : bool
        Colour by ``log10 f`` (glossy lobes span decades; :data:`LOG_DECADES` shown). RGB
        images keep each pixel's colour and map its luminance, linearly or (``log``) by its
        log10 over those decades, to 0..1 (the largest luminance is 1, sRGB-encoded). Each
        side has its own scale.
    """
    wi = np.asarray(wi, float)
    if wi.shape != (3,) or not np.all(np.isfinite(wi)) or abs(np.linalg.norm(wi) - 1) > 1e-5:
        raise ValueError("wi must be one unit vector of shape (3,)")
    if wi[2] == 0:
        raise ValueError("wi lies on the horizon (wi.z == 0)")
    imgs = slice_images(bsdf, wi, resolution)
    shown = [(k, v) for k, v in imgs.items() if v is not None]
    rgb = bsdf.channels == 3
    fig = Figure(figsize=(max(6.0, 5.2 * len(shown)), 5.2), dpi=100, layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(shown)))
    for ax, (side, img) in zip(axes, shown):
        # each side has its own scale (reflection is often far weaker than transmission)
        finite = img[np.isfinite(img)]
        top = float(finite.max()) if finite.size else 0.0
        floor = top * 10.0 ** -LOG_DECADES if top > 0 else 1e-12
        if rgb:
            img0 = np.nan_to_num(img, nan=0.0)
            lum = img0 @ LUMINANCE
            norm = float(lum.max()) if lum.max() > 0 else 1.0
            if log:
                lin, scale = _log_tone(img0, lum, norm)
                label = r"luminance of $f$ [1/sr], log scale"
            else:
                lin, scale = img0 / norm, Normalize(0.0, norm)
                label = r"luminance of $f$ [1/sr]"
            alpha = np.isfinite(img[..., 0]).astype(float)[..., None]
            ax.imshow(np.concatenate([_srgb(np.clip(lin, 0.0, 1.0)), alpha], axis=-1),
                      extent=[-1, 1, -1, 1], origin="lower", interpolation="nearest")
            # the scale of the image: grey levels encoded as the image is, up to the largest
            # luminance (which is white)
            grey = ListedColormap(np.repeat(_srgb(np.linspace(0, 1, 256))[:, None], 3, 1))
            fig.colorbar(ScalarMappable(scale, grey), ax=ax, shrink=0.8, label=label)
        elif log:
            im = ax.imshow(np.log10(np.maximum(img, floor)), extent=[-1, 1, -1, 1],
                           origin="lower", cmap="inferno", interpolation="nearest",
                           vmin=math.log10(floor), vmax=math.log10(top) if top > 0 else 0)
            fig.colorbar(im, ax=ax, shrink=0.8, label=r"$\log_{10} f$ [1/sr]")
        else:
            im = ax.imshow(img, extent=[-1, 1, -1, 1], origin="lower", cmap="inferno",
                           interpolation="nearest", vmin=0.0, vmax=max(top, 1e-12))
            fig.colorbar(im, ax=ax, shrink=0.8, label=r"$f$ [1/sr]")
        ax.add_patch(Circle((0, 0), 1.0, fill=False, lw=0.8, color="0.5"))
        ax.plot([wi[0]], [wi[1]], "x", color="cyan", ms=8, mew=2, label="incident")
        ax.plot([-wi[0]], [-wi[1]], "+", color="lime", ms=10, mew=2,
                label="specular" if side == "reflection" else "straight through")
        ax.set_xlim(-1.05, 1.05)
        ax.set_ylim(-1.05, 1.05)
        ax.set_aspect("equal")
        ax.set_xlabel(r"$\omega_{o,x}$")
        ax.set_ylabel(r"$\omega_{o,y}$")
        below = (wi[2] > 0) == (side == "transmission")
        ax.set_title(f"{side} " + (r"($\omega_{o,z} < 0$)" if below else
                                   r"($\omega_{o,z} > 0$)"))
        ax.legend(loc="lower left", fontsize=7, framealpha=0.6)
    theta = math.degrees(math.acos(max(-1.0, min(1.0, wi[2]))))
    phi = math.degrees(math.atan2(wi[1], wi[0]))
    fig.suptitle((title + "\n" if title else "")
                 + r"$f(\omega_i, \omega_o)$ on the projected disk; $\omega_i$: "
                 + rf"$\theta = {theta:.1f}^\circ$, $\phi = {phi:.1f}^\circ$")
    return _save(fig, path)
