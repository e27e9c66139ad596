"""The solved BSDF of a stack: evaluation, energy fractions and bin energies.

Directions follow ``CONVENTIONS.md``: unit vectors ``(..., 3)`` in the local frame, both pointing
away from the surface. This module is the one place where they are converted to the solver's
discrete-ordinates convention::

    mu_in = wi.z,   mu_out = -wo.z,   dphi = phi(wo) - phi(wi) - pi

(``mu > 0`` propagates down; ``dphi`` is the azimuth difference of the propagation directions,
0 for the specular and straight-through directions). The block follows from the signs:
top reflection ``Rt`` (wi.z > 0, wo.z > 0), bottom reflection ``Rb``, top-to-bottom transmission
``Ttb`` (wi.z > 0, wo.z < 0) and ``Tbt``.

``eval`` interpolates the Fourier coefficients between ordinates with cubic (Catmull-Rom type)
splines in both elevations, constant beyond the outermost ordinates, and sums the cosine
series in ``dphi`` (a Warp kernel). Cubic weights are partly negative, so next to a sharp edge of
a lobe (the critical angle of total internal reflection) ``eval`` can undershoot slightly below
zero; it is not clamped. ``albedo`` and ``bin_energies`` interpolate the incident elevation
linearly instead: a convex combination of the energies at the ordinates, so that they are never
negative and never exceed 1 where the ordinates do not. The unscattered (delta) transmission
through media is not part of ``eval``; ``albedo`` and ``bin_energies`` include it.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .errors import FileFormatError, OperatorError
from .kernels import fourier_eval
from .operator import BLOCKS, IsoOperator, order_weight

FORMAT_VERSION = 1
#: Files holding anisotropic (coupled-mode) operators are written as version 2; isotropic ones
#: stay version 1, readable by older layersim versions.
FORMAT_VERSION_ANISO = 2
_BLOCK_ID = {name: k for k, name in enumerate(BLOCKS)}


# ---------------------------------------------------------------------------------------------
# Interpolation
# ---------------------------------------------------------------------------------------------

def spline_weights(nodes: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cubic Hermite spline weights on non-uniform ``nodes`` (increasing) at points ``x``.

    Derivatives are central differences (one-sided at the ends), so the interpolant of values
    ``f`` is ``sum_k w[:, k] f[idx[:, k]]`` with 4 taps. Beyond the ends the interpolant is
    constant (the outermost value). Returns ``idx`` (Q, 4) int64 and ``w`` (Q, 4).
    """
    nodes = np.asarray(nodes, float)
    x = np.asarray(x, float).ravel()
    n = nodes.size
    idx = np.zeros((x.size, 4), np.int64)
    w = np.zeros((x.size, 4))
    lo = x <= nodes[0]
    hi = x >= nodes[-1]
    idx[lo, 0], w[lo, 0] = 0, 1.0
    idx[hi, 0], w[hi, 0] = n - 1, 1.0
    mid = ~(lo | hi)
    if n < 2 or not mid.any():
        return idx, w
    xm = x[mid]
    k = np.clip(np.searchsorted(nodes, xm, side="right") - 1, 0, n - 2)
    x0, x1 = nodes[k], nodes[k + 1]
    width = x1 - x0
    t = (xm - x0) / width
    t2, t3 = t * t, t * t * t
    h00, h10 = 2 * t3 - 3 * t2 + 1, t3 - 2 * t2 + t
    h01, h11 = -2 * t3 + 3 * t2, t3 - t2
    # taps: k-1, k, k+1, k+2
    wm = np.zeros((xm.size, 4))
    wm[:, 1] += h00
    wm[:, 2] += h01
    has_left = k > 0
    km1 = np.maximum(k - 1, 0)
    a = np.where(has_left, h10 * width / (x1 - nodes[km1]), h10)
    wm[:, 2] += a
    wm[:, 0] -= np.where(has_left, a, 0.0)
    wm[:, 1] -= np.where(has_left, 0.0, a)
    has_right = k + 2 < n
    kp2 = np.minimum(k + 2, n - 1)
    b = np.where(has_right, h11 * width / (nodes[kp2] - x0), h11)
    wm[:, 3] += np.where(has_right, b, 0.0)
    wm[:, 2] += np.where(has_right, 0.0, b)
    wm[:, 1] -= b
    idx[mid] = np.stack([km1, k, k + 1, kp2], axis=1)
    w[mid] = wm
    return idx, w


