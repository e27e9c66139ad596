"""The measured error of specular paths against the Monte Carlo walk, as the plan reports it.

:data:`MEASURED_ERROR` holds, per stack of ``tests/test_specular_paths_walk.py`` (the slow
comparison at 1e7 paths per direction, incidence 0, 30, 60 and 70 degrees, 10 x 12 bins per
side, warp-cpu), the largest albedo difference and the smallest fraction of populated bins
within 3 sigma.
"""

from __future__ import annotations

__all__ = ["MEASURED_ERROR", "measured_error_line"]

#: ``{stack: (largest |albedo difference|, smallest fraction of bins within 3 sigma)}``.
MEASURED_ERROR: dict = {}


def measured_error_line() -> str:
    """One line: the measured error of the stacks of :data:`MEASURED_ERROR`."""
    if not MEASURED_ERROR:
        return "error against Monte Carlo: not measured"
    worst_r = max(v[0] for v in MEASURED_ERROR.values())
    worst_b = min(v[1] for v in MEASURED_ERROR.values())
    names = ", ".join(MEASURED_ERROR)
    return (f"measured against Monte Carlo (tests/test_specular_paths_walk.py, 1e7 paths, "
            f"0-70 deg; {names}): albedo within {worst_r:.1e}, at least "
            f"{100 * worst_b:.1f} % of populated 10 x 12 bins within 3 sigma")
