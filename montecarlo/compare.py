"""Monte Carlo walks against another estimate of the same bins: a solved BSDF or other walks.

Distances are in standard errors, with the conventions of
:meth:`layersim.montecarlo.MCResult.z_scores`: an empty or nearly empty bin has a tiny sample
standard error while its real spread is Poisson (variance >= E / N for a bin receiving energy E
per path), so ``max(other, 0) / N`` is added to the walk's variance; a bin is *populated* where
either estimate is nonzero (the other above 1e-12 for a solver). Against other walks both
standard errors enter, each with the Poisson floor of the other's energy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Comparison", "z_map", "against_values", "against_walk", "SIDES"]

SIDES = ("top", "bottom")
#: Smallest standard error a distance is divided by (a bin equal in both gives 0, not NaN).
_TINY = 1e-15


@dataclass(frozen=True)
class Comparison:
    """One walk against another estimate.

    Attributes
    ----------
    albedo_z : dict
        ``{"R": z, "T": z}``: (other - walk) / combined standard error of the reflectance and
        transmittance.
    albedo : dict
        ``{"R": (walk, walk_stderr, other), "T": ...}``.
    z : dict
        ``{"top" | "bottom": (n_mu, n_phi)}`` signed distances (other - walk) in standard
        errors, NaN where the bin is not populated.
    """

    albedo_z: dict
    albedo: dict
    z: dict

    def populated(self) -> np.ndarray:
        """|z| of every populated bin of both sides, flattened."""
        return np.abs(np.concatenate([v[np.isfinite(v)] for v in self.z.values()]))

    def within(self, k: float = 3.0) -> float:
        """Fraction of the populated bins with |z| <= k (1 when none is populated)."""
        z = self.populated()
        return float(np.mean(z <= k)) if z.size else 1.0

    def largest(self) -> tuple:
        """(|z|, side, i_mu, i_phi) of the farthest populated bin (|z| 0 if none)."""
        best = (0.0, "top", 0, 0)
        for side, v in self.z.items():
            if np.any(np.isfinite(v)):
                k = np.nanargmax(np.abs(v))
                i, j = np.unravel_index(k, v.shape)
                if abs(v[i, j]) > best[0]:
                    best = (float(abs(v[i, j])), side, int(i), int(j))
        return best


def z_map(est, err, particles, values, values_err=None, values_particles=None) -> np.ndarray:
    """Signed distances ``(values - est) / sigma`` of one side's bins, NaN where unpopulated.

    Parameters
    ----------
    est, err : ndarray (n_mu, n_phi)
        The walk's bin energies and standard errors.
    particles : int
        The walk's paths.
    values : ndarray (n_mu, n_phi)
        The other estimate (a solver's :meth:`~layersim.solved.bsdf.BSDF.bin_energies`, or a walk's).
    values_err, values_particles : optional
        For another walk: its standard errors and paths.
    """
    est, err, values = (np.asarray(a, float) for a in (est, err, values))
    var = err ** 2 + np.maximum(values, 0.0) / particles
    if values_err is None:
        populated = (est > 0) | (values > 1e-12)
    else:
        var = var + np.asarray(values_err, float) ** 2 + np.maximum(est, 0.0) / values_particles
        populated = (est > 0) | (values > 0)
    z = (values - est) / np.maximum(np.sqrt(var), _TINY)
    return np.where(populated, z, np.nan)


def _albedo(res, key: str, value: float, value_err: float = 0.0) -> tuple:
    est, err = float(getattr(res, key)), float(getattr(res, key + "_stderr"))
    return (value - est) / max(np.hypot(err, value_err), _TINY), (est, err, value)


def against_values(res, R: float, T: float, bins: dict) -> Comparison:
    """Walk ``res`` (:class:`MCResult`, one channel) against a solver's albedos ``R``, ``T``
    and bin energies ``bins`` (``{"top", "bottom"}: (n_mu, n_phi)``)."""
    zr, ar = _albedo(res, "reflectance", R)
    zt, at = _albedo(res, "transmittance", T)
    z = {s: z_map(res.bins[s], res.bins_stderr[s], res.particles, bins[s]) for s in SIDES}
    return Comparison({"R": zr, "T": zt}, {"R": ar, "T": at}, z)


def against_walk(res, other) -> Comparison:
    """Walk ``res`` against walk ``other`` (both :class:`MCResult` of the same bins)."""
    zr, ar = _albedo(res, "reflectance", other.reflectance, other.reflectance_stderr)
    zt, at = _albedo(res, "transmittance", other.transmittance, other.transmittance_stderr)
    z = {s: z_map(res.bins[s], res.bins_stderr[s], res.particles, other.bins[s],
                  other.bins_stderr[s], other.particles) for s in SIDES}
    return Comparison({"R": zr, "T": zt}, {"R": ar, "T": at}, z)
