"""Fit a template to a target by exact transport: every residual is a solve of the concrete
scene by the adding equations (:func:`layersim.solve`).

Coarse to fine: a first stage solves on half the planner's ordinates and Fourier orders (of the
start scene), far from the optimum, where a rough residual suffices to move; the final stage
solves on the planner's plan of the first stage's optimum, and its Jacobian gives the standard
errors. Each stage keeps its discretisation fixed, so that the residuals are smooth in the
parameters and finite differences see the physics, not a change of plan. Where the final optimum
needs more ordinates or orders than the plan it was found on (a narrower or more anisotropic lobe
than the first stage's optimum), the final stage runs again from it on that optimum's plan, so
that the result is never matched through a truncated plan. A stage whose plan
turns out too coarse for a scene it visits (a narrower lobe, :class:`InfeasibleError`) is
restarted from its best point on the plan of that scene. The optimiser is
:func:`scipy.optimize.least_squares` (trust-region reflective, bounds, 2-point Jacobian).
"""

from __future__ import annotations

import sys

import numpy as np

from ..errors import InfeasibleError
from ..plan import make_plan
from ..solver import solve
from .result import FitResult, correlation, covariance, diagnose, misfit
from .target import Target, as_target
from .template import Template

__all__ = ["fit"]

#: Relative finite-difference step of the Jacobian: well above the solver's rounding, well
#: below the scale on which the BSDF bends.
DIFF_STEP = 1e-6
#: The coarse stage's fraction of the planner's ordinates and orders, and its floor.
COARSE = 0.5
MIN_COARSE_N, MIN_COARSE_MD = 32, 8
#: Tolerances (scipy's ftol, xtol and gtol) of the final stage by default and of the coarse one.
FINAL_TOL, COARSE_TOL = 1e-10, 1e-5
#: Restarts of a stage on a finer plan before giving up.
MAX_REPLANS = 3


class _Replan(Exception):
    def __init__(self, x):
        self.x = x


def _even(n: float) -> int:
    return int(2 * np.ceil(n / 2))


def fourier_plan(scene):
    """The planner's plan of ``scene``, refused where it routes the stack to specular paths
    (:mod:`layersim.specular_paths`): the fit's stages are Fourier discretisations (``n``,
    ``md``), which such a stack does not have."""
    plan = make_plan(scene)
    if plan.representation == "specular-paths":
        raise InfeasibleError(
            f"fit: scene {scene.name!r} is solved as specular paths (near-specular interfaces "
            "and clear media), which fit does not take: its stages refine a Fourier "
            "discretisation; free the roughnesses above 0.03 or give the template a rough "
            "or scattering layer")
    return plan


def like_discretisation(like) -> dict:
    """The discretisation (``n``, ``md``, quadrature rule and, if coupled, ``ms``) of a solved
    BSDF, as ``[discretization]`` entries (what :func:`layersim.solve` with ``like=`` uses)."""
    op = like.operators[0]
    out = {"n": int(op.grid.n), "md": int(op.m), "quadrature": op.grid.rule}
    ms = like.info.get("ms", getattr(op, "ms", None))
    return out | ({"ms": int(ms)} if ms else {})


def _stages(template: Template, coarse: bool, like=None) -> list:
    """The discretisations of the stages: ``[coarse, None]`` (None: plan at the stage's start),
    the template's own ``n``/``md`` for one stage when it fixes them, or with ``like`` (a solved
    BSDF) ``[coarse, like's discretisation]``, the coarse stage at half of like's (none where
    half would be below the floor: a coarser plan than the floor is refused by narrow lobes,
    and the restart would then plan above like's)."""
    own = {k: v for k, v in template.data.get("discretization", {}).items() if k in ("n", "md")}
    if own:
        return [own]
    last = None if like is None else like_discretisation(like)
    plan = fourier_plan(template.scene(template.start)) if last is None else None
    n, md = (plan.n, plan.md) if last is None else (last["n"], last["md"])
    first = {"n": max(_even(COARSE * n), MIN_COARSE_N), "md": max(int(COARSE * md), MIN_COARSE_MD)}
    if not coarse or first["n"] >= n or (last is not None and MIN_COARSE_N > COARSE * n):
        return [last]
    return [first, last]


class _Residuals:
    """The residual function of one stage, recording each solve in ``history``."""

    def __init__(self, template, target, disc, stage, history, bar, threads):
        self.template, self.target, self.disc = template, target, disc
        self.stage, self.history, self.bar, self.threads = stage, history, bar, threads
        self.best = (np.inf, template.start)

    def __call__(self, x) -> np.ndarray:
        try:
            bsdf = solve(self.template.scene(x, self.disc), threads=self.threads)
        except InfeasibleError:
            raise _Replan(np.array(x)) from None
        r = self.target.residual(bsdf)
        rms = float(np.sqrt(np.mean(r * r)))
        self.history.append({"stage": self.stage, **self.disc, "x": np.array(x), "rms": rms})
        if rms < self.best[0]:
            self.best = (rms, np.array(x))
        self.bar.update(1)
        self.bar.set_postfix_str(f"{self.stage} n={self.disc['n']} rms={rms:.3g}")
        return r


