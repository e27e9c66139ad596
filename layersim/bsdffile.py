"""The tabulated Fourier BSDF file format (``.bsdf``, header ``SCATFUN``) of layerlab, Mitsuba 0.6
and pbrt-v3 (version 1, isotropic), and the layout of the Layer Laboratory's anisotropic
version 2.

Byte layout (little-endian; offsets in bytes; ``N`` nodes, ``P = N * N`` ordinate pairs)
---------------------------------------------------------------------------------------
======  ==========================  ==============================================================
size    field                       meaning
======  ==========================  ==============================================================
7       identifier                  ``b"SCATFUN"``
1       version                     1 (isotropic) or 2 (anisotropic layout)
4       flags (uint32)              0x01: the file holds a BSDF; 0x02 (v1): harmonic extrapolation
4       nNodes (uint32)             ``N``
4       nCoeffs (uint32)            floats in the coefficient array
4       nMaxOrder (uint32)          v1: longest series; v2: two fields, ``ms`` then ``md``
4       nChannels (uint32)          1 or 3 (stored as Y, R, B)
4       nBases (uint32)             1 (textured files: more)
4       nMetadataBytes (uint32)     length of the trailing JSON/text metadata
4       nParameters (uint32)        0 (textured files: more)
4       nParameterValues (uint32)   0
4       eta (float32)               relative index eta(bottom) / eta(top)
8       alpha (2 x float32)         Beckmann-equivalent roughness, top and bottom (informative)
8 / 4   unused                      pads the header to 64 bytes (v2: one float, since it has ms
                                    and md)
4 N     nodes (float32)             ``[-mu_h .. -mu_1, 0, 0, mu_1 .. mu_h]`` (layerlab inserts
                                    two zero nodes so that the spline has a node on the horizon)
4 nP    parameter sample counts     absent when ``nParameters = 0``
4 nPV   parameter sample positions  absent when ``nParameterValues = 0``
4 P     CDF (float32)               v1: ``cdf[i N + o]``, integral over mu_o of the zeroth order
                                    of channel 0 from node 0 to node o (Catmull-Rom spline);
                                    v2: ``(ms_max // 2 + 1)`` marginal cosine coefficients per
                                    pair at ``[(o N + i) * n_marg + j]``
8 P     offset table (uint32)       v1: ``(offset, length)`` of pair ``i N + o``;
(12 P)                              v2: ``(offset, ms, md)``
4 nC    coefficients (float32)      per pair: channel-major blocks (Y, R, B) of ``length``
                                    (v2: ``ms x md``, ``s`` slowest) floats
nMB     metadata                    UTF-8 text (layersim writes JSON)
======  ==========================  ==============================================================

The file size must equal the sum exactly (layerlab and Mitsuba refuse anything else).

Meaning of the coefficients
---------------------------
Directions use layerlab's discrete-ordinates convention (``mu > 0`` propagates down, into the
stack). The series of pair ``(o, i)`` is ``a_l = f_l(mu_o, mu_i) |mu_o|``, the BSDF's cosine series
(radiance convention, light arriving along ``mu_i``) times the outgoing cosine, so that a
renderer's ``eval`` (which includes the cosine factor) is ``sum_l a_l cos(l phi)``; ``phi`` is
the azimuth difference of the propagation directions (0: specular / straight through).
In layersim's terms (``CONVENTIONS.md``): ``mu_i = wi.z``, ``mu_o = -wo.z``, and pair ``(o, i)`` of
block ``Rt`` (our ordinate indices ``o``, ``i``) is file pair ``(h - 1 - o, h + 2 + i)``, ``Ttb``
is ``(h + 2 + o, h + 2 + i)``, ``Rb`` is ``(h + 2 + o, h - 1 - i)`` and ``Tbt`` is
``(h - 1 - o, h - 1 - i)``. Version 2 stores an exponential series in ``phi_s, phi_d``,
``f |mu_o| = 2 sum_{s, d >= 0} c_sd cos(s phi_s + d phi_d) - sum_s c_s0 cos(s phi_s)``; an
isotropic BSDF is ``ms = 1`` with ``c_00 = a_0`` and ``c_0d = a_d / 2``.

Renderers evaluate the table *adjointly* (pbrt-v3 ``FourierBSDF::f``, Mitsuba 0.6 ``fourier``):
the camera direction takes the role of ``mu_i`` and the light that of ``mu_o``, and transmission
is multiplied by ``(eta_camera / eta_light)^2``; by generalized reciprocity this is the same BSDF.
:meth:`FourierTable.eval` reproduces that evaluation.

Not representable: the unscattered (delta) transmission of media (layersim keeps it in the JSON
metadata, so that :meth:`FourierTable.to_bsdf` restores it; renderers ignore it).

References: layerlab ``include/layer/storage.h``, ``src/storage.cpp`` (``BSDFStorage``); pbrt-v3
``FourierBSDFTable::Read`` and ``FourierBSDF::f``; Mitsuba 0.6 ``src/bsdfs/fourier.cpp``; for
version 2 the Layer Laboratory's Mitsuba 2 ``BSDFStorage`` (``n_max_order_s/d``, ``(offset, ms,
md)`` table, marginal cosine series in ``2 phi_i``). Seed 004 sec. 6.5.
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sps

from .bsdf import BSDF, _azimuth, _directions, spline_weights
from .channels import LUMINANCE, aligned_series, green_from_ybr
from .errors import FileFormatError, InfeasibleError
from .kernels import fourier_eval
from .operator import BLOCKS, Grid, IsoOperator, order_weight

MAGIC = b"SCATFUN"
HEADER_SIZE = 64
FLAG_BSDF = 0x01
FLAG_EXTRAPOLATED = 0x02
_HEADER_V1 = struct.Struct("<7sB9If2f2f")
_HEADER_V2 = struct.Struct("<7sB10If2ff")
assert _HEADER_V1.size == HEADER_SIZE and _HEADER_V2.size == HEADER_SIZE
#: Largest value a uint32 header field can hold.
_U32 = 2**32 - 1


def file_nodes(mu: np.ndarray) -> np.ndarray:
    """Node array of a file for positive ordinates ``mu`` (increasing): ``[-mu reversed, 0, 0,
    mu]`` (``N = 2 h + 2``), float32 as stored."""
    mu = np.asarray(mu, float)
    return np.concatenate([-mu[::-1], [0.0, 0.0], mu]).astype(np.float32)


def _block_indices(name: str, h: int):
    """File (outgoing, incident) node index arrays of block ``name``'s pairs ``[o, i]`` (h, h)."""
    down = h + 2 + np.arange(h)          # mu > 0: propagating down
    up = h - 1 - np.arange(h)            # mu < 0: propagating up
    out = {"Rt": up, "Tbt": up, "Ttb": down, "Rb": down}[name]
    inc = {"Rt": down, "Ttb": down, "Rb": up, "Tbt": up}[name]
    return np.broadcast_to(out[:, None], (h, h)), np.broadcast_to(inc[None, :], (h, h))


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


