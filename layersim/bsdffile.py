"""The tabulated Fourier BSDF file format (``.bsdf``, header ``SCATFUN``) of layerlab, Mitsuba 0.6
and pbrt-v3 (version 1, isotropic), and the Layer Laboratory's anisotropic version 2.

Byte layout (little-endian; offsets in bytes; ``N`` nodes, ``P = N * N`` ordinate pairs)
---------------------------------------------------------------------------------------
======  ==========================  ==============================================================
size    field                       meaning
======  ==========================  ==============================================================
7       identifier                  ``b"SCATFUN"``
1       version                     1 (isotropic) or 2 (anisotropic)
4       flags (uint32)              0x01: the file holds a BSDF; 0x02 (v1): harmonic
                                    extrapolation; 0x04 (v2, layersim's extension): complex
                                    coefficients (see below)
4       nNodes (uint32)             ``N``
4       nCoeffs (uint32)            floats in the coefficient array
4       nMaxOrder (uint32)          v1: longest series; v2: two fields, ``ms_max`` (odd) then
(8)                                 ``md_max``, the largest ``ms`` and ``md`` of the table
4       nChannels (uint32)          1 or 3 (stored as Y, R, B)
4       nBases (uint32)             1 (textured files: more)
4       nMetadataBytes (uint32)     length of the trailing JSON/text metadata
4       nParameters (uint32)        0 (textured files: more)
4       nParameterValues (uint32)   0
4       eta (float32)               relative index eta(bottom) / eta(top)
8       alpha (2 x float32)         Beckmann-equivalent roughness, top and bottom (informative)
8 / 4   unused                      pads the header to 64 bytes (v2: one float, since it has
                                    ``ms_max`` and ``md_max``)
4 N     nodes (float32)             ``[-mu_h .. -mu_1, 0, 0, mu_1 .. mu_h]`` (layerlab inserts
                                    two zero nodes so that the spline has a node on the horizon)
4 nP    parameter sample counts     absent when ``nParameters = 0``
4 nPV   parameter sample positions  absent when ``nParameterValues = 0``
4 P M   CDF (float32)               v1 (``M = 1``): ``cdf[i N + o]``, integral over mu_o of the
                                    zeroth order of channel 0 from node 0 to node o
                                    (Catmull-Rom spline); v2: ``M`` marginal coefficients per
                                    pair at ``[(o N + i) M + j]`` (below)
8 P     offset table (uint32)       v1: ``(offset, length)`` of pair ``i N + o``;
(12 P)                              v2: ``(offset, ms, md)``
4 nC    coefficients (float32)      v1: per pair, channel-major blocks (Y, R, B) of ``length``
                                    floats; v2: per pair, channel-major blocks of ``ms x md``
                                    floats (``s = -(ms-1)/2 .. (ms-1)/2`` slowest, ``d = 0 ..
                                    md-1`` fastest); with flag 0x04 the ``ms x md`` imaginary
                                    parts of every channel follow the real parts of every channel
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
``(h - 1 - o, h - 1 - i)``.

Version 2 stores per pair and channel a series in ``phi_s = phi_o + phi_i`` and
``phi_d = phi_o - phi_i``::

    f |mu_o| = 2 sum_{s, d >= 0} Re(c_sd exp(i (s phi_s + d phi_d))) - sum_s Re(c_s0 exp(i s phi_s)),
    c_sd = f_{d,s}(mu_o, mu_i) |mu_o|,

where ``f = sum_{d,s} f_{d,s} exp(i d phi_d) exp(i s phi_s)`` over all ``d, s`` is the complex
expansion of seed 000 eq. (7) (:mod:`layersim.aniso.basis`; ``f_{-d,-s} = conj(f_{d,s})``, so
``d >= 0`` suffices; the ``d = 0`` row holds both ``f_{0,s}`` and ``f_{0,-s}``). The Layer
Laboratory stores real ``c_sd`` (its layers are mirror symmetric about their tangent axes), and
then this is its ``eval_fourier_series_2d``: ``2 sum c_sd cos(s phi_s + d phi_d) - sum_s c_s0
cos(s phi_s)``. A layer rotated by ``rot`` has ``f_{d,s} exp(-2 i s rot)``: rotated layers, and
stacks that hold one, have complex coefficients, which layersim writes with flag 0x04 (files
without it are the Layer Laboratory's layout, bit for bit). An isotropic BSDF is ``ms = 1`` with
``c_00 = a_0`` and ``c_0d = a_d / 2``.

The marginal table of version 2 serves the sampling of ``mu_o``: averaged over the outgoing
azimuth, ``f |mu_o|`` keeps the terms with ``s = -d``, a series in ``2 phi_i``::

    m(phi_i) = sum_{j=0}^{J} m_j cos(2 j phi_i) + sum_{j=1}^{J} m'_j sin(2 j phi_i),
    m_0 = Re c_00,  m_j = 2 Re c_{-j,j},  m'_j = 2 Im c_{-j,j},   J = ms_max // 2,

of channel 0. The table holds, for every pair, its Catmull-Rom integral over ``mu_o`` from node 0
to node ``o``, coefficient by coefficient: ``M = J + 1`` cosine coefficients ``m_j``, followed with
flag 0x04 by the ``J`` sine coefficients ``m'_j`` (``M = 2 J + 1``). (``c_{-j,j}`` is zero where a
pair's ``ms`` or ``md`` does not reach it.)

Azimuths: the version-2 plugin evaluates at ``phi_i`` = the azimuth of the camera direction and
``phi_o`` = that of the reversed light direction; both differ from the propagation azimuths of
:mod:`layersim.aniso.bsdf` (``phi_i = atan2(-wi.y, -wi.x)``, ``phi_o = atan2(wo.y, wo.x)`` with the
roles swapped, below) by ``pi``, which leaves ``phi_d`` and ``phi_s`` (mod ``2 pi``) unchanged.

Renderers evaluate the table *adjointly* (pbrt-v3 ``FourierBSDF::f``, Mitsuba 0.6 ``fourier``,
the Layer Laboratory's Mitsuba 2 ``fourier``): the camera direction takes the role of ``mu_i``
and the light that of ``mu_o``, and transmission is multiplied by ``(eta_camera /
eta_light)^2``; by generalized reciprocity this is the same BSDF. :meth:`FourierTable.eval`
reproduces that evaluation.

What is confirmed and what is ours (version 2)
----------------------------------------------
Confirmed against the Layer Laboratory's source (``tizian/layer-laboratory``:
``include/mitsuba/layer/storage.h``, ``src/liblayer/storage.cpp``, ``src/liblayer/fourier.cpp``,
``src/bsdfs/fourier.cpp``): the header fields and their order, the exact-size rule and its sum,
the ``(offset, ms, md)`` table of pair ``i N + o``, channel-major ``ms x md`` blocks with ``s``
slowest from ``-(ms-1)/2`` and ``d`` from 0, the values (``scatter_coeff(s, d, o, i) |mu_o| /
(2 pi w_i |mu_i|)``, i.e. ``c_sd`` above, real), the evaluation formula and its azimuths, the
marginal table (``ms_max // 2 + 1`` coefficients ``(j == 0 ? 1 : 2) c_{-j,j}`` per pair, integrated
over ``o``, evaluated as a cosine series in ``2 phi_i``), and ``Y, R, B`` channels.

layersim's own: flag 0x04 (imaginary parts and the sine half of the marginal table; the Layer
Laboratory checks neither version nor flags, and refuses such files by their size instead of
misreading them); every nonzero coefficient of the solved operator is stored (the Layer
Laboratory keeps a per-pair box found by ``find_truncation`` with error ``1e-3``); the
transmission factor follows pbrt-v3 and Mitsuba 0.6 for both versions (the Layer Laboratory's
Mitsuba 2 plugin multiplies by ``eta^2`` when the light is below, the inverse of pbrt-v3's
radiance-mode factor).

Not representable: the unscattered (delta) transmission of media (layersim keeps it in the JSON
metadata, so that :meth:`FourierTable.to_bsdf` restores it; renderers ignore it).

References: layerlab ``include/layer/storage.h``, ``src/storage.cpp`` (``BSDFStorage``); pbrt-v3
``FourierBSDFTable::Read`` and ``FourierBSDF::f``; Mitsuba 0.6 ``src/bsdfs/fourier.cpp``; the Layer
Laboratory's Mitsuba 2 ``BSDFStorage`` (files above); seed 000 eq. (7), (10); seed 004 sec. 6.5.
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import scipy.sparse as sps

from .aniso import basis
from .aniso.operator import AnisoOperator
from .bsdf import BSDF
from .channels import LUMINANCE, aligned_series, green_from_ybr
from .directions import azimuth, unit_directions
from .errors import FileFormatError, InfeasibleError
from .interpolation import spline_weights
from .kernels import fourier_eval, fourier_eval2d
from .operator import BLOCKS, Grid, IsoOperator, order_weight

MAGIC = b"SCATFUN"
HEADER_SIZE = 64
FLAG_BSDF = 0x01
FLAG_EXTRAPOLATED = 0x02
#: Version 2, layersim's extension: the coefficients are complex (module docstring).
FLAG_COMPLEX = 0x04
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


def _pair_maps(h: int, present=BLOCKS):
    """Between our pair numbering ``b h^2 + o h + i`` (block ``b`` of :data:`BLOCKS`, as in the
    series tables of :mod:`layersim.bsdf`) and file pairs ``i N + o``, for the blocks in
    ``present``: ``(file_of (4 h^2,), ours_of (N^2,))``, -1 where there is no counterpart."""
    N = 2 * h + 2
    file_of = np.full(len(BLOCKS) * h * h, -1, np.int64)
    ours_of = np.full(N * N, -1, np.int64)
    for b, name in enumerate(BLOCKS):
        if name not in present:
            continue
        fo, fi = _block_indices(name, h)
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
        The sampling table (v1: (N * N,); v2: (N * N * M,), ``M`` = :func:`n_marginal`).
    channels : int
        1 or 3 (Y, R, B).
    eta : float
        eta(bottom) / eta(top) (1 for opaque stacks).
    alpha : tuple of float
        Beckmann-equivalent roughness of the top and bottom surface (informative only).
    metadata : str
    flags : int
        :data:`FLAG_BSDF`, with :data:`FLAG_COMPLEX` for complex version-2 coefficients.
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
    def is_complex(self) -> bool:
        """Version 2 with complex coefficients (:data:`FLAG_COMPLEX`)."""
        return self.version == 2 and bool(self.flags & FLAG_COMPLEX)

    @property
    def anisotropic(self) -> bool:
        """The table depends on more than the azimuth difference (v2 with ``ms > 1``), or on
        its sign (complex coefficients)."""
        return self.version == 2 and (self.max_order[0] > 1 or self.is_complex)

    @property
    def pair_size(self) -> np.ndarray:
        """Floats per channel (and per real or imaginary part) of each pair (v1: length,
        v2: ms * md)."""
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
        kind = ", complex" if self.is_complex else ""
        return (f"FourierTable(v{self.version}, {self.n_nodes} nodes, max order "
                f"{self.max_order}{kind}, {self.channels} channel(s), {self.coef.size} "
                f"coefficients, eta={self.eta:g}, {self.nbytes()} bytes)")

    # ---- construction from a solved BSDF ------------------------------------------------

    @classmethod
    def from_bsdf(cls, bsdf: BSDF, version: int | None = None, alpha=(0.0, 0.0),
                  metadata: dict | None = None, relerr: float = 0.0) -> "FourierTable":
        """Tabulate a solved BSDF in the file's layout.

        Parameters
        ----------
        bsdf : layersim.BSDF
            Isotropic or anisotropic; one or three channels (RGB: stored as Y, R, B).
        version : {None, 1, 2}
            1: the isotropic format of layerlab, Mitsuba 0.6 and pbrt-v3 (isotropic BSDFs only);
            2: the Layer Laboratory's anisotropic layout (complex coefficients, e.g. of rotated
            layers, with :data:`FLAG_COMPLEX`). None: 1 for isotropic BSDFs, 2 for anisotropic
            ones.
        alpha : (float, float)
            Beckmann-equivalent roughness of the top and bottom surface for the header
            (renderers use it only as a hint; layerlab writes 0).
        metadata : dict, optional
            Extra JSON fields.
        relerr : float
            Version 2 only: drop the coefficients of each file pair below ``relerr`` times the
            pair's largest (over all channels), shrinking each pair's ``(ms, md)`` box to what
            is left (the Layer Laboratory trims its files at 1e-3). 0 (default) keeps every
            nonzero coefficient.
        """
        if not 0.0 <= relerr < 1.0:
            raise ValueError(f"relerr = {relerr!r}: the relative truncation of the coefficients "
                             "must be in [0, 1)")
        if version is None:
            version = 2 if bsdf.anisotropic else 1
        if version not in (1, 2):
            raise ValueError(f"unknown .bsdf version {version}; layersim writes 1 or 2")
        if version == 1 and bsdf.anisotropic:
            raise InfeasibleError("version 1 of the .bsdf format holds isotropic BSDFs only; "
                                  "write this anisotropic (coupled-mode) stack as version 2 "
                                  "(the default for anisotropic stacks)")
        if bsdf.channels not in (1, 3):
            raise ValueError(f"a .bsdf file holds 1 or 3 channels, this BSDF has "
                             f"{bsdf.channels}")
        op = bsdf.operators[0]
        grid = op.grid
        file_of, _ = _pair_maps(grid.h, [n for n in BLOCKS if op.blocks[n] is not None])
        # |mu_o| of our pair [o, i] of every block (row-major)
        mu_out = np.tile(np.repeat(grid.mu, grid.h), len(BLOCKS))
        nodes = file_nodes(grid.mu)
        if version == 1:
            if relerr:
                raise ValueError("relerr applies to version 2 files only (version 1 stores each "
                                 "pair's series as solved)")
            offsets, shape, coef, cdf, flags = _layout_v1(bsdf, file_of, mu_out, nodes)
        else:
            offsets, shape, coef, cdf, flags = _layout_v2(bsdf, file_of, mu_out, nodes, relerr)
        if coef.size > _U32:
            raise InfeasibleError(f"{coef.size} coefficients exceed the format's 32-bit "
                                  "offsets; lower md or n")
        info = {"generator": "layersim", "format": f"SCATFUN v{version}",
                "scene": bsdf.info.get("scene"),
                "channels": "Y,R,B" if bsdf.channels == 3 else "mono",
                "relerr": relerr,
                "layersim": {"rule": grid.rule, "n": grid.n, "md": op.m,
                             "representation": "anisotropic" if bsdf.anisotropic
                             else "isotropic",
                             "eta_top": op.eta_top, "eta_bottom": op.eta_bottom,
                             "opaque": op.opaque,
                             "delta": [{k: v.tolist() for k, v in o.delta.items()}
                                       for o in bsdf.operators]}}
        info.update(metadata or {})
        eta = 1.0 if op.opaque else float(op.eta_bottom) / float(op.eta_top)
        return cls(version, nodes, offsets.astype(np.uint32), shape, coef, cdf, bsdf.channels,
                   eta, (float(alpha[0]), float(alpha[1])), json.dumps(info, default=str),
                   FLAG_BSDF | flags)

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
        the header before anything is read; inconsistent files raise :class:`FileFormatError`
        naming the field."""
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
            table_width, n_marg, parts = 2, 1, 1
        elif version == 2:
            (_, _, flags, N, n_coef, ms_max, md_max, nch, nbases, nmeta, npar, npv, eta, a0,
             a1, _) = _HEADER_V2.unpack(data[:HEADER_SIZE])
            table_width, n_marg = 3, n_marginal(ms_max, flags)
            parts = 2 if flags & FLAG_COMPLEX else 1
        else:
            fail(f"unsupported version {version} (layersim reads versions 1 and 2)")
        if not flags & FLAG_BSDF:
            fail("the file does not hold a BSDF (flag 0x01 missing)")
        if version == 1 and flags & FLAG_EXTRAPOLATED:
            fail("harmonic-extrapolation files (flag 0x02) are not supported")
        if version == 2 and flags & ~(FLAG_BSDF | FLAG_COMPLEX):
            fail(f"unknown flags 0x{flags:x} (version 2 knows 0x01 and 0x04)")
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
        if version == 2:
            for k, (name, top) in enumerate((("ms", ms_max), ("md", md_max))):
                if np.any(shape[:, k] > top):
                    bad = int(np.argmax(shape[:, k] > top))
                    fail(f"pair {bad} has {name} = {int(shape[bad, k])}, more than the header's "
                         f"n_max_order_{name[1]} = {top}")
            even = (shape[:, 0] % 2 == 0) & (size > 0)
            if np.any(even):
                fail(f"pair {int(np.argmax(even))} has an even ms = "
                     f"{int(shape[np.argmax(even), 0])} (s runs over -(ms-1)/2 .. (ms-1)/2)")
        end = offsets.astype(np.int64) + size * nch * parts
        if np.any(end > n_coef):
            bad = int(np.argmax(end > n_coef))
            fail(f"pair {bad} reaches coefficient {int(end[bad])} of nCoeffs = {n_coef} "
                 "(corrupt offset table)")
        if not np.all(np.isfinite(coef)) or not np.all(np.isfinite(cdf)):
            fail("non-finite coefficients")
        if not math.isfinite(eta) or eta <= 0:
            fail(f"invalid relative index eta = {eta}")
        return cls(int(version), nodes, offsets, shape, coef, cdf, int(nch), float(eta),
                   (float(a0), float(a1)), metadata, int(flags))

    # ---- renderer-faithful evaluation --------------------------------------------------

    def _channel_series(self, c: int, imag: bool = False):
        """Compact (offsets (P + 1,), coef float64) of channel ``c``: its block of every pair
        (v1: the cosine series ``a_l``; v2: ``ms x md`` real parts, or with ``imag`` the
        imaginary parts of a complex table), pairs one after the other."""
        key = (c, imag)
        if key not in self._series:
            size = self.pair_size
            block = c + (self.channels if imag else 0)
            start = self.offsets.astype(np.int64) + block * size
            offs = np.zeros(size.size + 1, np.int64)
            np.cumsum(size, out=offs[1:])
            idx = np.repeat(start, size) + (np.arange(offs[-1]) - np.repeat(offs[:-1], size))
            self._series[key] = (offs, self.coef[idx].astype(np.float64))
        return self._series[key]

    def _spectrum(self, c: int):
        """Every stored coefficient of channel ``c`` of a v2 table: ``(pair, s, d, c_sd)``
        (complex ``c_sd`` as in the module docstring), flattened in storage order."""
        offs, re = self._channel_series(c)
        im = self._channel_series(c, imag=True)[1] if self.is_complex else 0.0
        size = np.diff(offs)
        pair = np.repeat(np.arange(size.size), size)
        local = np.arange(re.size) - offs[pair]
        md = self.shape[pair, 1].astype(np.int64)
        s = local // np.maximum(md, 1) - self.shape[pair, 0].astype(np.int64) // 2
        return pair, s, local % np.maximum(md, 1), re + 1j * im

    def _runs2d(self, c: int) -> SimpleNamespace:
        """Channel ``c`` of a v2 table in the run layout of
        :mod:`layersim.kernels.fourier_eval2d` (one run per pair and ``s``; ``d = 0`` halved,
        so that the kernel's ``2 Re sum`` is the file's series)."""
        key = ("runs", c)
        if key not in self._series:
            offs, re = self._channel_series(c)
            im = self._channel_series(c, imag=True)[1] if self.is_complex else np.zeros(re.size)
            ms = np.where(self.pair_size > 0, self.shape[:, 0], 0).astype(np.int64)
            md = self.shape[:, 1].astype(np.int64)
            run_offsets = np.zeros(ms.size + 1, np.int64)
            np.cumsum(ms, out=run_offsets[1:])
            pair = np.repeat(np.arange(ms.size), ms)
            k = np.arange(run_offsets[-1]) - run_offsets[pair]
            start = offs[pair] + k * md[pair]
            re, im = re.copy(), im.copy()
            re[start] *= 0.5
            im[start] *= 0.5
            self._series[key] = SimpleNamespace(
                run_offsets=run_offsets, run_s=k - ms[pair] // 2,
                run_d0=np.zeros(k.size, np.int64),
                run_start=start, run_len=md[pair], coef_re=re, coef_im=im)
        return self._series[key]

    def eval(self, wi, wo) -> np.ndarray:
        """The BSDF ``f(wi, wo)`` (1/sr, no cosine factor) as pbrt-v3 (``FourierBSDF::f``),
        Mitsuba 0.6 and, for version 2, the Layer Laboratory's plugin compute it from this file
        in radiance mode.

        The camera direction ``wo`` plays the file's incident role and the light ``wi`` the
        outgoing one; Catmull-Rom weights on the file's nodes (zero outside them), the series
        summed in float64 (v1: cosine series in the azimuth difference; v2: the 2D series in
        ``phi_s, phi_d`` of the module docstring), ``Y`` clamped at 0, divided by ``|wi.z|``,
        transmission multiplied by ``(eta_camera / eta_light)^2``; RGB reconstructs ``G`` from
        ``Y, R, B`` and clamps at 0.

        Parameters
        ----------
        wi, wo : array_like, shape (..., 3)
            Unit directions toward the light and the viewer (local frame).

        Returns
        -------
        ndarray, shape (...) or (..., 3)
        """
        wi = unit_directions("wi", wi)
        wo = unit_directions("wo", wo)
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
        # azimuths of the camera direction and of the reversed light direction
        phi_i, phi_o = azimuth(wo), azimuth(-wi)
        if self.version == 1:
            sums = [fourier_eval.eval_series(*self._channel_series(c), pair, weight,
                                             phi_o - phi_i) for c in range(self.channels)]
        else:
            sums = [fourier_eval2d.eval_series2d(self._runs2d(c), pair, weight, phi_o - phi_i,
                                                 phi_o + phi_i) for c in range(self.channels)]
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

    def _order_index(self, c):
        offs, coef = self._channel_series(c)
        size = np.diff(offs)
        return np.arange(coef.size) - np.repeat(offs[:-1], size)

    # ---- back to a layersim BSDF --------------------------------------------------------

    def to_bsdf(self) -> BSDF:
        """The layersim BSDF this file holds (inverse of :meth:`from_bsdf`).

        Needs a table whose nodes are those of a Gauss-Lobatto or Gauss-Legendre rule
        (layersim's files name theirs in the metadata; layerlab's use Gauss-Lobatto), laid out as
        ``[-mu reversed, 0, 0, mu]``. The quadrature weights, which the file does not store, come
        from that rule. Unscattered transmission is restored from layersim's metadata.
        Anisotropic version-2 tables (``ms > 1`` or complex) become
        :class:`~layersim.aniso.operator.AnisoOperator` s (``md`` from layersim's metadata, or
        the smallest that holds the table); the ``d = 0`` row is read as the series it
        evaluates to (``f_{0,s} = (c_s0 + conj c_{-s,0}) / (2 |mu_o|)``).
        """
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
        eta_top = float(meta.get("eta_top", 1.0))
        eta_bottom = None if opaque else float(meta.get("eta_bottom") or eta_top * self.eta)
        deltas = meta.get("delta") or [{}] * 3
        if self.anisotropic:
            series = [self._spectrum(c) for c in range(self.channels)]
        else:
            series = []
            for c in range(self.channels):
                offs, coef = self._channel_series(c)
                order = self._order_index(c)
                a = coef * (np.where(order > 0, 2.0, 1.0) if self.version == 2 else 1.0)
                series.append((np.repeat(np.arange(offs.size - 1), np.diff(offs)), order, a))
        if self.channels == 3:        # (Y, R, B) -> (R, G, B): same layout in every channel
            y, r, b = (s[-1] for s in series)
            series = [s[:-1] + (v,) for s, v in zip(series, (r, green_from_ybr(y, r, b), b))]
        present = ["Rt"] if opaque else list(BLOCKS)
        _, ours_of = _pair_maps(h, present)
        ops = []
        for c, ser in enumerate(series):
            delta = {k: np.asarray(v, float) for k, v in
                     (deltas[c] if c < len(deltas) else {}).items()} if not opaque else {}
            if self.anisotropic:
                ops.append(_aniso_operator(grid, ours_of, *ser, int(meta.get("md", 1)),
                                           present, eta_top, eta_bottom, delta))
            else:
                ops.append(_operator(grid, ours_of, *ser, present, eta_top, eta_bottom, delta))
        info = {"scene": self.info.get("scene"), "source": "bsdf file",
                "channels": len(ops), "n": grid.n, "md": ops[0].m, "rule": grid.rule,
                "representation": "anisotropic" if self.anisotropic else "isotropic"}
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