def _plan_of(template, x, disc=None) -> dict:
    plan = fourier_plan(template.scene(x))
    out = {"n": plan.n, "md": plan.md}
    if disc:            # a restart never coarsens the stage
        out = {k: max(out[k], disc[k]) for k in out}
    return out


def _run_stage(template, target, disc, x0, stage, history, bar, threads, tol):
    """Least squares over one stage; returns scipy's result, the residual function and the
    discretisation it ended on."""
    from scipy.optimize import least_squares
    disc = disc or _plan_of(template, x0)
    for _ in range(MAX_REPLANS + 1):
        fun = _Residuals(template, target, disc, stage, history, bar, threads)
        try:
            res = least_squares(fun, x0, bounds=(template.lo, template.hi), jac="2-point",
                                diff_step=DIFF_STEP, x_scale="jac", method="trf",
                                ftol=tol, xtol=tol, gtol=tol)
            return res, fun, disc
        except _Replan as exc:
            x0 = np.clip(fun.best[1], template.lo, template.hi)
            disc = _plan_of(template, exc.x, disc)
    raise InfeasibleError(f"fit: the planner's plan stayed too coarse after {MAX_REPLANS} "
                          "restarts; narrow the roughness bounds")


def _check_channels(template: Template, target: Target) -> None:
    channels = template.scene(template.start).channels
    if channels != target.channels:
        raise ValueError(f"fit: the template has {channels} channel(s), "
                         f"{target.source or 'the target'} has {target.channels}")


def fit(template, target, *, coarse: bool = True, threads: int | None = None,
        progress: bool | None = None, like=None, tol: float = FINAL_TOL) -> FitResult:
    """Fit the free values of ``template`` to ``target`` by exact transport.

    Parameters
    ----------
    template : Template, dict or path
        A scene with free values ``{ fit = [lo, hi], start = x }`` (:mod:`.template`).
    target : BSDF, path or tuple
        A solved BSDF; the path of a saved one (``.lsim``), of a tabulated BSDF (``.bsdf``:
        Fourier or RGL format), of a MERL binary (``.binary``) or of point measurements
        (``.npz``, ``.csv``) (:mod:`.files`, :mod:`.tables`); or point measurements ``(wi,
        wo, f)`` of shapes (N, 3), (N, 3), (N,) or (N, C) with f in 1/sr, optionally with the
        standard deviations of f as a fourth array (:func:`.target.as_target`). A spectral
        RGL file is evaluated at the template's ``[stack] wavelengths``.
    coarse : bool
        Start with the coarse stage (module docstring).
    threads : int, optional
        Threads of each solve.
    progress : bool, optional
        A progress bar on stderr (default: when stderr is a terminal).
    like : BSDF, optional
        Solve the final stage on this BSDF's discretisation (:func:`layersim.solve` ``like=``)
        instead of the planner's: a BSDF target's own, so that the fit and the target share
        their discretisation error (model-based subtraction, :mod:`.modelsub`).
    tol : float
        Tolerance of the final stage on the cost, the step and the gradient (scipy's ``ftol``,
        ``xtol``, ``gtol``); the coarse stage stops at the larger of it and 1e-5.

    Returns
    -------
    FitResult
        Minimising the sum of squares of ``(f_model - f_target) cos(theta_o)`` over the
        target's direction pairs and channels (of ``(f_model - f) / sigma`` for measurements
        with standard deviations).

    Raises
    ------
    SceneError, ValueError
        A bad template or target, before any solve.
    """
    from tqdm import tqdm
    template = template if isinstance(template, Template) else Template(template)
    target = as_target(target, template.scene(template.start).wavelengths)
    _check_channels(template, target)
    history, plans, x = [], [], template.start
    stages = _stages(template, coarse, like)
    with tqdm(desc="fit", unit="solve", disable=not (sys.stderr.isatty() if progress is None
                                                     else progress)) as bar:
        for k, disc in enumerate(stages):
            final = k == len(stages) - 1
            res, fun, disc = _run_stage(template, target, disc, x, "final" if final else
                                        "coarse", history, bar, threads,
                                        tol if final else max(tol, COARSE_TOL))
            for _ in range(MAX_REPLANS if final and like is None else 0):
                grown = _plan_of(template, res.x, disc)
                if grown == disc:
                    break
                plans.append({**disc, "nfev": res.nfev})
                res, fun, disc = _run_stage(template, target, grown, res.x, "final", history,
                                            bar, threads, tol)
            x = res.x
            plans.append({**disc, "nfev": res.nfev})
    return _result(template, res, history, plans, target.unit)


def _result(template: Template, res, history: list, plans: list, unit: str) -> FitResult:
    cov, cond = covariance(res.jac, res.fun)
    corr = correlation(cov)
    names = template.names
    warnings = diagnose(names, res.x, template.lo, template.hi, res.jac, cond, corr,
                        res.active_mask)
    warnings += misfit(res.fun, unit)
    if res.status <= 0:
        warnings.append(f"the optimiser stopped before converging: {res.message}")
    return FitResult(scene=template.scene(res.x),
                     params=dict(zip(names, map(float, res.x))),
                     uncertainty=dict(zip(names, map(float, np.sqrt(np.diag(cov))))),
                     correlation=corr, residual=float(np.sqrt(np.mean(res.fun ** 2))),
                     residuals=res.fun, unit=unit, history=history, warnings=warnings, plans=plans)
