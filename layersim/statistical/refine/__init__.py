"""Designs that hold in exact transport: a statistical design (Bati et al. 2021) refined by
exact fits to its target lobes.

Top-down, as the design itself is built (Bati et al. 2021, Algorithm 2): stage ``k`` frees the
layers of lobe ``k`` (its interfaces and the media above them, :mod:`.template`) around their
statistical values, keeps the layers above as refined, and fits the stack cut below the lobe
with :func:`layersim.fit` (every residual an exact solve by the adding equations) to the exact
BSDF of the cut above it plus the lobe wanted (:mod:`.samples`). Lobe ``k`` in exact transport
being the difference of the two cuts (sec. 6.1), each stage matches its own lobe, which a fit
of the whole stack to the sum of the lobes does not: lobes of similar widths trade energy there
(a coat of roughness 0.15 over a dielectric lobe of 0.3 ended 63 % off in lobe energy against
23 % before). Smooth lobes keep their layers: their Fresnel mirror is the same in the model
and in exact transport. Both designs are then measured by their exact lobes against the
targets (:mod:`.mismatch`).

    from layersim.statistical.refine import refine
    result = refine(design, targets)        # a Design and Targets of layersim.statistical
    result.refined.scene, result.mismatch["refined"]["energy"]
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass, replace

from ...scene import Scene
from ..lobes import StatisticalBSDF
from ..verify import exact_lobes
from .mismatch import lobe_mismatch
from .samples import stage_samples
from .template import has_free, refine_template

__all__ = ["refine", "Refinement", "REFINED_NOTE"]

#: The note a refined design carries (its TOML file's comment).
REFINED_NOTE = ("refined by exact fits to the target lobes (layersim design --exact): "
                "indices, roughnesses, conductor k, optical depths")
#: Tolerance of each fit (:func:`layersim.fit`'s ``tol``): the lobes' relative errors are
#: read to 0.1 %, far above what 1e-6 on the cost leaves.
FIT_TOL = 1e-6


@dataclass
class Refinement:
    """A statistical design and its refinement.

    Attributes
    ----------
    statistical, refined : Design
        The two designs (the refined one: the same layers, groups and choice, fitted values).
    lobes : dict
        ``"statistical"`` / ``"refined"`` -> per target lobe ``(energy, roughness)`` per
        channel in exact transport (:func:`~layersim.statistical.verify.exact_lobes`).
    mismatch : dict
        ``"statistical"`` / ``"refined"`` -> :func:`.mismatch.lobe_mismatch`.
    fits : list of (int, FitResult)
        The stages: the lobe (0: top) and its fit (:class:`layersim.fit.FitResult`).
    seconds : float
        Wall time of the stages (s): the fits and the solves of the cuts above them.
    """

    statistical: object
    refined: object
    lobes: dict
    mismatch: dict
    fits: list
    seconds: float

    @property
    def solves(self) -> int:
        """Exact solves of the fits."""
        return sum(len(f.history) for _, f in self.fits)


def _memo_solve(threads):
    """:func:`layersim.solve` remembering its results per scene (the cuts above the stages
    are the refined design's cuts)."""
    from ...solver import solve
    cache = {}

    def run(scene):
        key = repr(scene.stacks)
        if key not in cache:
            cache[key] = solve(scene, threads=threads)
        return cache[key]
    return run


def _stage(data, targets, model, groups, k, solve, threads, progress):
    """Fit lobe ``k``'s layers of the design dict ``data`` (refined above ``k``); returns the
    fit, or None where they have nothing to free (a smooth lobe), and the new dict."""
    from ...fit import Template, fit
    first = max(groups[k - 1]) + 1 if k else 0
    cut = {**data, "layer": data["layer"][:max(groups[k]) + 1]}
    raw = refine_template(cut, range(first, len(cut["layer"])), targets.eta_max)
    if targets.lobes[k].roughness <= 0.0 or not has_free(raw):
        return None, data
    template = Template(raw)
    above = solve(Scene.from_dict({**data, "layer": data["layer"][:first]})) if k else None
    samples = stage_samples(targets, model, groups, k, above,
                            template.scene(template.start).channels)
    result = fit(template, samples, threads=threads, progress=progress, tol=FIT_TOL)
    fitted = template.as_dict([result.params[name] for name in template.names])
    out = copy.deepcopy(data)
    out["layer"][:len(cut["layer"])] = fitted["layer"]
    return result, out


def refine(design, targets, *, threads: int | None = None, progress: bool | None = None,
           discretization: dict | None = None) -> Refinement:
    """Refine the statistical ``design`` of ``targets`` by exact fits (module docstring).

    Parameters
    ----------
    design : Design
        A design of ``targets`` (:func:`layersim.statistical.design.designs`).
    targets : Targets
        The parsed targets (:func:`layersim.statistical.parse_targets`).
    threads : int, optional
        Threads of each solve.
    progress : bool, optional
        The fits' progress bars on stderr (default: when stderr is a terminal).
    discretization : dict, optional
        ``n`` and ``md`` of every solve, the fits' (then one stage each, on it) and the
        measurement's (quick looks and tests); default: the planner's plans.

    Raises
    ------
    InfeasibleError
        Where the solver refuses the design, or solves it as specular paths, which the fits
        do not take (its plan, checked before any fit).
    """
    from ...fit.optimize import fourier_plan
    fourier_plan(design.scene)
    model, solve = StatisticalBSDF(design.scene), _memo_solve(threads)
    data, fits = copy.deepcopy(design.data), []
    if discretization:
        data["discretization"] = dict(discretization)
        design = replace(design, data=data, scene=Scene.from_dict(data))
    t0 = time.perf_counter()
    for k in range(len(design.groups)):
        result, data = _stage(data, targets, model, design.groups, k, solve, threads, progress)
        if result is not None:
            fits.append((k, result))
    seconds = time.perf_counter() - t0
    refined = replace(design, data=data, scene=Scene.from_dict(data),
                      notes=design.notes + (REFINED_NOTE,))
    lobes = {"statistical": exact_lobes(design, solve), "refined": exact_lobes(refined, solve)}
    return Refinement(design, refined, lobes,
                      {k: lobe_mismatch(targets, v) for k, v in lobes.items()}, fits, seconds)