@dataclass(eq=False)
class FourierTable:
    """Contents of a ``.bsdf`` file (see the module docstring for the layout and meaning).

    Attributes
    ----------
    version : int
        1 (isotropic) or 2 (anisotropic layout).
    nodes : float32 ndarray (N,)
        Signed elevation cosines (layerlab convention), increasing.
    offsets : uint32 ndarray (N * N,)
        Start of pair ``i N + o`` in ``coef``.
    shape : uint32 ndarray (N * N,) or (N * N, 2)
        Series length (v1) or ``(ms, md)`` (v2) of each pair.
    coef : float32 ndarray (nCoeffs,)
    cdf : float32 ndarray
        The sampling table (v1: (N * N,); v2: (N * N * n_marginal,)).
    channels : int
        1 or 3 (Y, R, B).
    eta : float
        eta(bottom) / eta(top) (1 for opaque stacks).
    alpha : tuple of float
        Beckmann-equivalent roughness of the top and bottom surface (informative only).
    metadata : str
    flags : int
    """

    version: int
    nodes: np.ndarray
    offsets: np.ndarray
    shape: np.ndarray
    coef: np.ndarray
    cdf: np.ndarray
    channels: int
    eta: float = 1.0
    alpha: tuple = (0.0, 0.0)
    metadata: str = ""
    flags: int = FLAG_BSDF
    _series: dict = field(default_factory=dict, repr=False, compare=False)

    # ---- basic properties --------------------------------------------------------------

    @property
    def n_nodes(self) -> int:
        return int(self.nodes.size)

    @property
    def max_order(self):
        """v1: longest series; v2: ``(ms, md)`` maxima."""
        if self.version == 1:
            return int(self.shape.max()) if self.shape.size else 0
        return tuple(int(v) for v in (self.shape.max(axis=0) if self.shape.size else (0, 0)))

    @property
    def pair_size(self) -> np.ndarray:
        """Floats per channel of each pair (v1: length, v2: ms * md)."""
        if self.version == 1:
            return self.shape.astype(np.int64)
        return self.shape[:, 0].astype(np.int64) * self.shape[:, 1].astype(np.int64)

    @property
    def info(self) -> dict:
        """The JSON metadata (empty if the metadata is not JSON)."""
        try:
            d = json.loads(self.metadata) if self.metadata else {}
        except ValueError:
            return {}
        return d if isinstance(d, dict) else {}

    @property
    def opaque(self) -> bool:
        """No light leaves through the bottom and none enters from below."""
        N, h = self.n_nodes, self.n_nodes // 2 - 1
        size = self.pair_size.reshape(N, N)          # [i, o]
        top_in = size[h + 2:, :]
        return not (size[:h + 2, :].any() or top_in[:, h + 2:].any())

    def __repr__(self) -> str:
        return (f"FourierTable(v{self.version}, {self.n_nodes} nodes, max order "
                f"{self.max_order}, {self.channels} channel(s), {self.coef.size} coefficients, "
                f"eta={self.eta:g}, {self.nbytes()} bytes)")

    # ---- construction from a solved BSDF ------------------------------------------------

    @classmethod
    def from_bsdf(cls, bsdf: BSDF, version: int = 1, alpha=(0.0, 0.0),
                  metadata: dict | None = None) -> "FourierTable":
        """Tabulate a solved isotropic BSDF in the file's layout.

        Parameters
        ----------
        bsdf : layersim.BSDF
            One or three channels (RGB: stored as Y, R, B).
        version : {1, 2}
            2 writes the anisotropic layout (``ms = 1`` per pair: an isotropic BSDF).
        alpha : (float, float)
            Beckmann-equivalent roughness of the top and bottom surface for the header
            (renderers use it only as a hint; layerlab writes 0).
        metadata : dict, optional
            Extra JSON fields.
        """
        if version not in (1, 2):
            raise ValueError(f"unknown .bsdf version {version}; layersim writes 1 or 2")
        if bsdf.anisotropic:
            raise InfeasibleError("exporting anisotropic (coupled-mode) stacks to .bsdf is not "
                                  "implemented yet: save them with BSDF.save (.lsim), or export "
                                  "their rotational average (an isotropic approximation)")
        if bsdf.channels not in (1, 3):
            raise ValueError(f"a .bsdf file holds 1 or 3 channels, this BSDF has "
                             f"{bsdf.channels}")
        op = bsdf.operators[0]
        grid = op.grid
        h = grid.h
        N = 2 * h + 2
        offsets_al, coef_al = aligned_series(bsdf)
        counts_al = np.diff(offsets_al)
        if bsdf.channels == 3:
            coef_al = np.stack([coef_al @ LUMINANCE, coef_al[:, 0], coef_al[:, 2]], axis=1)
        # map every (block, o, i) pair to its file pair and scale by |mu_o|
        length = np.zeros(N * N, np.int64)
        src = np.full(N * N, -1, np.int64)              # first aligned coefficient of the pair
        scale = np.zeros(N * N)
        for b, name in enumerate(BLOCKS):
            if op.blocks[name] is None:
                continue
            fo, fi = _block_indices(name, h)
            p_file = (fi * N + fo).ravel()
            p_ours = b * h * h + np.arange(h * h)
            length[p_file] = counts_al[p_ours]
            src[p_file] = offsets_al[:-1][p_ours]
            scale[p_file] = np.repeat(grid.mu, h)       # |mu_o| of pair [o, i] (row-major)
        nch = bsdf.channels
        pairs = np.flatnonzero(length > 0)
        L = length[pairs]
        order = np.concatenate([np.arange(n) for n in L]) if pairs.size else np.zeros(0, int)
        rows = np.repeat(src[pairs], L) + order          # aligned coefficient of each entry
        vals = coef_al[rows] * np.repeat(scale[pairs], L)[:, None]     # (entries, nch)
        if version == 2:
            vals[order > 0] *= 0.5                          # c_0d = a_d / 2
        per_pair = length * nch
        offsets = np.zeros(N * N, np.int64)
        offsets[1:] = np.cumsum(per_pair)[:-1]
        coef = np.zeros(int(per_pair.sum()), np.float32)
        # pair blocks are channel-major: [ch0: L][ch1: L][ch2: L]
        start = np.repeat(offsets[pairs], L)
        for c in range(nch):
            coef[start + c * np.repeat(L, L) + order] = vals[:, c]
        if coef.size > _U32:
            raise InfeasibleError(f"{coef.size} coefficients exceed the format's 32-bit "
                                  "offsets; lower md or n")
        nodes = file_nodes(grid.mu)
        # zeroth order of channel 0 on the file grid, [i, o], from the stored float32 values
        a0 = np.zeros(N * N)
        a0[pairs] = coef[offsets[pairs]]
        a0 = a0.reshape(N, N)
        cdf = integrate_catmull_rom(nodes.astype(float), a0)             # [i, o]
        if version == 1:
            shape = length.astype(np.uint32)
            cdf = cdf.astype(np.float32).ravel()
        else:
            shape = np.stack([np.where(length > 0, 1, 0), length], axis=1).astype(np.uint32)
            cdf = cdf.T.astype(np.float32).ravel()                         # [(o N + i), j=0]
        info = {"generator": "layersim", "format": f"SCATFUN v{version}",
                "scene": bsdf.info.get("scene"),
                "channels": "Y,R,B" if nch == 3 else "mono",
                "layersim": {"rule": grid.rule, "n": grid.n, "md": op.m,
                             "eta_top": op.eta_top, "eta_bottom": op.eta_bottom,
                             "opaque": op.opaque,
                             "delta": [{k: v.tolist() for k, v in o.delta.items()}
                                       for o in bsdf.operators]}}
        info.update(metadata or {})
        eta = 1.0 if op.opaque else float(op.eta_bottom) / float(op.eta_top)
        return cls(version, nodes, offsets.astype(np.uint32), shape, coef, cdf, nch, eta,
                   (float(alpha[0]), float(alpha[1])), json.dumps(info, default=str))

    # ---- bytes -------------------------------------------------------------------------

    def nbytes(self) -> int:
        """Size of the file in bytes."""
        P = self.n_nodes ** 2
        table = 3 if self.version == 2 else 2
        return (HEADER_SIZE + 4 * self.n_nodes + 4 * self.cdf.size + 4 * table * P
                + 4 * self.coef.size + len(self.metadata.encode("utf-8")))

    def to_bytes(self) -> bytes:
        meta = self.metadata.encode("utf-8")
        N = self.n_nodes
        if self.version == 1:
            head = _HEADER_V1.pack(MAGIC, 1, self.flags, N, self.coef.size, self.max_order,
                                   self.channels, 1, len(meta), 0, 0, self.eta, *self.alpha,
                                   0.0, 0.0)
            table = np.stack([self.offsets, self.shape], axis=1)
        else:
            ms, md = self.max_order
            head = _HEADER_V2.pack(MAGIC, 2, self.flags, N, self.coef.size, ms, md,
                                   self.channels, 1, len(meta), 0, 0, self.eta, *self.alpha,
                                   0.0)
            table = np.concatenate([self.offsets[:, None], self.shape], axis=1)
        return b"".join([head, self.nodes.astype("<f4").tobytes(),
                         self.cdf.astype("<f4").tobytes(), table.astype("<u4").tobytes(),
                         self.coef.astype("<f4").tobytes(), meta])

    def write(self, path) -> Path:
        """Write the file (see :func:`export` to go from a BSDF in one step)."""
        path = Path(path)
        data = self.to_bytes()
        assert len(data) == self.nbytes()
        path.write_bytes(data)
        return path

    @classmethod
    def from_bytes(cls, data: bytes, source: str = "<bytes>") -> "FourierTable":
        """Parse and validate a ``.bsdf`` file's bytes (v1 or v2). Every size is checked against
        the header before anything is read; inconsistent files raise :class:`FileFormatError`."""
        def fail(msg):
            raise FileFormatError(f"{source}: {msg}")

        data = memoryview(bytes(data))
        if len(data) < HEADER_SIZE:
            fail(f"truncated header ({len(data)} bytes, a .bsdf header has {HEADER_SIZE})")
        if bytes(data[:7]) != MAGIC:
            fail("not a tabulated BSDF file (the identifier is not 'SCATFUN')")
        version = data[7]
        if version == 1:
            (_, _, flags, N, n_coef, max_order, nch, nbases, nmeta, npar, npv, eta, a0, a1,
             _, _) = _HEADER_V1.unpack(data[:HEADER_SIZE])
            table_width, n_marg = 2, 1
        elif version == 2:
            (_, _, flags, N, n_coef, ms_max, md_max, nch, nbases, nmeta, npar, npv, eta, a0,
             a1, _) = _HEADER_V2.unpack(data[:HEADER_SIZE])
            table_width, n_marg = 3, ms_max // 2 + 1
        else:
            fail(f"unsupported version {version} (layersim reads versions 1 and 2)")
        if not flags & FLAG_BSDF:
            fail("the file does not hold a BSDF (flag 0x01 missing)")
        if version == 1 and flags & FLAG_EXTRAPOLATED:
            fail("harmonic-extrapolation files (flag 0x02) are not supported")
        if nch not in (1, 3):
            fail(f"{nch} colour channels; the format has 1 or 3")
        if nbases != 1 or npar != 0 or npv != 0:
            fail(f"textured files ({nbases} bases, {npar} parameters) are not supported")
        if N < 4 or N % 2:
            fail(f"{N} nodes; a BSDF file has an even number >= 4 (two of them zero)")
        P = N * N
        expected = (HEADER_SIZE + 4 * N + 4 * P * n_marg + 4 * table_width * P + 4 * n_coef
                    + nmeta)
        if len(data) != expected:
            fail(f"size mismatch: the header describes {expected} bytes, the file has "
                 f"{len(data)} (truncated or corrupt)")
        pos = HEADER_SIZE
        nodes = np.frombuffer(data, "<f4", N, pos).astype(np.float32)
        pos += 4 * N
        cdf = np.frombuffer(data, "<f4", P * n_marg, pos).astype(np.float32)
        pos += 4 * P * n_marg
        table = np.frombuffer(data, "<u4", P * table_width, pos).reshape(P, table_width)
        pos += 4 * table_width * P
        coef = np.frombuffer(data, "<f4", n_coef, pos).astype(np.float32)
        pos += 4 * n_coef
        metadata = bytes(data[pos:pos + nmeta]).decode("utf-8", errors="replace")
        if not np.all(np.isfinite(nodes)) or np.any(np.diff(nodes) < 0):
            fail("the node array is not finite and non-decreasing")
        offsets = table[:, 0].astype(np.uint32)
        shape = (table[:, 1] if version == 1 else table[:, 1:]).astype(np.uint32)
        size = shape.astype(np.int64) if version == 1 else \
            shape[:, 0].astype(np.int64) * shape[:, 1].astype(np.int64)
        if version == 1 and np.any(shape > max_order):
            fail(f"a pair has more coefficients than nMaxOrder = {max_order}")
        if version == 2 and (np.any(shape[:, 0] > ms_max) or np.any(shape[:, 1] > md_max)
                             or np.any((shape[:, 0] % 2 == 0) & (size > 0))):
            fail("a pair's (ms, md) exceeds the header's maxima or ms is even")
        end = offsets.astype(np.int64) + size * nch
        if np.any(end > n_coef):
            bad = int(np.argmax(end > n_coef))
            fail(f"pair {bad} reaches coefficient {int(end[bad])} of {n_coef} (corrupt offset "
                 "table)")
        if not np.all(np.isfinite(coef)) or not np.all(np.isfinite(cdf)):
            fail("non-finite coefficients")
        if not math.isfinite(eta) or eta <= 0:
            fail(f"invalid relative index eta = {eta}")
        return cls(int(version), nodes, offsets, shape, coef, cdf, int(nch), float(eta),
                   (float(a0), float(a1)), metadata, int(flags))

    # ---- renderer-faithful evaluation --------------------------------------------------

    def _channel_series(self, c: int):
        """Compact (offsets (P + 1,), coef) of channel ``c`` in the v1 cosine form ``a_l``."""
        if c not in self._series:
            size = self.pair_size
            start = self.offsets.astype(np.int64) + c * size
            offs = np.zeros(size.size + 1, np.int64)
            np.cumsum(size, out=offs[1:])
            idx = np.repeat(start, size) + (np.arange(offs[-1]) - np.repeat(offs[:-1], size))
            self._series[c] = (offs, self.coef[idx].astype(np.float64))
        return self._series[c]

    def eval(self, wi, wo) -> np.ndarray:
        """The BSDF ``f(wi, wo)`` (1/sr, no cosine factor) as pbrt-v3 (``FourierBSDF::f``) and
        Mitsuba 0.6 compute it from this file in radiance mode.

        The camera direction ``wo`` plays the file's incident role and the light ``wi`` the
        outgoing one; Catmull-Rom weights on the file's nodes (zero outside them), the series
        summed in float64, ``Y`` clamped at 0, divided by ``|wi.z|``, transmission multiplied by
        ``(eta_camera / eta_light)^2``; RGB reconstructs ``G`` from ``Y, R, B`` and clamps at 0.
        Version 2 files are summed as 2D series (``phi_s, phi_d``) with the same conventions.

        Parameters
        ----------
        wi, wo : array_like, shape (..., 3)
            Unit directions toward the light and the viewer (local frame).

        Returns
        -------
        ndarray, shape (...) or (..., 3)
        """
        wi = _directions("wi", wi)
        wo = _directions("wo", wo)
        wi, wo = np.broadcast_arrays(wi, wo)
        shape = wi.shape[:-1]
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        N = self.n_nodes
        x = self.nodes.astype(float)
        mu_fi = wo[:, 2]                  # camera: the file's incident direction
        mu_fo = -wi[:, 2]                 # light: the file's outgoing direction
        inside = ((mu_fi >= x[0]) & (mu_fi <= x[-1]) & (mu_fo >= x[0]) & (mu_fo <= x[-1])
                  & (wi[:, 2] != 0))
        ii, wii = spline_weights(x, mu_fi)
        io, wio = spline_weights(x, mu_fo)
        pair = (ii[:, :, None] * N + io[:, None, :]).reshape(-1, 16)
        weight = (wii[:, :, None] * wio[:, None, :]).reshape(-1, 16)
        weight[~inside] = 0.0
        if self.version == 1 or self.max_order[0] <= 1:
            # propagation azimuths: camera ray -wo, light ray wi
            dphi = _azimuth(wi) - _azimuth(-wo)
            sums = [self._sum_v1(c, pair, weight, dphi) for c in range(self.channels)]
        else:
            phi_i, phi_o = _azimuth(wo), _azimuth(-wi)
            sums = [self._sum_v2(c, pair, weight, phi_o + phi_i, phi_o - phi_i)
                    for c in range(self.channels)]
        scale = np.where(inside, 1.0 / np.where(wi[:, 2] != 0, np.abs(wi[:, 2]), 1.0), 0.0)
        trans = mu_fi * mu_fo > 0
        light_below = wi[:, 2] < 0
        eta2 = np.where(light_below, 1.0 / self.eta, self.eta) ** 2
        scale = np.where(trans, scale * eta2, scale)
        y = np.maximum(sums[0], 0.0)
        if self.channels == 1:
            return (y * scale).reshape(shape)
        r, b = sums[1], sums[2]
        rgb = np.stack([r, green_from_ybr(y, r, b), b], axis=-1) * scale[:, None]
        return np.maximum(rgb, 0.0).reshape(shape + (3,))

    def _sum_v1(self, c, pair, weight, dphi):
        offs, coef = self._channel_series(c)
        if self.version == 2:        # ms <= 1 everywhere: a_0 = c_00, a_d = 2 c_0d
            coef = coef * np.where(self._order_index(c) > 0, 2.0, 1.0)
        return fourier_eval.eval_series(offs, coef, pair, weight, dphi)

    def _order_index(self, c):
        offs, coef = self._channel_series(c)
        size = np.diff(offs)
        return np.arange(coef.size) - np.repeat(offs[:-1], size)

    def _sum_v2(self, c, pair, weight, phi_s, phi_d):
        """``2 sum c_sd cos(s phi_s + d phi_d) - sum_s c_s0 cos(s phi_s)`` (Mitsuba 2 layer
        plugin's ``eval_fourier_series_2d``), interpolated over 16 pairs."""
        offs, coef = self._channel_series(c)
        out = np.zeros(weight.shape[0])
        ms = self.shape[:, 0].astype(np.int64)
        md = self.shape[:, 1].astype(np.int64)
        for k in range(16):
            p = pair[:, k]
            w = weight[:, k]
            for q in np.flatnonzero((w != 0) & (ms[p] * md[p] > 0)):
                pp = p[q]
                cs = coef[offs[pp]:offs[pp + 1]].reshape(ms[pp], md[pp])
                s = np.arange(ms[pp]) - ms[pp] // 2
                d = np.arange(md[pp])
                ang = s[:, None] * phi_s[q] + d[None, :] * phi_d[q]
                val = 2.0 * np.sum(cs * np.cos(ang)) - np.sum(cs[:, 0] * np.cos(s * phi_s[q]))
                out[q] += w[q] * val
        return out

    # ---- back to a layersim BSDF --------------------------------------------------------

    def to_bsdf(self) -> BSDF:
        """The layersim BSDF this file holds (inverse of :meth:`from_bsdf`).

        Needs an isotropic table whose nodes are those of a Gauss-Lobatto or Gauss-Legendre rule
        (layersim's files name theirs in the metadata; layerlab's use Gauss-Lobatto), laid out as
        ``[-mu reversed, 0, 0, mu]``. The quadrature weights, which the file does not store, come
        from that rule. Unscattered transmission is restored from layersim's metadata.
        """
        if self.version == 2 and self.max_order[0] > 1:
            raise InfeasibleError("this version-2 file is anisotropic (ms > 1); layersim has no "
                                  "anisotropic BSDF representation yet: evaluate it with "
                                  "FourierTable.eval")
        N = self.n_nodes
        h = N // 2 - 1
        x = self.nodes.astype(float)
        if x[h] != 0.0 or x[h + 1] != 0.0 or np.any(x[h + 2:] <= 0) or \
                np.any(np.abs(x[:h] + x[h + 2:][::-1]) > 1e-6):
            raise FileFormatError("the nodes are not laid out as [-mu reversed, 0, 0, mu]; "
                                  "cannot map them onto discrete ordinates")
        meta = self.info.get("layersim", {}) if isinstance(self.info.get("layersim"), dict) \
            else {}
        grid = _identify_grid(x[h + 2:], meta.get("rule"))
        size = self.pair_size.reshape(N, N)                    # [i, o]
        zero_rows = np.r_[h, h + 1]
        if size[zero_rows, :].any() or size[:, zero_rows].any():
            raise FileFormatError("pairs on the zero (horizon) nodes hold coefficients")
        opaque = bool(meta["opaque"]) if "opaque" in meta else self.opaque
        m = int(size.max()) if size.size else 0
        m = max(m, 1)
        eta_top = float(meta.get("eta_top", 1.0))
        eta_bottom = None if opaque else float(meta.get("eta_bottom") or eta_top * self.eta)
        deltas = meta.get("delta") or [{}] * 3
        channels = []
        for c in range(self.channels):
            offs, coef = self._channel_series(c)
            order = self._order_index(c)
            a = coef * (np.where(order > 0, 2.0, 1.0) if self.version == 2 else 1.0)
            channels.append((offs, a, order))
        if self.channels == 3:
            (offs, y, order), (_, r, _), (_, b, _) = channels
            channels = [(offs, r, order), (offs, green_from_ybr(y, r, b), order),
                        (offs, b, order)]
        ops = []
        for c, (offs, a, order) in enumerate(channels):
            delta = {k: np.asarray(v, float) for k, v in
                     (deltas[c] if c < len(deltas) else {}).items()}
            ops.append(_operator(grid, h, N, offs, a, order, m, opaque, eta_top, eta_bottom,
                                 delta))
        info = {"scene": self.info.get("scene"), "source": "bsdf file",
                "channels": len(ops), "n": grid.n, "md": m, "rule": grid.rule}
        return BSDF(ops, None, info)