def channel_pairs(a: "BSDF", b: "BSDF", mismatch: str) -> list:
    """Per-channel operator pairs of two BSDFs for stack algebra: equal channel counts pair
    up, a one-channel BSDF pairs with every channel of the other. Other counts raise
    :class:`OperatorError` with ``mismatch.format(a=a.channels, b=b.channels)``."""
    if a.channels != b.channels and 1 not in (a.channels, b.channels):
        raise OperatorError(mismatch.format(a=a.channels, b=b.channels))
    pick = lambda x, c: x.operators[0 if x.channels == 1 else c]
    return [(pick(a, c), pick(b, c)) for c in range(max(a.channels, b.channels))]


def block_taps(op, table, mu_in: np.ndarray, mu_out: np.ndarray):
    """For each block present, the queries it serves and their 16 interpolation taps.

    ``mu_in`` and ``mu_out`` are the signed cosines of the propagation directions (Q,); yields
    ``(sel, pair, weight)``: indices into the queries, and (len(sel), 16) pair indices
    (``table.base(block) + o * h + i``) and weights of the bicubic spline in both elevations.
    Shared by the isotropic and the anisotropic ``eval``.
    """
    h = op.h
    names = np.where(mu_in > 0, np.where(mu_out < 0, "Rt", "Ttb"),
                     np.where(mu_out > 0, "Rb", "Tbt"))
    valid = (mu_in != 0) & (mu_out != 0)
    for name in BLOCKS:
        sel = np.flatnonzero(valid & (names == name))
        if sel.size == 0 or op.blocks[name] is None:
            continue
        io, wo_ = spline_weights(op.grid.mu, np.abs(mu_out[sel]))
        ii, wi_ = spline_weights(op.grid.mu, np.abs(mu_in[sel]))
        pair = table.base(name) + (io[:, :, None] * h + ii[:, None, :]).reshape(sel.size, 16)
        weight = (wo_[:, :, None] * wi_[:, None, :]).reshape(sel.size, 16)
        yield sel, pair, weight