def _operator(grid, ours_of, pair, order, a, present, eta_top, eta_bottom, delta):
    """An IsoOperator from the file's cosine series ``a_l = f_l |mu_o|`` of one channel: file
    ``pair`` and ``order`` ``l`` of every coefficient ``a``."""
    h = grid.h
    ours = ours_of[pair]
    sel = ours >= 0
    b, rest = np.divmod(ours[sel], h * h)
    o, i = np.divmod(rest, h)
    l = order[sel]
    m = max(int(order.max()) + 1 if order.size else 1, 1)
    vals = a[sel] / grid.mu[o] * order_weight(l) * grid.flux_weight[i]
    blocks = {}
    for k, name in enumerate(BLOCKS):
        if name not in present:
            blocks[name] = None
            continue
        mats = []
        for j in range(m):
            s = (b == k) & (l == j)
            mat = sps.csr_matrix((vals[s], (o[s], i[s])), shape=(h, h))
            if name in delta:
                mat = mat + sps.diags(np.asarray(delta[name], float), format="csr")
            mats.append(mat.tocsr())
        blocks[name] = mats
    return IsoOperator(grid, blocks, eta_top, eta_bottom, delta)


def _aniso_operator(grid, ours_of, pair, s, d, c, md, present, eta_top, eta_bottom, delta):
    """An AnisoOperator from the file's complex ``c_sd = f_{d,s} |mu_o|`` of one channel (file
    ``pair``, ``s``, ``d >= 0`` of every coefficient), with at least ``md`` orders."""
    h = grid.h
    ours = ours_of[pair]
    sel = (ours >= 0) & (c != 0)                 # the boxes are dense: skip their zeros
    ours, s, d, c = ours[sel], s[sel], d[sel], c[sel]
    b, rest = np.divmod(ours, h * h)
    o, i = np.divmod(rest, h)
    f = c / grid.mu[o]
    # the d = 0 row evaluates to sum_s Re(c_s0 e^{i s phi_s}): f_{0,s} = (c_s0 + conj c_-s0) / 2
    row0 = d == 0
    f = np.where(row0, 0.5 * f, f)
    b, o, i, s, d = (np.concatenate([v, v[row0]]) for v in (b, o, i, s, d))
    s[s.size - int(row0.sum()):] *= -1
    f = np.concatenate([f, np.conj(f[row0])])
    # complex operator entries B_{l,k}/(2 pi w_i |mu_i|) of the upper half (l > 0, or l = 0 and
    # k >= 0): (d, s) itself or its conjugate (-d, -s); of the d = 0 row only s >= 0
    l, k = d + s, d - s
    upper = (l > 0) | ((l == 0) & (k >= 0))
    keep = (d > 0) | upper
    b, o, i, l, k, f, upper = (v[keep] for v in (b, o, i, l, k, f, upper))
    l, k, f = np.where(upper, l, -l), np.where(upper, k, -k), np.where(upper, f, np.conj(f))
    md = max(md, int(np.abs(np.concatenate([l, k, [0]])).max()) + 1)
    rows, cols, vals, src = basis.real_entries(l, k, f)
    vals = vals * 2.0 * np.pi * grid.flux_weight[i[src]]
    S = basis.n_slots(md)
    blocks = {}
    for n, name in enumerate(BLOCKS):
        if name not in present:
            blocks[name] = None
            continue
        e = b[src] == n
        mat = sps.csr_matrix((vals[e], (rows[e] * h + o[src][e], cols[e] * h + i[src][e])),
                             shape=(S * h, S * h))
        if name in delta:
            mat = mat + sps.diags(np.tile(np.asarray(delta[name], float), S), format="csr")
        blocks[name] = mat.tocsr()
    return AnisoOperator(grid, md, blocks, eta_top, eta_bottom, delta)


