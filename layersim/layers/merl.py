"""Measured isotropic BRDFs in the MERL binary layout (Matusik et al. 2003, "A data-driven
reflectance model"), as an opaque base layer (``kind = "measured"``).

File layout (little-endian): three int32 ``dims = (90, 90, 180)``, then
``3 * 90 * 90 * 180`` float64 values, channel-major (red, green, blue), each channel indexed
``[theta_h, theta_d, phi_d]`` (row-major, ``phi_d`` fastest). Stored values times the channel's
scale (:data:`SCALES`: 1/1500, 1.15/1500, 1.66/1500) are the BRDF in 1/sr; negative values mark
unmeasured samples and read as 0 (counted in :attr:`MERLTable.missing`).

Sample positions (Rusinkiewicz half/difference angles, ``phi_d`` folded to [0, pi) by
reciprocity): ``theta_h = (i / 90)^2 pi/2`` (the square-root mapping that crowds samples toward
the specular peak), ``theta_d = j pi / 180`` and ``phi_d = k pi / 180``. MERL's reference reader
takes the sample below; layersim interpolates trilinearly in the index coordinates
``(90 sqrt(theta_h / (pi/2)), theta_d / 1 deg, phi_d / 1 deg)``, periodic in ``phi_d`` and clamped
at the last ``theta`` samples, so that a smooth BRDF written at the sample positions is read back
to second order (:mod:`layersim.kernels.measured` holds the same lookup for the kernels).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SceneError

__all__ = ["MERLTable", "read_merl", "write_merl", "half_diff", "DIMS", "SCALES"]

#: Samples in theta_h, theta_d, phi_d.
DIMS = (90, 90, 180)
#: Scale of the stored values of the red, green and blue channels.
SCALES = (1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0)


@dataclass(frozen=True, eq=False)
class MERLTable:
    """A measured BRDF: ``values[c, i, j, k]`` (1/sr, scaled, unmeasured samples 0) at the sample
    positions of the module docstring; ``source`` names the file; ``missing`` counts the
    unmeasured samples; ``measured[i, j, k]`` (bool) is True where every channel was measured
    (None: everywhere)."""

    values: np.ndarray
    source: str = ""
    missing: int = 0
    measured: np.ndarray | None = None

    def eval(self, wi, wo) -> np.ndarray:
        """BRDF (1/sr) of unit directions (..., 3), both above the surface; shape (3, ...)."""
        u, v, w = _index_coords(*half_diff(np.asarray(wi, float), np.asarray(wo, float)))
        out = _trilinear(self.values, u, v, w)
        up = (np.asarray(wi)[..., 2] > 0) & (np.asarray(wo)[..., 2] > 0)
        return np.where(up, out, 0.0)

    def measured_at(self, wi, wo) -> np.ndarray:
        """Whether the interpolation of :meth:`eval` at unit directions (..., 3) rests on
        measured samples only (every corner of nonzero weight), bool (...)."""
        if self.measured is None:
            return np.ones(np.broadcast_shapes(np.shape(wi), np.shape(wo))[:-1], bool)
        u, v, w = _index_coords(*half_diff(np.asarray(wi, float), np.asarray(wo, float)))
        share = _trilinear(self.measured[None].astype(float), u, v, w)[0]
        return share > 1.0 - 1e-9

    def packed(self, channel: int, dtype=np.float32) -> np.ndarray:
        """The values of one channel, flat (``[i, j, k]`` row-major), for the kernels."""
        return np.ascontiguousarray(self.values[channel].ravel(), dtype=dtype)

    def equivalent_alpha(self) -> float:
        """Width (radians) of the brightest channel's lobe in ``theta_h`` near
        ``theta_d = 0``: where its mean over ``phi_d``, less its minimum, first falls to 1/e of
        its value at the specular peak; ``pi/2`` when it never does (diffuse). The planner
        sizes ``n`` and ``md`` as for a Beckmann lobe of that roughness."""
        prof = self.values[:, :, :10, :].mean(axis=(2, 3))
        prof = prof[int(np.argmax(prof[:, 0]))]
        prof = prof - prof.min()        # the lobe above the floor that diffuse reflection makes
        theta_h = (np.arange(DIMS[0]) / DIMS[0]) ** 2 * (0.5 * np.pi)
        below = np.flatnonzero(prof < prof[0] / math.e)
        if not prof[0] > 0 or not below.size:
            return 0.5 * np.pi
        return float(max(theta_h[below[0]], 0.01))


def half_diff(wi: np.ndarray, wo: np.ndarray):
    """Rusinkiewicz's half/difference angles ``(theta_h, theta_d, phi_d)`` of direction pairs
    (radians; ``phi_d`` folded to [0, pi))."""
    h = wi + wo
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    th = np.arctan2(np.hypot(h[..., 0], h[..., 1]), h[..., 2])
    ph = np.arctan2(h[..., 1], h[..., 0])
    # rotate wi by -phi_h about z, then by -theta_h about y
    c, s = np.cos(ph), np.sin(ph)
    x = wi[..., 0] * c + wi[..., 1] * s
    y = -wi[..., 0] * s + wi[..., 1] * c
    z = wi[..., 2]
    ct, st = np.cos(th), np.sin(th)
    dx = x * ct - z * st
    dz = x * st + z * ct
    td = np.arctan2(np.hypot(dx, y), dz)
    pd = np.arctan2(y, dx)
    return th, td, np.where(pd < 0, pd + np.pi, pd)


def _index_coords(th, td, pd):
    u = np.sqrt(np.clip(th / (0.5 * np.pi), 0.0, 1.0)) * DIMS[0]
    return u, td / (0.5 * np.pi) * DIMS[1], (pd / np.pi * DIMS[2]) % DIMS[2]


def _trilinear(values, u, v, w):
    i = np.clip(np.floor(u).astype(int), 0, DIMS[0] - 2)
    j = np.clip(np.floor(v).astype(int), 0, DIMS[1] - 2)
    k = np.floor(w).astype(int) % DIMS[2]
    a = np.clip(u - i, 0.0, 1.0)
    b = np.clip(v - j, 0.0, 1.0)
    c = np.clip(w - np.floor(w), 0.0, 1.0)
    k1 = (k + 1) % DIMS[2]
    out = 0.0
    for di, wa in ((0, 1 - a), (1, a)):
        for dj, wb in ((0, 1 - b), (1, b)):
            out = out + wa * wb * ((1 - c) * values[:, i + di, j + dj, k]
                                   + c * values[:, i + di, j + dj, k1])
    return out


def read_merl(path, layer: int | None = None, kind: str | None = None,
              fld: str = "file") -> MERLTable:
    """Read a MERL binary BRDF file (module docstring).

    Raises
    ------
    SceneError
        Naming the file (and the layer and field) if it cannot be read, has other dimensions,
        is truncated or holds non-finite values.
    """
    path = Path(path)

    def bad(msg):
        return SceneError(f"measured BRDF {path}: {msg}", layer=layer, kind=kind, field=fld)

    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise bad(f"cannot read the file ({exc.strerror or exc})") from None
    if len(raw) < 12:
        raise bad("too short for the MERL header (three int32 dimensions)")
    dims = tuple(int(x) for x in np.frombuffer(raw[:12], dtype="<i4"))
    if dims != DIMS:
        raise bad(f"dimensions {dims}; the MERL layout has {DIMS} (theta_h, theta_d, phi_d)")
    n = 3 * DIMS[0] * DIMS[1] * DIMS[2]
    if len(raw) != 12 + 8 * n:
        raise bad(f"{len(raw)} bytes; a MERL file has 12 + 8 x {n} = {12 + 8 * n}")
    values = np.frombuffer(raw[12:], dtype="<f8").reshape(3, *DIMS)
    if not np.all(np.isfinite(values)):
        raise bad("non-finite values")
    missing = int(np.count_nonzero(values < 0))
    measured = np.all(values >= 0, axis=0)
    values = np.maximum(values, 0.0) * np.asarray(SCALES)[:, None, None, None]
    return MERLTable(values, source=str(path), missing=missing, measured=measured)


def write_merl(path, brdf) -> None:
    """Write ``brdf(theta_h, theta_d, phi_d)`` (radians, broadcast; returns (3, ...) values in
    1/sr) at the MERL sample positions, in the MERL layout (values divided by :data:`SCALES`)."""
    th = (np.arange(DIMS[0]) / DIMS[0]) ** 2 * (0.5 * np.pi)
    td = np.arange(DIMS[1]) * (0.5 * np.pi / DIMS[1])
    pd = np.arange(DIMS[2]) * (np.pi / DIMS[2])
    f = np.asarray(brdf(th[:, None, None], td[None, :, None], pd[None, None, :]), float)
    f = np.broadcast_to(f, (3, *DIMS)) / np.asarray(SCALES)[:, None, None, None]
    with open(path, "wb") as out:
        out.write(np.asarray(DIMS, dtype="<i4").tobytes())
        out.write(np.ascontiguousarray(f, dtype="<f8").tobytes())
