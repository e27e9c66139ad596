"""Validation of public direction arguments and their azimuths.

Directions follow ``docs/conventions.md``: unit vectors ``(..., 3)`` in the local frame, both
pointing away from the surface.
"""

from __future__ import annotations

import numpy as np


def unit_directions(name: str, v) -> np.ndarray:
    """``v`` as a float array of unit vectors (..., 3).

    Raises
    ------
    TypeError
        If ``v`` is not numeric (a string, None, a dict, ...), naming ``name``.
    ValueError
        If it has the wrong shape, non-finite entries or is not of unit length.
    """
    if isinstance(v, (str, bytes)) or v is None:
        raise TypeError(f"{name} must be unit vectors in the local frame, an array of shape "
                        f"(..., 3) such as [0, 0, 1] (z = normal), got {type(v).__name__} "
                        f"{v!r:.40}")
    try:
        v = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be unit vectors in the local frame, an array of shape "
                        f"(..., 3) such as [0, 0, 1] (z = normal), got {type(v).__name__}"
                        ) from None
    if v.ndim == 0 or v.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (..., 3) (unit vectors in the local frame), "
                         f"got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name} contains non-finite values")
    with np.errstate(over="ignore"):           # |v| of huge entries is inf: reported below
        norm = np.linalg.norm(v, axis=-1)
    if np.any(np.abs(norm - 1.0) > 1e-5):
        worst = norm.ravel()[np.argmax(np.abs(norm - 1.0).ravel())]
        raise ValueError(f"{name} must be unit vectors (|v| = 1 within 1e-5); normalise them "
                         f"first (found |v| = {worst:.6g})")
    return v


def direction_pairs(wi, wo) -> tuple[np.ndarray, np.ndarray, tuple]:
    """``wi`` and ``wo`` validated (:func:`unit_directions`), broadcast together and flattened
    to ``(Q, 3)``, with the broadcast shape ``(...)`` to give results back in."""
    wi, wo = np.broadcast_arrays(unit_directions("wi", wi), unit_directions("wo", wo))
    shape = wi.shape[:-1]
    return wi.reshape(-1, 3), wo.reshape(-1, 3), shape


def azimuth(v: np.ndarray) -> np.ndarray:
    """Azimuth ``atan2(y, x)`` (radians) of directions (..., 3)."""
    return np.arctan2(v[..., 1], v[..., 0])


def bin_edges(name: str, edges, lo: float, hi: float) -> np.ndarray:
    """``edges`` as a strictly increasing float array within ``[lo, hi]``; ValueError naming
    ``name`` otherwise."""
    try:
        e = np.asarray(edges, float)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a 1-D array of increasing numbers (bin edges), got "
                        f"{type(edges).__name__} {edges!r:.40}") from None
    if e.ndim != 1 or e.size < 2:
        raise ValueError(f"{name} must be a 1-D array of at least two edges")
    if not np.all(np.isfinite(e)) or np.any(np.diff(e) <= 0):
        raise ValueError(f"{name} must be finite and strictly increasing")
    if e[0] < lo - 1e-12 or e[-1] > hi + 1e-12:
        raise ValueError(f"{name} must lie within [{lo:g}, {hi:g}], got [{e[0]:g}, {e[-1]:g}]")
    return e


def incident_directions(wi, opaque: bool, base: str) -> np.ndarray:
    """Checked incident directions ``wi`` (..., 3) of a BSDF: unit vectors off the horizon,
    and from above where the stack is ``opaque`` (``base`` names what makes it so, for the
    message)."""
    wi = unit_directions("wi", wi)
    if np.any(wi[..., 2] == 0):
        raise ValueError("wi lies on the horizon (wi.z == 0): no light enters")
    if opaque and np.any(wi[..., 2] < 0):
        raise ValueError(f"this stack is opaque (its base is {base}): light cannot arrive "
                         "from below (wi.z < 0)")
    return wi


def bin_arguments(wi: np.ndarray, mu_edges, phi_edges) -> tuple[np.ndarray, np.ndarray]:
    """The checked ``(mu_edges, phi_edges)`` of ``bin_energies``, whose checked ``wi`` must be
    one direction of shape (3,)."""
    if wi.shape != (3,):
        raise ValueError(f"bin_energies takes one incident direction of shape (3,), got "
                         f"{wi.shape}")
    return (bin_edges("mu_edges", mu_edges, 0.0, 1.0),
            bin_edges("phi_edges", phi_edges, 0.0, 2.0 * np.pi))
