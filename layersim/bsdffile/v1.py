"""Version 1 of the ``.bsdf`` layout (layerlab, Mitsuba 0.6, pbrt-v3): per file pair the
cosine series ``a_l = f_l |mu_o|`` of an isotropic BSDF (:mod:`layersim.bsdffile`)."""

from __future__ import annotations

import numpy as np

from ..solved.channels import LUMINANCE, aligned_series
from .layout import integrate_catmull_rom


def layout_v1(bsdf, file_of, mu_out, nodes):
    """Version 1: ``(offsets, lengths, coef, cdf, 0)`` of an isotropic BSDF (cosine series
    ``a_l = f_l |mu_o|`` per file pair, channel-major Y, R, B)."""
    N = nodes.size
    offsets_al, coef_al = aligned_series(bsdf)
    if bsdf.channels == 3:
        coef_al = np.stack([coef_al @ LUMINANCE, coef_al[:, 0], coef_al[:, 2]], axis=1)
    ours = np.flatnonzero(file_of >= 0)
    length = np.zeros(N * N, np.int64)
    src = np.zeros(N * N, np.int64)                 # first aligned coefficient of the pair
    scale = np.zeros(N * N)
    length[file_of[ours]] = np.diff(offsets_al)[ours]
    src[file_of[ours]] = offsets_al[:-1][ours]
    scale[file_of[ours]] = mu_out[ours]
    nch = bsdf.channels
    pairs = np.flatnonzero(length > 0)
    L = length[pairs]
    order = np.arange(L.sum()) - np.repeat(np.cumsum(L) - L, L)
    rows = np.repeat(src[pairs], L) + order          # aligned coefficient of each entry
    vals = coef_al[rows] * np.repeat(scale[pairs], L)[:, None]     # (entries, nch)
    per_pair = length * nch
    offsets = np.zeros(N * N, np.int64)
    offsets[1:] = np.cumsum(per_pair)[:-1]
    coef = np.zeros(int(per_pair.sum()), np.float32)
    # pair blocks are channel-major: [ch0: L][ch1: L][ch2: L]
    start = np.repeat(offsets[pairs], L)
    for c in range(nch):
        coef[start + c * np.repeat(L, L) + order] = vals[:, c]
    # zeroth order of channel 0 on the file grid, [i, o], from the stored float32 values
    a0 = np.zeros(N * N)
    a0[pairs] = coef[offsets[pairs]]
    cdf = integrate_catmull_rom(nodes.astype(float), a0.reshape(N, N))        # [i, o]
    return offsets, length.astype(np.uint32), coef, cdf.astype(np.float32).ravel(), 0
