"""The reconstruction error of an RGL file: how far the file, evaluated as the renderers
evaluate it (:class:`~layersim.bsdffile.rgl_table.RGLTable`, or a renderer itself), is from
the solved BSDF it was written from, as the relative L2 error of ``f cos(theta_o)`` over
direction pairs (:func:`reconstruction_error`).
"""

from __future__ import annotations

import numpy as np

from ..solved.bsdf import BSDF
from . import rgl_color
from .rgl_table import RGLTable

#: Direction pairs of the error estimate.
ERROR_SAMPLES = 8192


def cosine_directions(rng, count: int, max_sin: float = 1.0) -> np.ndarray:
    """Cosine-distributed directions (count, 3) over the upper hemisphere, within
    ``sin(theta) <= max_sin``."""
    u = rng.random((count, 2))
    r, phi = max_sin * np.sqrt(u[:, 0]), 2 * np.pi * u[:, 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - r * r)], -1)


def uniform_directions(rng, count: int) -> np.ndarray:
    """Uniform directions (count, 3) over the upper hemisphere (density 1 / (2 pi))."""
    u = rng.random((count, 2))
    z, phi = u[:, 0], 2 * np.pi * u[:, 1]
    r = np.sqrt(np.maximum(1 - z * z, 0.0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


def channel_values(table: RGLTable, wi, wo, channels: int, wavelengths=None) -> np.ndarray:
    """``f cos(theta_o)`` (n, channels) of the file at renderer directions ``wi`` (camera),
    ``wo`` (light), read back as layersim's channels: the ``rgb`` field's channels, the
    spectrum at each channel's wavelength, or (RGB written as spectra) the sRGB value of the
    spectrum (:mod:`layersim.bsdffile.rgl_color`)."""
    if table.wavelengths is None:
        out = table.eval(wi, wo, np.arange(3.0))
        return out[:, :1] if channels == 1 else out
    if wavelengths is not None:
        return table.eval(wi, wo, np.asarray(wavelengths, np.float64))
    if channels == 1:
        return table.eval(wi, wo, [550.0])
    return rgl_color.to_rgb(table.eval(wi, wo, rgl_color.WAVELENGTHS))


def reconstruction_error(bsdf: BSDF, table: RGLTable, wavelengths=None,
                         samples: int = ERROR_SAMPLES, seed: int = 0, evaluate=None,
                         max_theta_i: float = np.pi / 2) -> float:
    """Relative L2 error of the file's ``f cos(theta_o)`` against ``bsdf.eval`` (times the
    cosine) over direction pairs, all channels together.

    ``wi`` (the renderer's camera side) is drawn cosine-distributed; ``wo`` half from
    ``bsdf.sample`` (so the pairs sit where the lobe carries energy) and half uniformly
    over the hemisphere (so that no region is missed), and every pair is weighted by
    ``1 / p``, ``p = (pdf_bsdf + 1 / (2 pi)) / 2`` the mixture's density: the ratio
    ``sqrt(sum |F_file - F|^2 / p) / sqrt(sum F^2 / p)`` estimates
    ``||F_file - F|| / ||F||`` in L2 over the outgoing hemisphere, averaged over ``wi``.
    ``evaluate(wi, wo)`` -> (n, channels) replaces the numpy reconstruction
    (:func:`channel_values`), e.g. by a renderer's own evaluation of the file;
    ``max_theta_i`` (radians) restricts ``wi`` to elevations up to it (the cosine
    distribution cut there), to separate grazing incidence, where most of the error is.
    """
    rng = np.random.default_rng(seed)
    half = samples // 2
    wi = cosine_directions(rng, 2 * half, np.sin(min(max_theta_i, np.pi / 2)))
    drawn = bsdf.sample(wi[:half], rng.random((half, 2)))
    wo = np.concatenate([np.asarray(drawn.wo), uniform_directions(rng, half)])
    # pairs drawn below the horizon (transmission) or invalid add nothing to either sum:
    # the file and the reflection it stands for are zero there
    up = np.isfinite(wo).all(-1) & (wo[:, 2] > 0)
    wi, wo = wi[up], wo[up]
    p = 0.5 * np.asarray(bsdf.pdf(wi, wo)) + 0.5 / (2 * np.pi)
    ref = np.asarray(bsdf.eval(wo, wi)).reshape(len(wi), -1) * wo[:, 2:3]
    got = channel_values(table, wi, wo, bsdf.channels, wavelengths) if evaluate is None \
        else np.asarray(evaluate(wi, wo), np.float64).reshape(len(wi), -1)
    den = np.sum(ref ** 2 / p[:, None])
    return float(np.sqrt(np.sum((got - ref) ** 2 / p[:, None]) / den)) if den > 0 else 0.0
