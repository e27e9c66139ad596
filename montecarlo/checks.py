"""Checks of the inputs of a Monte Carlo run (:func:`~layersim.montecarlo.simulate`,
``layersim mc``): each raises ValueError naming the field before any walk starts."""

from __future__ import annotations

import numbers

import numpy as np

from ..scene import Scene

__all__ = ["check_int", "check_wi", "check_edges"]


def check_int(name: str, value, lo: int, hi: int | None) -> int:
    """``value`` as an int within ``[lo, hi]`` (``hi`` None: no upper bound)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer, got {value!r}")
    value = int(value)
    if value < lo or (hi is not None and value > hi):
        rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
        raise ValueError(f"{name} must be {rng}, got {value}")
    return value


def check_wi(wi, scene: Scene) -> np.ndarray:
    """``wi`` as a unit float64 direction of shape (3,) that lights ``scene`` (not grazing,
    not from below an opaque stack)."""
    try:
        w = np.asarray(wi, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"wi must be a direction (x, y, z), got {wi!r}") from None
    if w.shape != (3,):
        raise ValueError(f"wi must be one direction of shape (3,), got shape {w.shape}; "
                         "simulate() takes one incident direction per call")
    if not np.all(np.isfinite(w)):
        raise ValueError(f"wi must be finite, got {w}")
    norm = float(np.linalg.norm(w))
    if abs(norm - 1.0) > 1e-6:
        raise ValueError(f"wi must be a unit vector, got |wi| = {norm:.9g}; normalise it")
    w = w / norm
    if w[2] == 0.0:
        raise ValueError("wi.z must be non-zero: light at grazing incidence (wi.z = 0) never "
                         "enters the stack")
    if w[2] < 0 and scene.opaque:
        raise ValueError(f"wi.z < 0 lights the stack from below, but scene '{scene.name}' ends "
                         f"with an opaque {scene.stacks[0][-1].kind} layer; use wi.z > 0")
    return w


def check_edges(name: str, edges, hi: float, what: str) -> np.ndarray:
    """Strictly increasing float64 bin ``edges`` within ``[0, hi]`` (``what``: their unit)."""
    try:
        e = np.asarray(edges, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a 1-D sequence of numbers, got {edges!r}") from None
    if e.ndim != 1 or e.size < 2:
        raise ValueError(f"{name} must be a 1-D sequence of at least 2 edges, got shape "
                         f"{e.shape}")
    if not np.all(np.isfinite(e)):
        raise ValueError(f"{name} must be finite, got {e}")
    if np.any(np.diff(e) <= 0):
        raise ValueError(f"{name} must be strictly increasing, got {e}")
    if e[0] < 0 or e[-1] > hi * (1 + 1e-12):
        raise ValueError(f"{name} are edges in {what} and must lie within [0, {hi:.9g}], "
                         f"got [{e[0]:.9g}, {e[-1]:.9g}]")
    return np.minimum(e, hi)
