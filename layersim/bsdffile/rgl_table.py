"""The arrays of an RGL material file and their evaluation exactly as Mitsuba 3's ``measured``
plug-in and pbrt-v4's ``MeasuredBxDF`` evaluate them (the format and the reconstruction
formula: :mod:`layersim.bsdffile.rgl`). Used to check written files and to read any RGL file
(e.g. the RGL database's) without a renderer.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import FileFormatError
from . import tensorfile
from .marginal2d import Marginal2D
from .rgl_ndf import phi2u, theta2u


@dataclass
class RGLTable:
    """The arrays of an RGL file (module docstring) and their evaluation as renderers do."""

    theta_i: np.ndarray
    phi_i: np.ndarray
    ndf: np.ndarray
    sigma: np.ndarray
    vndf: np.ndarray
    luminance: np.ndarray
    spectra: np.ndarray
    wavelengths: np.ndarray | None          # None: the ``rgb`` flavour
    description: str = ""
    jacobian: bool = True
    _warps: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def isotropic(self) -> bool:
        return len(self.phi_i) <= 2

    @property
    def reduction(self) -> int:
        if self.isotropic:
            return 1
        return int(np.rint(2 * np.pi / (self.phi_i[-1] - self.phi_i[0])))

    def fields(self) -> dict:
        """The file's fields (name -> array with the readers' dtypes)."""
        f32 = lambda a: np.asarray(a, np.float32)          # noqa: E731
        out = {"description": np.frombuffer(self.description.encode("utf-8"), np.uint8),
               "jacobian": np.array([int(self.jacobian)], np.uint8),
               "theta_i": f32(self.theta_i), "phi_i": f32(self.phi_i), "ndf": f32(self.ndf),
               "sigma": f32(self.sigma), "vndf": f32(self.vndf),
               "luminance": f32(self.luminance)}
        if self.wavelengths is None:
            out["rgb"] = f32(self.spectra)
        else:
            out["spectra"] = f32(self.spectra)
            out["wavelengths"] = f32(self.wavelengths)
        return out

    def write(self, path) -> Path:
        return tensorfile.write(path, self.fields())

    @classmethod
    def from_fields(cls, f: dict, source: str = "RGL file") -> "RGLTable":
        """Check the fields as the readers do and wrap them."""
        _check_fields(f, source)
        rgb = "wavelengths" not in f
        return cls(theta_i=f["theta_i"], phi_i=f["phi_i"], ndf=f["ndf"], sigma=f["sigma"],
                   vndf=f["vndf"], luminance=f["luminance"],
                   spectra=f["rgb"] if rgb else f["spectra"],
                   wavelengths=None if rgb else f["wavelengths"],
                   description=bytes(f["description"]).decode("utf-8", "replace"),
                   jacobian=bool(f["jacobian"][0]))

    # ---- evaluation as the renderers do -----------------------------------------------

    def warp(self, name: str) -> Marginal2D:
        """The interpolant of field ``name`` (built on first use, from float32 values as the
        file holds them)."""
        if name not in self._warps:
            params = [self.phi_i, self.theta_i]
            lam = np.arange(3.0) if self.wavelengths is None else self.wavelengths
            spec = {"ndf": (self.ndf, [], False), "sigma": (self.sigma, [], False),
                    "vndf": (self.vndf, params, True),
                    "luminance": (self.luminance, params, True),
                    "spectra": (self.spectra, params + [lam], False)}[name]
            data, par, norm = spec
            self._warps[name] = Marginal2D(np.asarray(data, np.float32), [
                np.asarray(p, np.float32) for p in par], normalize=norm)
        return self._warps[name]

    def _coordinates(self, wi, wo):
        """Per pair: validity, the reduced directions' parameters and unit-square points."""
        wi = np.array(wi, np.float64).reshape(-1, 3)
        wo = np.array(wo, np.float64).reshape(-1, 3)
        active = (wi[:, 2] > 0) & (wo[:, 2] > 0)
        if self.reduction >= 2:                       # fold wi into the stored wedge
            sy = wi[:, 1].copy()
            sx = wi[:, 0].copy() if self.reduction == 4 else sy
            for v in (wi, wo):
                v[:, 0] = _mulsign_neg(v[:, 0], sx)
                v[:, 1] = _mulsign_neg(v[:, 1], sy)
        h = wi + wo
        h /= np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-300)
        theta_i, phi_i = _elevation(wi), np.arctan2(wi[:, 1], wi[:, 0])
        theta_h, phi_h = _elevation(h), np.arctan2(h[:, 1], h[:, 0])
        u_i = np.stack([theta2u(theta_i), phi2u(phi_i)], axis=-1)
        v_h = phi2u(phi_h - phi_i if self.isotropic else phi_h)
        u_h = np.stack([theta2u(theta_h), v_h - np.floor(v_h)], axis=-1)
        return active, wi, h, (phi_i, theta_i), u_i, u_h

    def eval(self, wi, wo, lam) -> np.ndarray:
        """``f cos(theta_o)`` as the renderers evaluate the file (Mitsuba's ``eval``, which
        includes the cosine), at ``wi`` (n, 3) toward the camera, ``wo`` (n, 3) toward the
        light, for each wavelength (nm) or, in the ``rgb`` flavour, channel index in ``lam``:
        shape (n, len(lam))."""
        active, _, _, params, u_i, u_h = self._coordinates(wi, wo)
        s, _ = self.warp("vndf").invert(u_h, params)
        out = np.stack([self.warp("spectra").eval(s, params + (np.full(len(s), x),))
                        for x in np.atleast_1d(lam)], axis=-1)
        if self.jacobian:
            out *= (self.warp("ndf").eval(u_h) / (4 * self.warp("sigma").eval(u_i)))[:, None]
        return np.where(active[:, None], out, 0.0)

    def pdf(self, wi, wo) -> np.ndarray:
        """Solid-angle density (1/sr) with which the renderers sample ``wo`` given ``wi``."""
        active, wi_r, h, params, _, u_h = self._coordinates(wi, wo)
        s, vndf_pdf = self.warp("vndf").invert(u_h, params)
        lum = self.warp("luminance").eval(s, params)
        sin_h = np.sqrt(np.maximum(1.0 - h[:, 2] ** 2, 0.0))
        jac = np.maximum(2 * np.pi ** 2 * u_h[:, 0] * sin_h, 1e-6) * 4 * np.sum(wi_r * h, -1)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(active, vndf_pdf * lum / jac, 0.0)