def hat_weights(nodes: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation weights (2 taps, non-negative, summing to 1; constant beyond the
    ends) in the same (Q, 4) layout as :func:`spline_weights`."""
    nodes = np.asarray(nodes, float)
    x = np.clip(np.asarray(x, float).ravel(), nodes[0], nodes[-1])
    k = np.clip(np.searchsorted(nodes, x, side="right") - 1, 0, nodes.size - 2)
    t = (x - nodes[k]) / (nodes[k + 1] - nodes[k])
    idx = np.zeros((x.size, 4), np.int64)
    w = np.zeros((x.size, 4))
    idx[:, 0], idx[:, 1] = k, k + 1
    w[:, 0], w[:, 1] = 1.0 - t, t
    return idx, w


def side_energies(mu: np.ndarray, nodes: np.ndarray, energy) -> tuple[np.ndarray, np.ndarray]:
    """Energy fractions ``(R, T)`` of beams arriving at signed elevation cosines ``mu`` (Q,),
    interpolated linearly (:func:`hat_weights`) between the ordinates ``nodes`` (h,).

    ``energy(name, q)`` gives, for the queries ``q`` (indices into ``mu``), the fraction of a
    beam from each node that leaves through block ``name``: shape (h,) (the same for every
    query, isotropic stacks) or (len(q), h) (azimuth-dependent, anisotropic stacks), or None
    for a block left out. Beams from above use Rt / Ttb, from below Rb / Tbt.
    """
    idx, w = hat_weights(nodes, np.abs(mu))
    R = np.zeros(mu.size)
    T = np.zeros(mu.size)
    top = mu > 0
    for sel, rname, tname in ((top, "Rt", "Ttb"), (~top, "Rb", "Tbt")):
        q = np.flatnonzero(sel)
        if q.size == 0:
            continue
        for out, name in ((R, rname), (T, tname)):
            e = energy(name, q)
            if e is not None:
                e = np.broadcast_to(e, (q.size, nodes.size))
                out[q] = np.sum(w[q] * np.take_along_axis(e, idx[q], axis=1), axis=1)
    return R, T


# ---------------------------------------------------------------------------------------------
# Direction handling
# ---------------------------------------------------------------------------------------------

def _directions(name: str, v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    if v.ndim == 0 or v.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3) (unit vectors in the local frame), "
                         f"got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} contains non-finite values")
    norm = np.linalg.norm(v, axis=-1)
    if np.any(np.abs(norm - 1.0) > 1e-5):
        raise ValueError(f"{name} must be unit vectors (|v| = 1 within 1e-5); normalise them "
                         f"first (found |v| = {norm.ravel()[np.argmax(np.abs(norm - 1.0).ravel())]:.6g})")
    return v


def _azimuth(v: np.ndarray) -> np.ndarray:
    return np.arctan2(v[..., 1], v[..., 0])


# ---------------------------------------------------------------------------------------------
# Series table
# ---------------------------------------------------------------------------------------------

class _SeriesTable:
    """All blocks of one operator as per-pair cosine series (see
    :mod:`layersim.kernels.fourier_eval`), unscattered deltas removed from the diagonals."""

    def __init__(self, op: IsoOperator):
        h = op.h
        fw = op.grid.flux_weight
        self.h = h
        counts = np.zeros(len(BLOCKS) * h * h, np.int64)
        entries = []
        for b, name in enumerate(BLOCKS):
            blk = op.blocks[name]
            if blk is None:
                continue
            delta = op.delta.get(name)
            for l, mat in enumerate(blk):
                coo = mat.tocoo()
                vals = coo.data / (order_weight(l) * fw[coo.col])
                if delta is not None:
                    diag = coo.row == coo.col
                    vals = vals.copy()
                    vals[diag] -= delta[coo.row[diag]] / (order_weight(l) * fw[coo.row[diag]])
                p = b * h * h + coo.row.astype(np.int64) * h + coo.col
                entries.append((p, np.full(p.size, l, np.int64), vals))
        if entries:
            p = np.concatenate([e[0] for e in entries])
            l = np.concatenate([e[1] for e in entries])
            v = np.concatenate([e[2] for e in entries])
            np.maximum.at(counts, p, l + 1)
        else:
            p = l = np.zeros(0, np.int64)
            v = np.zeros(0)
        self.offsets = np.zeros(counts.size + 1, np.int64)
        np.cumsum(counts, out=self.offsets[1:])
        self.coef = np.zeros(int(self.offsets[-1]))
        self.coef[self.offsets[p] + l] = v

    def base(self, name: str) -> int:
        return _BLOCK_ID[name] * self.h * self.h


# ---------------------------------------------------------------------------------------------
# BSDF
# ---------------------------------------------------------------------------------------------

class BSDF:
    """Solved BSDF of a layer stack (one operator per colour channel).

    Use :func:`layersim.solve` to make one and :meth:`load` to read a saved one.

    Attributes
    ----------
    operators : list of IsoOperator
        One per channel.
    plan : layersim.plan.Plan or None
    info : dict
        Scene name, timings and other metadata (saved with the BSDF).
    """

    def __init__(self, operators: list, plan=None, info: dict | None = None):
        if not operators:
            raise ValueError("a BSDF needs at least one operator")
        self.operators = list(operators)
        self.plan = plan
        self.info = dict(info or {})
        self._tables: dict[int, _SeriesTable] = {}

    # ---- basic properties --------------------------------------------------------------

    @property
    def channels(self) -> int:
        return len(self.operators)

    @property
    def opaque(self) -> bool:
        return self.operators[0].opaque

    @property
    def grid(self):
        return self.operators[0].grid

    @property
    def anisotropic(self) -> bool:
        """True if the operators couple Fourier modes (see :mod:`layersim.aniso`)."""
        return getattr(self.operators[0], "representation", "isotropic") == "anisotropic"

    def _table(self, c: int):
        if c not in self._tables:
            if self.anisotropic:  # --- anisotropic stacks (layersim.aniso.bsdf) ---
                from .aniso.bsdf import SeriesTable2D
                self._tables[c] = SeriesTable2D(self.operators[c])
            else:
                self._tables[c] = _SeriesTable(self.operators[c])
        return self._tables[c]

    def _per_channel(self, fn):
        out = [fn(c) for c in range(self.channels)]
        if self.channels == 1:
            return out[0]
        if isinstance(out[0], tuple):
            return tuple(np.stack([o[k] for o in out], axis=-1) for k in range(len(out[0])))
        if isinstance(out[0], dict):
            return {k: np.stack([o[k] for o in out], axis=-1) for k in out[0]}
        return np.stack(out, axis=-1)

    # ---- evaluation --------------------------------------------------------------------

    def eval(self, wi, wo) -> np.ndarray:
        """BSDF value f(wi, wo) in 1/sr, without the cosine factor (radiance convention).

        Parameters
        ----------
        wi, wo : array_like, shape (..., 3)
            Unit directions toward the light and the viewer (broadcast against each other).

        Returns
        -------
        ndarray, shape (...) (or (..., 3) for RGB)
            Zero for configurations whose block is left out (opaque stack lit from below) and on
            the horizon (z = 0). The unscattered delta transmission of media is not included.
        """
        wi = _directions("wi", wi)
        wo = _directions("wo", wo)
        wi, wo = np.broadcast_arrays(wi, wo)
        shape = wi.shape[:-1]
        wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
        if self.anisotropic:  # --- anisotropic stacks (layersim.aniso.bsdf) ---
            from .aniso import bsdf as aniso_bsdf
            return self._per_channel(lambda c: aniso_bsdf.eval_channel(self, c, wi, wo)
                                     .reshape(shape))
        mu_in, mu_out = wi[:, 2], -wo[:, 2]
        dphi = _azimuth(wo) - _azimuth(wi) - np.pi
        return self._per_channel(lambda c: self._eval_channel(c, mu_in, mu_out, dphi)
                                 .reshape(shape))

    def _eval_channel(self, c, mu_in, mu_out, dphi) -> np.ndarray:
        table = self._table(c)
        out = np.zeros(mu_in.size)
        for sel, pair, weight in block_taps(self.operators[c], table, mu_in, mu_out):
            out[sel] = fourier_eval.eval_series(table.offsets, table.coef, pair, weight,
                                                dphi[sel])
        return out

    # ---- importance sampling (layersim.sampling) ----------------------------------------

    def sample(self, wi, u):
        """Importance-sample outgoing directions: returns ``(wo, weight, pdf)`` with
        ``weight = f(wi, wo) |wo.z| / pdf`` (per channel). See :mod:`layersim.sampling`."""
        from .sampling import sampler_for
        return sampler_for(self).sample(wi, u)

    def pdf(self, wi, wo) -> np.ndarray:
        """Solid-angle density (1/sr) with which :meth:`sample` draws ``wo``. See
        :mod:`layersim.sampling`."""
        from .sampling import sampler_for
        return sampler_for(self).pdf(wi, wo)

    # ---- energy ------------------------------------------------------------------------

    def _incident(self, wi):
        wi = _directions("wi", wi)
        if np.any(wi[..., 2] == 0):
            raise ValueError("wi lies on the horizon (wi.z == 0): no light enters")
        if self.opaque and np.any(wi[..., 2] < 0):
            raise ValueError("this stack is opaque (its base is a conductor or diffuse layer): "
                             "light cannot arrive from below (wi.z < 0)")
        return wi

    def _node_energy(self, c: int, name: str) -> np.ndarray:
        """Energy fraction per incident node through block ``name`` (order 0 + delta)."""
        op = self.operators[c]
        fw = op.grid.flux_weight
        blk = op.blocks[name]
        if blk is None:
            return np.zeros(op.h)
        return (blk[0].T @ fw) / fw

    def albedo(self, wi):
        """Energy fractions ``(R, T)`` of a beam arriving from ``wi``: R leaves on the side it
        came from, T on the other. Each has shape ``wi.shape[:-1]`` (plus a channel axis).

        Computed with the discretisation's own quadrature at the ordinates and interpolated
        linearly in the incident elevation, so that they agree with the operator's energy
        balance (R + T = 1 to rounding for non-absorbing stacks, R + T <= 1 otherwise).
        """
        wi = self._incident(wi)
        shape = wi.shape[:-1]
        mu = wi.reshape(-1, 3)[:, 2]
        if self.anisotropic:  # --- anisotropic stacks (layersim.aniso.bsdf) ---
            from .aniso import bsdf as aniso_bsdf
            return self._per_channel(lambda c: tuple(
                x.reshape(shape) for x in aniso_bsdf.albedo_channel(self, c, wi.reshape(-1, 3))))

        def one(c):
            R, T = side_energies(mu, self.grid.mu, lambda name, q: self._node_energy(c, name))
            return R.reshape(shape), T.reshape(shape)

        return self._per_channel(one)

    def bin_energies(self, wi, mu_edges, phi_edges) -> dict:
        """Fraction of the power of a beam from ``wi`` leaving into each solid-angle bin.

        Parameters
        ----------
        wi : array_like, shape (3,)
            One incident direction.
        mu_edges : array_like (n_mu + 1,)
            Increasing edges in |cos theta_o| within [0, 1].
        phi_edges : array_like (n_phi + 1,)
            Increasing edges in the azimuth phi_o of ``wo`` (radians) within [0, 2 pi].

        Returns
        -------
        dict
            ``{"top": (n_mu, n_phi), "bottom": (n_mu, n_phi)}`` (a trailing channel axis for
            RGB). The angular distribution is that of the spline interpolant (integrated exactly
            in elevation, Gauss-Legendre on each piece, and analytically in azimuth), scaled so
            that over the whole hemisphere it carries the energy of :meth:`albedo` (the
            quadrature's; the two differ by the discretisation error, ~1e-5 at n ~ 200): bins
            covering a hemisphere sum exactly to R or T. The unscattered delta transmission is
            added to the bin that holds the straight-through direction.
        """
        wi = self._incident(wi)
        if wi.shape != (3,):
            raise ValueError(f"bin_energies takes one incident direction of shape (3,), got "
                             f"{wi.shape}")
        mu_edges = _edges("mu_edges", mu_edges, 0.0, 1.0)
        phi_edges = _edges("phi_edges", phi_edges, 0.0, 2.0 * np.pi)
        if self.anisotropic:  # --- anisotropic stacks (layersim.aniso.bsdf) ---
            from .aniso import bsdf as aniso_bsdf
            return self._per_channel(lambda c: aniso_bsdf.bins_channel(self, c, wi, mu_edges,
                                                                       phi_edges))
        return self._per_channel(lambda c: self._bins_channel(c, wi, mu_edges, phi_edges))

    def _bins_channel(self, c, wi, mu_edges, phi_edges) -> dict:
        op = self.operators[c]
        grid = op.grid
        mu_in = wi[2]
        phi_in = math.atan2(wi[1], wi[0])
        ii, wi_ = hat_weights(grid.mu, np.array([abs(mu_in)]))
        ii, wi_ = ii[0], wi_[0]
        pts, gw, bin_of = _bin_quadrature(grid.mu, mu_edges)
        io, wo_ = spline_weights(grid.mu, pts)
        full_pts, full_w, _ = _bin_quadrature(grid.mu, np.array([0.0, 1.0]))
        full_io, full_wo = spline_weights(grid.mu, full_pts)
        # phi integrals of cos(l (phi_o - phi_in - pi)) over each phi bin
        m = op.m
        l = np.arange(m)[:, None]
        a = phi_edges[None, :] - phi_in - np.pi
        with np.errstate(divide="ignore", invalid="ignore"):
            prim = np.where(l == 0, a, np.sin(l * a) / np.where(l == 0, 1, l))
        phi_int = np.diff(prim, axis=1)                                  # (m, n_phi)
        top_from = ("Rt", "Ttb") if mu_in > 0 else ("Tbt", "Rb")
        out = {}
        for side, name in zip(("top", "bottom"), top_from):
            E = np.zeros((mu_edges.size - 1, phi_edges.size - 1))
            blk = op.blocks[name]
            if blk is not None:
                fw = grid.flux_weight
                delta = op.delta.get(name)
                # F[l, a] = sum_b w_b f_l(a, b): incident interpolation, then elevation integral
                F = np.empty((m, grid.h))
                for order, mat in enumerate(blk):
                    col = mat[:, ii].toarray() / (order_weight(order) * fw[ii])[None, :]
                    if delta is not None:
                        col[ii, np.arange(4)] -= delta[ii] / (order_weight(order) * fw[ii])
                    F[order] = col @ wi_
                vals = np.einsum("pk,lpk->lp", wo_, F[:, io])            # (m, points)
                M = np.zeros((m, mu_edges.size - 1))
                np.add.at(M.T, bin_of, (vals * (gw * pts)[None, :]).T)
                E = M.T @ phi_int
                # scale to the quadrature's energy of the same (smooth) part
                interp = np.sum(np.einsum("pk,pk->p", full_wo, F[0][full_io]) * full_w * full_pts)
                quad = np.sum(F[0] * fw)
                if interp != 0.0:
                    E *= quad / interp
                if delta is not None:
                    energy = float(np.dot(wi_, delta[ii]))
                    kmu = closed_bin(mu_edges, abs(mu_in))
                    kphi = closed_bin(phi_edges, (phi_in + np.pi) % (2 * np.pi))
                    if kmu is not None and kphi is not None:
                        E[kmu, kphi] += energy
            out[side] = E
        return out

    # ---- persistence -------------------------------------------------------------------

    def export(self, path, version: int | None = None, alpha=(0.0, 0.0), relerr: float = 0.0):
        """Write a ``.bsdf`` file (``SCATFUN``): version 1 for layerlab, Mitsuba 0.6 and pbrt-v3
        (isotropic BSDFs), version 2 in the Layer Laboratory's anisotropic layout; the default
        (None) is 1 for isotropic and 2 for anisotropic BSDFs. ``relerr`` (version 2) drops
        each pair's coefficients below that fraction of its largest. Returns the
        :class:`layersim.bsdffile.FourierTable` written. See :mod:`layersim.bsdffile`."""
        from .bsdffile import export
        return export(self, path, version=version, alpha=alpha, relerr=relerr)

    def save(self, path) -> Path:
        """Write the solved operators and metadata to ``path`` (numpy ``.npz`` container;
        reload with :meth:`BSDF.load`)."""
        path = Path(path)
        version = FORMAT_VERSION_ANISO if self.anisotropic else FORMAT_VERSION
        arrays = {"format": np.array("layersim-bsdf"), "version": np.array(version),
                  "channels": np.array(self.channels),
                  "info": np.array(json.dumps(self.info, default=str))}
        for c, op in enumerate(self.operators):
            arrays.update(op.to_arrays(prefix=f"c{c}_"))
        with open(path, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        return path

    @classmethod
    def load(cls, path) -> "BSDF":
        """Read a BSDF written by :meth:`save`."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as d:
                if str(d.get("format", "")) != "layersim-bsdf":
                    raise FileFormatError(f"{path}: not a layersim BSDF file")
                version = int(d["version"])
                if version > FORMAT_VERSION_ANISO:
                    raise FileFormatError(f"{path}: format version {version} is newer than "
                                          f"this layersim ({FORMAT_VERSION_ANISO}); upgrade "
                                          "layersim")
                ops = [_operator_from_arrays(d, prefix=f"c{c}_")
                       for c in range(int(d["channels"]))]
                info = json.loads(str(d["info"]))
        except FileFormatError:
            raise
        except (OSError, ValueError, KeyError) as exc:
            raise FileFormatError(f"{path}: cannot read BSDF file ({exc})") from None
        return cls(ops, None, info)

    def __repr__(self) -> str:
        op = self.operators[0]
        ms = f", ms={op.ms}" if self.anisotropic else ""
        return (f"BSDF({self.info.get('scene', '?')}: n={op.grid.n}, md={op.m}{ms}, "
                f"{self.channels} channel(s), {'opaque' if self.opaque else 'transmissive'})")


def _operator_from_arrays(d, prefix: str):
    """An isotropic or (version 2 files) anisotropic operator from saved arrays."""
    if str(d.get(f"{prefix}representation", "isotropic")) == "anisotropic":
        from .aniso.operator import AnisoOperator
        return AnisoOperator.from_arrays(d, prefix=prefix)
    return IsoOperator.from_arrays(d, prefix=prefix)


def closed_bin(edges: np.ndarray, x: float) -> int | None:
    """Index of the bin ``[edges[k], edges[k + 1])`` holding ``x``, the last bin closed (so that
    normal incidence, mu = 1, lands in the top elevation bin); None outside the edges."""
    if x == edges[-1]:
        return edges.size - 2
    k = int(np.searchsorted(edges, x, side="right")) - 1
    return k if 0 <= k < edges.size - 1 else None


def _edges(name, edges, lo, hi) -> np.ndarray:
    e = np.asarray(edges, float)
    if e.ndim != 1 or e.size < 2:
        raise ValueError(f"{name} must be a 1-D array of at least two edges")
    if not np.all(np.isfinite(e)) or np.any(np.diff(e) <= 0):
        raise ValueError(f"{name} must be finite and strictly increasing")
    if e[0] < lo - 1e-12 or e[-1] > hi + 1e-12:
        raise ValueError(f"{name} must lie within [{lo:g}, {hi:g}], got [{e[0]:g}, {e[-1]:g}]")
    return e


def _bin_quadrature(nodes: np.ndarray, edges: np.ndarray, order: int = 3):
    """Gauss-Legendre points integrating piecewise cubics (pieces between nodes) exactly over
    each bin: returns points, weights and the bin index of each point."""
    x, w = np.polynomial.legendre.leggauss(order)
    pts, wts, bins = [], [], []
    for b in range(edges.size - 1):
        lo, hi = edges[b], edges[b + 1]
        cuts = np.concatenate([[lo], nodes[(nodes > lo) & (nodes < hi)], [hi]])
        a, c = cuts[:-1], cuts[1:]
        half = 0.5 * (c - a)
        pts.append((0.5 * (a + c))[:, None] + half[:, None] * x[None, :])
        wts.append(half[:, None] * w[None, :])
        bins.append(np.full(a.size * order, b))
    return (np.concatenate([p.ravel() for p in pts]), np.concatenate([q.ravel() for q in wts]),
            np.concatenate(bins))
