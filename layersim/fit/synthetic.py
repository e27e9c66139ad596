"""Synthetic measurements of a known BSDF: what a gonioreflectometer with a stated noise would
record, for testing a fit against parameters that are known (``tests/test_fit.py``,
``benchmarks/accuracy/fit_recovery.py``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["noisy_points"]

#: What ``sigma`` adds so that it stays positive where ``f`` is 0 and no floor is given (1/sr).
TINY = 1e-9


def _directions(mu: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Unit vectors (n, 3) of elevation cosines ``mu`` and azimuths ``phi`` (radians)."""
    s = np.sqrt(1.0 - mu * mu)
    return np.stack([s * np.cos(phi), s * np.sin(phi), mu], axis=-1)


def noisy_points(bsdf, n: int = 3000, noise: float = 0.02, floor: float = 0.0, seed: int = 0,
                 mu_min: float = 0.1) -> tuple:
    """Point measurements of ``bsdf`` with Gaussian noise, and the noise they state.

    Parameters
    ----------
    bsdf : object with ``eval(wi, wo)``
        A solved BSDF (or anything that evaluates like one), f in 1/sr.
    n : int
        Number of direction pairs.
    noise : float
        Relative standard deviation of each reading (0.02: 2 %).
    floor : float
        Absolute standard deviation (1/sr) added to each reading: a detector's dark noise.
    seed : int
        Seed of :func:`numpy.random.default_rng`, which draws the directions, then the relative
        noise, then the floor noise (so that the same seed gives the same pairs and noise).
    mu_min : float
        Smallest elevation cosine of either direction.

    Returns
    -------
    wi, wo : ndarray, shape (n, 3)
        Directions toward the light and the viewer, ``mu`` uniform in ``[mu_min, 1)`` and
        azimuth uniform in ``[0, 2 pi)``.
    f : ndarray, shape (n,) or (n, C)
        ``bsdf.eval(wi, wo) (1 + noise N(0, 1))``, plus ``floor N(0, 1)`` with a floor (1/sr).
    sigma : ndarray, the shape of f
        The standard deviations the instrument states (1/sr): ``noise |f| + 1e-9`` without a
        floor, ``hypot(noise f, floor)`` with one.
    """
    rng = np.random.default_rng(seed)
    mu_i, mu_o = rng.uniform(mu_min, 1.0, (2, n))
    phi_i, phi_o = rng.uniform(0.0, 2.0 * np.pi, (2, n))
    wi, wo = _directions(mu_i, phi_i), _directions(mu_o, phi_o)
    f = np.asarray(bsdf.eval(wi, wo), dtype=float)
    f = f * (1.0 + noise * rng.standard_normal(f.shape))
    if not floor:
        return wi, wo, f, noise * np.abs(f) + TINY
    f = f + floor * rng.standard_normal(f.shape)
    return wi, wo, f, np.hypot(noise * f, floor)
