"""Validation of public direction arguments and their azimuths.

Directions follow ``docs/conventions.md``: unit vectors ``(..., 3)`` in the local frame, both
pointing away from the surface.
"""

from __future__ import annotations

import numpy as np


def unit_directions(name: str, v) -> np.ndarray:
    """``v`` as a float array of unit vectors (..., 3); ValueError naming ``name`` otherwise."""
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


def azimuth(v: np.ndarray) -> np.ndarray:
    """Azimuth ``atan2(y, x)`` (radians) of directions (..., 3)."""
    return np.arctan2(v[..., 1], v[..., 0])


def bin_edges(name: str, edges, lo: float, hi: float) -> np.ndarray:
    """``edges`` as a strictly increasing float array within ``[lo, hi]``; ValueError naming
    ``name`` otherwise."""
    e = np.asarray(edges, float)
    if e.ndim != 1 or e.size < 2:
        raise ValueError(f"{name} must be a 1-D array of at least two edges")
    if not np.all(np.isfinite(e)) or np.any(np.diff(e) <= 0):
        raise ValueError(f"{name} must be finite and strictly increasing")
    if e[0] < lo - 1e-12 or e[-1] > hi + 1e-12:
        raise ValueError(f"{name} must lie within [{lo:g}, {hi:g}], got [{e[0]:g}, {e[-1]:g}]")
    return e