# ---------------------------------------------------------------------------------------------
# Layouts of the two versions (from a solved BSDF)
# ---------------------------------------------------------------------------------------------

def _layout_v1(bsdf, file_of, mu_out, nodes):
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


def _bsdf_spectrum(bsdf, c: int):
    """Every nonzero ``f_{d,s}`` (1/sr, complex) with ``d >= 0`` of channel ``c`` of a solved
    BSDF, the unscattered delta excluded: ``(pair, s, d, f)`` with our pair numbering
    (``b h^2 + o h + i``). The ``d = 0`` row holds ``f_{0,s}`` and ``f_{0,-s}``."""
    table = bsdf.series_table(c)
    if not bsdf.anisotropic:       # f = sum_l f_l cos(l phi_d): f_{0,0} = f_0, f_{+-l,0} = f_l / 2
        size = np.diff(table.offsets)
        pair = np.repeat(np.arange(size.size), size)
        d = np.arange(table.coef.size) - table.offsets[pair]
        f = np.where(d > 0, 0.5, 1.0) * table.coef
        keep = f != 0
        return pair[keep], np.zeros(int(keep.sum()), np.int64), d[keep], f[keep] + 0j
    # SeriesTable2D: runs over the half l = d + s > 0 (and l = 0, d >= 0), f_{0,0} halved
    run = np.repeat(np.arange(table.run_s.size), table.run_len)
    pair = np.searchsorted(table.run_offsets, run, side="right") - 1
    s = table.run_s[run].astype(np.int64)
    d = table.run_d0[run] + (np.arange(run.size) - table.run_start[run])
    f = table.coef_re + 1j * table.coef_im
    f = np.where((d == 0) & (s == 0), 2.0 * f, f)
    keep = f != 0
    pair, s, d, f = pair[keep], s[keep], d[keep], f[keep]
    neg = d < 0                                             # use the conjugate (-d, -s)
    s, d, f = np.where(neg, -s, s), np.abs(d), np.where(neg, np.conj(f), f)
    mirror = (d == 0) & (s != 0)                            # f_{0,-s} = conj f_{0,s}
    return (np.concatenate([pair, pair[mirror]]), np.concatenate([s, -s[mirror]]),
            np.concatenate([d, d[mirror]]), np.concatenate([f, np.conj(f[mirror])]))


