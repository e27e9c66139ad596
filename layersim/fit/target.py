"""What a fit compares: the target as direction pairs and values of ``f cos(theta_o)``.

A solved BSDF (or a saved ``.lsim``) is sampled on a fixed set of direction pairs
(:func:`direction_pairs`), a tabulated file (``.bsdf``, MERL; :mod:`.tables`) on those of them
where the file has data; point measurements ``(wi, wo, f)`` are used as given. The residual of
a fit is, at every pair and channel, ``(f_model - f_target) cos(theta_o)`` (1/sr times a
cosine): the reflected radiance per unit incident irradiance, which weights each pair by what
it carries and stays finite at grazing views. Measurements with their standard deviations,
``(wi, wo, f, sigma)``, give the residuals ``(f_model - f) / sigma`` instead (dimensionless:
chi-square), so that points of larger noise (a noise proportional to f) weigh less and the
standard errors of the fit hold.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..errors import LayersimError
from ..solved.bsdf import BSDF
from .tables import TableTarget

__all__ = ["Target", "as_target", "direction_pairs"]

#: Incident elevations (degrees) and azimuths (degrees) of the pairs that sample a BSDF target:
#: up to 75 degrees, where the planner's default plan keeps every lobe sharp; three azimuths
#: so that anisotropic stacks are seen along and across their axes.
THETA_I = (0.0, 15.0, 30.0, 45.0, 60.0, 75.0)
PHI_I = (0.0, 45.0, 90.0)
#: Outgoing directions per incident one (a Fibonacci lattice on the upper hemisphere).
N_OUT = 256


def _fibonacci_hemisphere(n: int) -> np.ndarray:
    """``n`` nearly uniformly spread unit vectors with z > 0 (equal-area lattice), (n, 3)."""
    k = np.arange(n) + 0.5
    z = 1.0 - k / n
    phi = np.pi * (3.0 - np.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def direction_pairs(n_out: int = N_OUT) -> tuple:
    """The fixed pairs ``(wi, wo)``, each of shape (len(THETA_I) * len(PHI_I) * n_out, 3), on
    which a BSDF target is compared (reflection above the stack)."""
    th, ph = np.meshgrid(np.radians(THETA_I), np.radians(PHI_I), indexing="ij")
    th, ph = th.ravel(), ph.ravel()
    wi = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1)
    wo = _fibonacci_hemisphere(n_out)
    return np.repeat(wi, len(wo), axis=0), np.tile(wo, (len(wi), 1))


@dataclass(frozen=True)
class Target:
    """Direction pairs and the target's ``f cos(theta_o)`` on them.

    Attributes
    ----------
    wi, wo : ndarray, shape (N, 3)
        Unit directions toward the light and the viewer.
    f : ndarray, shape (N, C)
        The target BSDF value (1/sr) per channel.
    points : bool
        True for measurements (residual noise), False for a sampled BSDF.
    sigma : ndarray, shape (N, C), or None
        Standard deviations of ``f`` (1/sr), when the measurements come with them.
    source : str
        What the target is, for messages (empty: "the target").
    """

    wi: np.ndarray
    wo: np.ndarray
    f: np.ndarray
    points: bool
    sigma: np.ndarray | None = None
    source: str = ""

    @property
    def channels(self) -> int:
        return self.f.shape[1]

    @property
    def weight(self) -> np.ndarray:
        """``cos(theta_o)``, shape (N, 1), or ``1 / sigma``, shape (N, C) (1/sr)^-1."""
        return self.wo[:, 2:3] if self.sigma is None else 1.0 / self.sigma

    @property
    def unit(self) -> str:
        """The unit of the residuals."""
        return "1/sr (f cos theta_o)" if self.sigma is None else "sigma (chi)"

    def residual(self, bsdf: BSDF) -> np.ndarray:
        """The residuals (module docstring) flattened, shape (N * C,)."""
        f = np.asarray(bsdf.eval(self.wi, self.wo), dtype=float).reshape(len(self.wi), -1)
        return ((f - self.f) * self.weight).ravel()


def _unit(a, name: str) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"fit target: {name} must have shape (N, 3), got {a.shape}")
    norm = np.linalg.norm(a, axis=1)
    if not np.all(np.isfinite(a)) or np.any(norm == 0):
        raise ValueError(f"fit target: {name} holds a zero or non-finite direction")
    if np.any(a[:, 2] <= 0):
        raise ValueError(f"fit target: {name} must point above the surface (z > 0): the fit "
                         "compares reflection")
    return a / norm[:, None]


def _sigma(sigma, f) -> np.ndarray | None:
    if sigma is None:
        return None
    sigma = np.asarray(sigma, dtype=float)
    sigma = sigma[:, None] if sigma.ndim == 1 else sigma
    if sigma.shape != f.shape:
        raise ValueError(f"fit target: sigma must have the shape of f, {f.shape}, got "
                         f"{sigma.shape}")
    if not np.all(np.isfinite(sigma) & (sigma > 0)):
        raise ValueError("fit target: sigma must be positive and finite")
    return sigma


def _points(wi, wo, f, sigma=None) -> Target:
    wi, wo = _unit(wi, "wi"), _unit(wo, "wo")
    f = np.asarray(f, dtype=float)
    f = f[:, None] if f.ndim == 1 else f
    if f.ndim != 2 or len(f) != len(wi) or len(wo) != len(wi):
        raise ValueError(f"fit target: wi, wo and f must have N rows (shapes (N, 3), (N, 3), "
                         f"(N,) or (N, C)), got {len(wi)}, {len(wo)} and {f.shape}")
    if not np.all(np.isfinite(f)):
        raise ValueError("fit target: f holds a non-finite value")
    return Target(wi, wo, f, points=True, sigma=_sigma(sigma, f))


def _table(table: TableTarget) -> Target:
    """The pairs of :func:`direction_pairs` where ``table`` has data, and its values there."""
    wi, wo = direction_pairs()
    keep = table.valid(wi, wo)
    if not np.any(keep):
        raise LayersimError(f"fit target: {table.source} has no data on the pairs a fit "
                            "compares (reflection above the surface, theta_i <= 75 degrees)")
    wi, wo = wi[keep], wo[keep]
    f = np.asarray(table.f(wi, wo), dtype=float).reshape(len(wi), -1)
    if not np.all(np.isfinite(f)):
        raise LayersimError(f"fit target: {table.source} holds a non-finite value")
    return Target(wi, wo, f, points=False, source=table.source)


def as_target(target, wavelengths=None) -> Target:
    """A :class:`Target` from a solved BSDF, the path of a target file (:mod:`.files`: a saved
    BSDF ``.lsim``, a tabulated ``.bsdf``, a MERL ``.binary``, points ``.npz`` or ``.csv``) or
    point measurements ``(wi, wo, f)`` of shapes (N, 3), (N, 3), (N,) or (N, C), optionally
    with the standard deviations of f, ``(wi, wo, f, sigma)``, sigma of the shape of f.
    ``wavelengths`` (nm, one per channel): where a spectral RGL file is evaluated.

    Raises
    ------
    ValueError
        Arrays of the wrong shapes, directions below the surface, non-finite values.
    LayersimError
        A file that cannot be read or is of no accepted kind (``FileFormatError``), or a
        target of another type.
    """
    if isinstance(target, Target):
        return target
    if isinstance(target, (str, os.PathLike)):
        from .files import read_target
        target = read_target(target, wavelengths)
    if isinstance(target, BSDF):
        wi, wo = direction_pairs()
        f = np.asarray(target.eval(wi, wo), dtype=float).reshape(len(wi), -1)
        return Target(wi, wo, f, points=False)
    if isinstance(target, TableTarget):
        return _table(target)
    if isinstance(target, (tuple, list)) and len(target) in (3, 4):
        return _points(*target)
    raise LayersimError("a fit target is a solved BSDF, the path of a target file (.lsim, "
                        ".bsdf, MERL .binary, .npz, .csv) or point measurements (wi, wo, f) "
                        f"or (wi, wo, f, sigma), got {type(target).__name__}")