def _identify_grid(mu32: np.ndarray, rule: str | None) -> Grid:
    """The quadrature rule whose positive nodes are ``mu32`` (float32 precision)."""
    n = 2 * mu32.size
    rules = [rule] if rule else ["gauss-lobatto", "gauss-legendre"]
    for name in rules:
        try:
            grid = Grid.make(name, n)
        except ValueError:
            continue
        if np.max(np.abs(grid.mu - mu32)) <= 2e-7:
            return grid
    raise FileFormatError(f"the file's {mu32.size} positive nodes are not those of a "
                          f"{' or '.join(rules)} rule with n = {n}; layersim needs the "
                          "quadrature weights to rebuild the operators (FourierTable.eval "
                          "evaluates the file directly)")


def _operator(grid, h, N, offs, a, order, m, opaque, eta_top, eta_bottom, delta):
    """An IsoOperator from the file's ``a_l = f_l |mu_o|`` of one channel."""
    fw = grid.flux_weight
    size = np.diff(offs)
    pair_of = np.repeat(np.arange(size.size), size)
    blocks = {}
    for name in BLOCKS:
        if opaque and name != "Rt":
            blocks[name] = None
            continue
        fo, fi = _block_indices(name, h)
        p_file = (fi * N + fo).ravel()
        lookup = np.full(N * N, -1, np.int64)
        lookup[p_file] = np.arange(h * h)
        ours = lookup[pair_of]
        sel = ours >= 0
        o, i = np.divmod(ours[sel], h)
        l = order[sel]
        f = a[sel] / grid.mu[o]
        vals = f * order_weight(l) * fw[i]
        mats = []
        for k in range(m):
            s = l == k
            mat = sps.csr_matrix((vals[s], (o[s], i[s])), shape=(h, h))
            if name in delta:
                mat = mat + sps.diags(np.asarray(delta[name], float), format="csr")
            mats.append(mat.tocsr())
        blocks[name] = mats
    return IsoOperator(grid, blocks, eta_top, eta_bottom,
                       {k: v for k, v in delta.items() if not opaque})


# ---------------------------------------------------------------------------------------------
# Functions
# ---------------------------------------------------------------------------------------------

def export(bsdf: BSDF, path, version: int = 1, alpha=(0.0, 0.0)) -> FourierTable:
    """Write a solved BSDF as a ``.bsdf`` file for layerlab, Mitsuba 0.6 and pbrt-v3 (version 1)
    or in the Layer Laboratory's version-2 layout; returns the table written."""
    table = FourierTable.from_bsdf(bsdf, version=version, alpha=alpha)
    table.write(path)
    return table


def read(path) -> FourierTable:
    """Read and validate a ``.bsdf`` file (version 1 or 2)."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read ({exc.strerror or exc})") from None
    return FourierTable.from_bytes(data, source=str(path))