def _mulsign_neg(a, b):
    """``a`` with the sign opposite to ``b``'s (drjit ``mulsign_neg``: ``-a`` where ``b >= 0``)."""
    return np.where(b >= 0, -a, a)


def _elevation(d):
    """``acos(d.z)`` computed as the readers do (stable near the normal)."""
    dist = np.sqrt(d[:, 0] ** 2 + d[:, 1] ** 2 + (d[:, 2] - 1) ** 2)
    return 2 * np.arcsin(np.clip(0.5 * dist, -1.0, 1.0))


def _check_fields(f: dict, source: str) -> None:
    """The readers' structural checks (Mitsuba 3 ``Measured``), with the field named."""
    def need(cond, what):
        if not cond:
            raise FileFormatError(f"{source}: not an RGL material file ({what})")

    spec = "rgb" if "wavelengths" not in f else "spectra"
    for name in ("description", "jacobian", "theta_i", "phi_i", "ndf", "sigma", "vndf",
                 "luminance", spec):
        need(name in f, f"field {name!r} missing")
    P, T = len(f["phi_i"]), len(f["theta_i"])
    need(f["ndf"].ndim == 2 and f["sigma"].ndim == 2, "ndf and sigma must be 2D")
    need(f["vndf"].ndim == 4 and f["vndf"].shape[:2] == (P, T), "vndf must be (P, T, H, W)")
    L = 3 if spec == "rgb" else len(f["wavelengths"])
    need(f[spec].ndim == 5 and f[spec].shape[:3] == (P, T, L) and
         f[spec].shape[3] == f[spec].shape[4], f"{spec} must be (P, T, L, n, n)")
    need(f["luminance"].shape == (P, T) + f[spec].shape[3:], "luminance must be (P, T, n, n)")
    need(f["jacobian"].shape == (1,), "jacobian must hold one byte")


def read(path) -> RGLTable:
    """Read and check an RGL material file (ours or any other, e.g. the RGL database's)."""
    return RGLTable.from_fields(tensorfile.read(path), source=str(path))
