"""Colour channels of a solved BSDF: luminance, the (Y, R, B) storage of RGB files, and the
channel-aligned series table that both share.

A BSDF solved from an RGB scene carries one operator per channel (R, G, B), each with its own
sparsity pattern. Renderers and the importance sampler want one table in which every ordinate
pair has the same series length in all channels; :func:`aligned_series` builds it.

Luminance uses the Rec. 709 / sRGB primaries (the weights layerlab and Mitsuba use for the ``Y``
channel of ``.bsdf`` files); files store ``Y, R, B`` and reconstruct green as
``G = (Y - 0.212671 R - 0.072169 B) / 0.715160`` (:func:`green_from_ybr`).

References: ITU-R BT.709-6, item 3.2 (luminance weights); layerlab ``BSDFStorage::fromLayerRGB``.
"""

from __future__ import annotations

import numpy as np

#: Rec. 709 luminance weights of linear (R, G, B).
LUMINANCE = np.array([0.212671, 0.715160, 0.072169])


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Luminance ``Y`` of linear RGB values with a trailing axis of 3."""
    rgb = np.asarray(rgb, float)
    if rgb.shape[-1] != 3:
        raise ValueError(f"luminance needs a trailing RGB axis of 3, got shape {rgb.shape}")
    return rgb @ LUMINANCE


def green_from_ybr(y, r, b):
    """Green from luminance, red and blue: the inverse of :func:`luminance` for G."""
    return (np.asarray(y) - LUMINANCE[0] * np.asarray(r) - LUMINANCE[2] * np.asarray(b)) \
        / LUMINANCE[1]


def aligned_series(bsdf) -> tuple[np.ndarray, np.ndarray]:
    """All channels of a BSDF as one table of per-pair cosine series with a common layout.

    Parameters
    ----------
    bsdf : layersim.BSDF

    Returns
    -------
    offsets : int64 ndarray, shape (4 h^2 + 1,)
        Pair ``p`` (block-major, then outgoing node, then incident node, as in
        :class:`layersim.solved.isobsdf.SeriesTable`) owns ``coef[offsets[p]:offsets[p + 1]]``; its
        length is the longest series of that pair over all channels.
    coef : float64 ndarray, shape (C, channels)
        ``f_l(mu_o, mu_i)`` in 1/sr for ``l = 0, 1, ...`` of every pair, per channel (zero-padded
        where a channel's series is shorter). The unscattered delta of media is not included.
    """
    tables = [bsdf.series_table(c) for c in range(bsdf.channels)]
    counts = np.max([np.diff(t.offsets) for t in tables], axis=0)
    offsets = np.zeros(counts.size + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    coef = np.zeros((int(offsets[-1]), len(tables)))
    for c, t in enumerate(tables):
        cnt = np.diff(t.offsets)
        pair = np.repeat(np.arange(cnt.size), cnt)
        order = np.arange(t.coef.size) - np.repeat(t.offsets[:-1], cnt)
        coef[offsets[pair] + order, c] = t.coef
    return offsets, coef


def luminance_series(bsdf) -> tuple[np.ndarray, np.ndarray]:
    """The luminance of a BSDF as one cosine-series table (``offsets``, ``coef`` of shape (C,));
    for a one-channel BSDF, that channel itself."""
    offsets, coef = aligned_series(bsdf)
    if coef.shape[1] == 1:
        return offsets, coef[:, 0].copy()
    if coef.shape[1] != 3:
        raise ValueError(f"luminance is defined for 1 or 3 channels, not {coef.shape[1]}")
    return offsets, coef @ LUMINANCE
