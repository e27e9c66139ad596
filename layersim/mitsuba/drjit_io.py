"""Dr.Jit values of a Mitsuba 3 variant to numpy rows and back, once per call.

Scalar variants (``scalar_*``) pass one ray per call as scalar arrays; JIT variants
(``llvm_*``, ``cuda_*``) pass wavefronts whose members may have width 1 (a value shared by all
rays, e.g. ``si.wi`` set from a constant) or the wavefront's width. :func:`rows` brings every
input to ``(N, k)`` float64 (or ``(N,)``) with the common width ``N``; :class:`Writer` builds
the variant's types from numpy results.

Spectra: the plug-in computes one value per channel of the solved stack (1 or 3). ``rgb``
variants take three channels (a one-channel stack is grey); ``mono`` variants take the
luminance (Rec. 709, as Mitsuba reduces RGB inputs there); ``spectral`` variants take a
one-channel stack as a flat spectrum and (``scalar_spectral`` only: the model's lookup takes one
scalar colour) a three-channel one through Mitsuba's RGB-to-spectrum model (Jakob & Hanika 2019, ``mi.srgb_model_fetch`` / ``srgb_model_eval``) applied to the RGB
value divided by its largest channel and scaled back, which keeps values above 1 (BSDF values
are not reflectances) and is exact for grey.
"""

from __future__ import annotations

import numpy as np

from ..solved.channels import luminance


def width(x) -> int:
    """Number of rays in a Dr.Jit value (1 for scalars and scalar arrays)."""
    import drjit as dr
    try:
        return int(dr.width(x))
    except TypeError:
        return 1


def rows(x, n: int, k: int) -> np.ndarray:
    """A Dr.Jit value with ``k`` components (``k = 0``: a plain number per ray) as float64
    numpy of shape ``(n, k)`` (or ``(n,)``), broadcasting width-1 values to ``n`` rays."""
    a = np.asarray(x, dtype=np.float64)
    if k == 0:
        return np.broadcast_to(a.reshape(-1), (n,)).copy()
    return np.broadcast_to(a.reshape(k, -1).T, (n, k)).copy()


def mask(x, n: int) -> np.ndarray:
    """A Dr.Jit mask (or a Python bool) as numpy bool ``(n,)``."""
    return np.broadcast_to(np.asarray(x, dtype=bool).reshape(-1), (n,)).copy()


def unit_rows(x, n: int) -> np.ndarray:
    """Directions as float64 unit rows ``(n, 3)``: renormalised in double precision, since
    single-precision variants hand over vectors whose length differs from 1 by ~1e-7 and
    layersim checks unit length; zero vectors (inactive lanes) become ``(0, 0, 1)``."""
    v = rows(x, n, 3)
    norm = np.linalg.norm(v, axis=1)
    bad = ~(norm > 0) | ~np.isfinite(norm)
    v[bad] = (0.0, 0.0, 1.0)
    norm[bad] = 1.0
    return v / norm[:, None]


class Writer:
    """Builds the current variant's Dr.Jit values from numpy results.

    Parameters
    ----------
    mi : module
        ``mitsuba`` with a variant set.
    si : mitsuba.SurfaceInteraction3f
        The interaction of the call (its ``wavelengths`` in spectral variants).
    n : int
        Rays in the call.
    """

    def __init__(self, mi, si, n: int):
        self.mi = mi
        self.scalar = mi.variant().startswith("scalar")
        self.variant = mi.variant()
        self.si = si
        self.n = n

    def float(self, a: np.ndarray):
        """``mi.Float`` from ``(n,)``."""
        return float(a[0]) if self.scalar else self.mi.Float(np.asarray(a, np.float32))

    def uint(self, a: np.ndarray):
        """``mi.UInt32`` from ``(n,)`` non-negative integers."""
        return int(a[0]) if self.scalar else self.mi.UInt32(np.asarray(a, np.uint32))

    def vector(self, a: np.ndarray):
        """``mi.Vector3f`` from ``(n, 3)``."""
        if self.scalar:
            return self.mi.Vector3f(*map(float, a[0]))
        return self.mi.Vector3f(np.ascontiguousarray(a.T, np.float32))

    def spectrum(self, a: np.ndarray):
        """``mi.Spectrum`` from per-channel values ``(n, C)``, C = 1 or 3 (module docstring)."""
        mi = self.mi
        if "mono" in self.variant:
            v = a[:, 0] if a.shape[1] == 1 else luminance(a)
            return mi.Spectrum(self.float(v))
        if "rgb" in self.variant:
            c = np.repeat(a, 3, axis=1) if a.shape[1] == 1 else a
            return mi.Spectrum(*(self.float(c[:, j]) for j in range(3)))
        if a.shape[1] == 1:
            return mi.Spectrum(self.float(a[:, 0]))
        return self._upsampled(a)

    def _upsampled(self, a: np.ndarray):
        """Spectral values of RGB rows ``(n, 3)`` at ``si.wavelengths`` (module docstring)."""
        mi = self.mi
        scale = a.max(axis=1)
        unit = np.divide(a, scale[:, None], out=np.zeros_like(a), where=scale[:, None] > 0)
        rgb = mi.Color3f(*(self.float(unit[:, j]) for j in range(3)))
        spec = mi.srgb_model_eval(mi.srgb_model_fetch(rgb), self.si.wavelengths)
        return spec * self.float(scale)
