"""Facts of the ``.bsdf`` layout shared by reading and writing: identifier, flags, header
structs, the node array and the mapping between layersim's ordinate pairs and the file's
(see :mod:`layersim.bsdffile` for the byte layout)."""

from __future__ import annotations

import struct

import numpy as np

from ..operators.operator import BLOCKS

MAGIC = b"SCATFUN"
HEADER_SIZE = 64
FLAG_BSDF = 0x01
FLAG_EXTRAPOLATED = 0x02
#: Version 2, layersim's extension: the coefficients are complex (module docstring).
FLAG_COMPLEX = 0x04
#: Header of version 1 and of version 2 (two ``nMaxOrder`` fields, one float less).
HEADER_V1 = struct.Struct("<7sB9If2f2f")
HEADER_V2 = struct.Struct("<7sB10If2ff")
assert HEADER_V1.size == HEADER_SIZE and HEADER_V2.size == HEADER_SIZE
#: Largest value a uint32 header field can hold.
U32 = 2**32 - 1


def file_nodes(mu: np.ndarray) -> np.ndarray:
    """Node array of a file for positive ordinates ``mu`` (increasing): ``[-mu reversed, 0, 0,
    mu]`` (``N = 2 h + 2``), float32 as stored."""
    mu = np.asarray(mu, float)
    return np.concatenate([-mu[::-1], [0.0, 0.0], mu]).astype(np.float32)


def block_indices(name: str, h: int):
    """File (outgoing, incident) node index arrays of block ``name``'s pairs ``[o, i]`` (h, h)."""
    down = h + 2 + np.arange(h)          # mu > 0: propagating down
    up = h - 1 - np.arange(h)            # mu < 0: propagating up
    out = {"Rt": up, "Tbt": up, "Ttb": down, "Rb": down}[name]
    inc = {"Rt": down, "Ttb": down, "Rb": up, "Tbt": up}[name]
    return np.broadcast_to(out[:, None], (h, h)), np.broadcast_to(inc[None, :], (h, h))


def pair_maps(h: int, present=BLOCKS):
    """Between our pair numbering ``b h^2 + o h + i`` (block ``b`` of :data:`BLOCKS`, as in the
    series tables of :mod:`layersim.solved.bsdf`) and file pairs ``i N + o``, for the blocks in
    ``present``: ``(file_of (4 h^2,), ours_of (N^2,))``, -1 where there is no counterpart."""
    N = 2 * h + 2
    file_of = np.full(len(BLOCKS) * h * h, -1, np.int64)
    ours_of = np.full(N * N, -1, np.int64)
    for b, name in enumerate(BLOCKS):
        if name not in present:
            continue
        fo, fi = block_indices(name, h)
        p_ours = b * h * h + np.arange(h * h)
        file_of[p_ours] = (fi * N + fo).ravel()
        ours_of[file_of[p_ours]] = p_ours
    return file_of, ours_of


def integrate_catmull_rom(x: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Cumulative integral of the Catmull-Rom spline through ``(x, f)`` at the nodes (layerlab's
    ``spline::integrate1D``, pbrt-v3's ``IntegrateCatmullRom``); works along the last axis of
    ``f``. Intervals of zero width (the doubled zero node) contribute nothing."""
    x = np.asarray(x, float)
    f = np.asarray(f, float)
    n = x.size
    out = np.zeros(f.shape)
    if n < 2:
        return out
    k = np.arange(n - 1)
    width = x[1:] - x[:-1]
    f0, f1 = f[..., :-1], f[..., 1:]
    with np.errstate(divide="ignore", invalid="ignore"):
        left = np.where(k > 0, width / (x[np.minimum(k + 1, n - 1)] - x[np.maximum(k - 1, 0)]),
                        0.0)
        right = np.where(k + 2 < n, width / (x[np.minimum(k + 2, n - 1)] - x[k]), 0.0)
    fm = f[..., np.maximum(k - 1, 0)]
    fp = f[..., np.minimum(k + 2, n - 1)]
    d0 = np.where(k > 0, left * (f1 - fm), f1 - f0)
    d1 = np.where(k + 2 < n, right * (fp - f0), f1 - f0)
    seg = ((d0 - d1) / 12.0 + (f0 + f1) * 0.5) * width
    out[..., 1:] = np.cumsum(seg, axis=-1)
    return out


def n_marginal(ms_max: int, flags: int) -> int:
    """Marginal coefficients per pair of a version-2 file (``M`` of the module docstring):
    ``ms_max // 2 + 1`` cosines, plus ``ms_max // 2`` sines with :data:`FLAG_COMPLEX`."""
    J = int(ms_max) // 2
    return 2 * J + 1 if flags & FLAG_COMPLEX else J + 1