def _layout_v2(bsdf, file_of, mu_out, nodes, relerr: float = 0.0):
    """Version 2: ``(offsets, (ms, md), coef, cdf, flags)`` of any solved BSDF (module
    docstring): per file pair the box of every nonzero ``c_sd = f_{d,s} |mu_o|`` over all
    channels (those below ``relerr`` times the pair's largest dropped first), channel-major
    Y, R, B, imaginary parts after the real parts where any is nonzero
    (:data:`FLAG_COMPLEX`)."""
    N = nodes.size
    P = N * N
    nch = bsdf.channels
    spectra = []
    for c in range(nch):
        pair, s, d, f = _bsdf_spectrum(bsdf, c)
        sel = file_of[pair] >= 0
        spectra.append((file_of[pair[sel]], s[sel], d[sel], f[sel] * mu_out[pair[sel]]))
    if relerr > 0:
        peak = np.zeros(P)
        for p, _, _, f in spectra:
            np.maximum.at(peak, p, np.abs(f))
        spectra = [tuple(x[np.abs(f) >= relerr * peak[p]] for x in (p, s, d, f))
                   for p, s, d, f in spectra]
    allp = np.concatenate([sp[0] for sp in spectra])
    msh = np.zeros(P, np.int64)
    np.maximum.at(msh, allp, np.abs(np.concatenate([sp[1] for sp in spectra])))
    md = np.zeros(P, np.int64)
    np.maximum.at(md, allp, np.concatenate([sp[2] for sp in spectra]) + 1)
    ms = np.where(md > 0, 2 * msh + 1, 0)
    size = ms * md
    base = np.zeros(P, np.int64)                           # start of the pair, real parts only
    base[1:] = np.cumsum(size * nch)[:-1]
    re = np.zeros(int((size * nch).sum()))
    im = np.zeros(re.size)
    # (stored block, source channel, weight): Y = sum_c LUMINANCE[c] channel c, then R and B
    plan = [(0, c, LUMINANCE[c]) for c in range(3)] + [(1, 0, 1.0), (2, 2, 1.0)] \
        if nch == 3 else [(0, 0, 1.0)]
    for ch, c, w in plan:
        p, s, d, f = spectra[c]
        pos = base[p] + ch * size[p] + (s + msh[p]) * md[p] + d
        np.add.at(re, pos, w * f.real)
        np.add.at(im, pos, w * f.imag)
    re32, im32 = re.astype(np.float32), im.astype(np.float32)
    complex_ = bool(np.any(im32 != 0))
    parts = 2 if complex_ else 1
    pair_of = np.repeat(np.arange(P), size * nch)
    dest = np.arange(re.size) + (parts - 1) * base[pair_of]
    coef = np.zeros(parts * re.size, np.float32)
    coef[dest] = re32
    if complex_:
        coef[dest + nch * size[pair_of]] = im32
    # marginal coefficients of channel 0: (s, d) = (-j, j), from the stored float32 values
    flags = FLAG_COMPLEX if complex_ else 0
    J = int(ms.max()) // 2 if P else 0
    marg = np.zeros((n_marginal(2 * J + 1, flags), P))
    for j in range(J + 1):
        has = (msh >= j) & (md > j)
        pos = base[has] + (msh[has] - j) * md[has] + j
        marg[j, has] = (1.0 if j == 0 else 2.0) * re32[pos]
        if complex_ and j > 0:
            marg[J + j, has] = 2.0 * im32[pos]
    cdf = integrate_catmull_rom(nodes.astype(float), marg.reshape(-1, N, N))    # [j, i, o]
    cdf = cdf.transpose(2, 1, 0).astype(np.float32).ravel()                     # [o, i, j]
    shape = np.stack([ms, md], axis=1).astype(np.uint32)
    return parts * base, shape, coef, cdf, flags


# ---------------------------------------------------------------------------------------------
# Functions
# ---------------------------------------------------------------------------------------------

def export(bsdf: BSDF, path, version: int | None = None, alpha=(0.0, 0.0),
           relerr: float = 0.0) -> FourierTable:
    """Write a solved BSDF as a ``.bsdf`` file: version 1 for layerlab, Mitsuba 0.6 and pbrt-v3
    (isotropic BSDFs), version 2 in the Layer Laboratory's anisotropic layout (default: 1 for
    isotropic, 2 for anisotropic BSDFs); ``relerr``: see :meth:`FourierTable.from_bsdf`.
    Returns the table written."""
    table = FourierTable.from_bsdf(bsdf, version=version, alpha=alpha, relerr=relerr)
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
