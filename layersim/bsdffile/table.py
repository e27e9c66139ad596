"""The contents of a ``.bsdf`` file, :class:`FourierTable`: bytes, renderer-faithful evaluation,
and conversion from and to a solved :class:`~layersim.solved.bsdf.BSDF`; :func:`export` and
:func:`read` (:mod:`layersim.bsdffile` for the layout)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ..solved.bsdf import BSDF
from ..specular_paths import SpecularPathsBSDF
from ..solved.channels import green_from_ybr
from ..solved.directions import azimuth, direction_pairs
from ..errors import FileFormatError, InfeasibleError
from ..operators.interpolation import spline_weights
from ..kernels import fourier_eval, fourier_eval2d
from ..operators.operator import BLOCKS
from .layout import (FLAG_BSDF, FLAG_COMPLEX, FLAG_EXTRAPOLATED, HEADER_SIZE, HEADER_V1,
                     HEADER_V2, MAGIC, U32, file_nodes, n_marginal, pair_maps)
from .rawfile import read_bytes
from .reading import coupled_operator, identify_grid, isotropic_operator
from .v1 import layout_v1
from .v2 import layout_v2


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
        file_of, _ = pair_maps(grid.h, [n for n in BLOCKS if op.blocks[n] is not None])
        # |mu_o| of our pair [o, i] of every block (row-major)
        mu_out = np.tile(np.repeat(grid.mu, grid.h), len(BLOCKS))
        nodes = file_nodes(grid.mu)
        if version == 1:
            if relerr:
                raise ValueError("relerr applies to version 2 files only (version 1 stores each "
                                 "pair's series as solved)")
            offsets, shape, coef, cdf, flags = layout_v1(bsdf, file_of, mu_out, nodes)
        else:
            offsets, shape, coef, cdf, flags = layout_v2(bsdf, file_of, mu_out, nodes, relerr)
        if coef.size > U32:
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
            head = HEADER_V1.pack(MAGIC, 1, self.flags, N, self.coef.size, self.max_order,
                                   self.channels, 1, len(meta), 0, 0, self.eta, *self.alpha,
                                   0.0, 0.0)
            table = np.stack([self.offsets, self.shape], axis=1)
        else:
            ms, md = self.max_order
            head = HEADER_V2.pack(MAGIC, 2, self.flags, N, self.coef.size, ms, md,
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
             _, _) = HEADER_V1.unpack(data[:HEADER_SIZE])
            table_width, n_marg, parts = 2, 1, 1
        elif version == 2:
            (_, _, flags, N, n_coef, ms_max, md_max, nch, nbases, nmeta, npar, npv, eta, a0,
             a1, _) = HEADER_V2.unpack(data[:HEADER_SIZE])
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
        wi, wo, shape = direction_pairs(wi, wo)
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
        grid = identify_grid(x[h + 2:], meta.get("rule"))
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
        _, ours_of = pair_maps(h, present)
        ops = []
        for c, ser in enumerate(series):
            delta = {k: np.asarray(v, float) for k, v in
                     (deltas[c] if c < len(deltas) else {}).items()} if not opaque else {}
            if self.anisotropic:
                ops.append(coupled_operator(grid, ours_of, *ser, int(meta.get("md", 1)),
                                           present, eta_top, eta_bottom, delta))
            else:
                ops.append(isotropic_operator(grid, ours_of, *ser, present, eta_top, eta_bottom,
                                              delta))
        info = {"scene": self.info.get("scene"), "source": "bsdf file",
                "channels": len(ops), "n": grid.n, "md": ops[0].m, "rule": grid.rule,
                "representation": "anisotropic" if self.anisotropic else "isotropic"}
        return BSDF(ops, None, info)


def export(bsdf: BSDF, path, version: int | None = None, alpha=(0.0, 0.0),
           relerr: float = 0.0, format: str = "bsdf", **rgl_options):
    """Write a solved BSDF for renderers.

    ``format="bsdf"`` (default): a ``.bsdf`` file, version 1 for layerlab, Mitsuba 0.6 and
    pbrt-v3 (isotropic BSDFs), version 2 in the Layer Laboratory's anisotropic layout
    (default: 1 for isotropic, 2 for anisotropic BSDFs); ``relerr``: see
    :meth:`FourierTable.from_bsdf`. Returns the table written.

    ``format="rgl"``: the RGL tensor format of Mitsuba 3's and pbrt-v4's ``measured``
    material, top-side reflection only; ``rgl_options`` are those of
    :func:`layersim.bsdffile.rgl.export` (``resolution``, ``wavelengths``, ``color``,
    ``samples``, ``seed``, ``name``). Returns its :class:`~layersim.bsdffile.rgl.RGLExport`
    (with the measured reconstruction ``error``).
    """
    if isinstance(bsdf, SpecularPathsBSDF):
        raise InfeasibleError(
            f"format {format!r}: a stack solved by specular paths (near-specular lobes and "
            "deltas of flat interfaces) has no Fourier series per ordinate pair to tabulate; "
            "use its eval, sample and pdf directly")
    if format == "rgl":
        if version is not None or relerr or tuple(alpha) != (0.0, 0.0):
            raise ValueError("version, relerr and alpha belong to the .bsdf format; the RGL "
                             "format takes resolution, wavelengths and color")
        from . import rgl
        return rgl.export(bsdf, path, **rgl_options)
    if format != "bsdf":
        raise ValueError(f"format {format!r}: must be 'bsdf' or 'rgl'")
    if rgl_options:
        raise TypeError(f"export(format='bsdf') got RGL options {sorted(rgl_options)}")
    if not isinstance(bsdf, BSDF):
        raise TypeError("export() takes a solved BSDF (from layersim.solve or BSDF.load), got "
                        f"{type(bsdf).__name__}")
    for c, op in enumerate(bsdf.operators):
        # the format tabulates cosine series per ordinate pair: a mirror reflection is not a
        # function of the pair, and outside a smooth boundary the ordinates are not the
        # format's (the inside nodes are matched by Snell's law)
        if bsdf.lobes[c]:
            raise InfeasibleError(
                f"channel {c}: this BSDF has a near-specular interface (layersim.solved.lobe), "
                "solved as smooth transport plus its exact lobe at evaluation; a .bsdf "
                "file would need about 1 / alpha ordinates to tabulate that lobe; keep the "
                "solved BSDF (BSDF.save), or export a rougher interface")
        if bsdf.boundary or any(name in op.delta for name in ("Rt", "Rb")):
            what = ("a smooth dielectric boundary" if bsdf.boundary
                    else "a specular (mirror) reflection")
            raise InfeasibleError(
                f"channel {c}: this BSDF has {what} (a smooth interface, roughness 0), a delta "
                "in direction that .bsdf files cannot hold (they tabulate Fourier series per "
                "pair of ordinates); give the interface a roughness > 0 to export, or keep the "
                "solved BSDF (BSDF.save), which holds the delta exactly")
    table = FourierTable.from_bsdf(bsdf, version=version, alpha=alpha, relerr=relerr)
    table.write(path)
    return table


def read(path) -> FourierTable:
    """Read and validate a ``.bsdf`` file (version 1 or 2)."""
    return FourierTable.from_bytes(read_bytes(path), source=str(path))
