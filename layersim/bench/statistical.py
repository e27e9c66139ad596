"""Belcour's statistical model (:mod:`layersim.statistical`) as a third method of
``layersim bench``: its bin energies against the same reference as the solver and Monte Carlo,
on the scenes it represents (GGX interfaces and absorbing media; others are skipped with the
reason)."""

from __future__ import annotations

import time

import numpy as np

from ..statistical import StatisticalBSDF
from ..statistical.stack import UnsupportedStack


def statistical_row(scene, settings, ref_bins, ref_alb, solver_bins, error, albedo_error):
    """``{"seconds", "error", "albedo_error"}`` of the model against ``ref_bins`` (bins of
    both sides: the model has no transmitted distribution), or ``{"skipped": why}``."""
    try:
        model = StatisticalBSDF(scene)
    except UnsupportedStack as exc:
        return {"skipped": str(exc)}
    t0 = time.perf_counter()
    bins, alb = solver_bins(model, settings)
    seconds = time.perf_counter() - t0
    return {"seconds": seconds, "error": error(bins, ref_bins),
            "albedo_error": albedo_error(alb, ref_alb),
            "top_error": error(bins[:, 0], ref_bins[:, 0])}


def markdown(row: dict, fmt) -> list[str]:
    """Report lines of :func:`statistical_row`'s result."""
    if "skipped" in row:
        return [f"Statistical model (Belcour 2018): not applicable ({row['skipped']}).", ""]
    return ["| statistical model | seconds | error | top-side error | albedo err |",
            "|---|---:|---:|---:|---:|",
            f"| Belcour 2018 (Bati et al. 2021) | {row['seconds']:.3f} | {fmt(row['error'])} | "
            f"{fmt(row['top_error'])} | {fmt(row['albedo_error'])} |", ""]
