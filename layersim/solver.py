"""``solve``: scene -> plan -> layer operators -> adding -> BSDF; and ``add`` on solved BSDFs."""

from __future__ import annotations

import contextlib
import functools
import os
import time
from dataclasses import replace

import numpy as np
from threadpoolctl import threadpool_limits

from .plan import accuracy
from .stacking import adding
from .aniso import adding as aniso_adding
from .aniso.plan import STACK_RELERR, STACK_RELERR_INTERMEDIATE
from .solved.bsdf import BSDF, channel_pairs, refuse_boundary
from .specular_paths import SpecularPathsBSDF
from .config import settings
from .errors import InfeasibleError
from .ingredients.aniso_microfacet import AnisoProjectionStats
from .ingredients.microfacet import ProjectionStats
from .kernels.runtime import device_for
from .layers import OperatorJob, kind_of
from .layers.brushed import projected as brushed_projected
from .layers.near_specular_inner import projected as inner_projected
from .operators.operator import IsoOperator, Operator, common_representation
from .outofcore import memory
from .outofcore.workspace import Workspace
from .plan import Plan, make_plan
from .scene import Scene, as_scene


#: Projection methods for interfaces: "numeric" samples the BSDF per pair at a rate set by the
#: analytically known length of its series, then an FFT (default: more accurate at equal or
#: lower cost on the CPU, and much faster on a GPU; benchmarks/speed/projection_paths.py);
#: "semi-analytic" multiplies exact peak series by fitted smooth factors (Zeltner & Jakob 2018, sec. 4.1).
PROJECTIONS = ("numeric", "semi-analytic")


def _layer_operator(plan: Plan, grid, scene: Scene, i: int, stats: ProjectionStats,
                    projection: str = "numeric", device=None,
                    workspace: Workspace | None = None, notes: list | None = None):
    """The operator of layer ``i``, built by its kind (:meth:`layersim.layers.LayerKind.
    operator`); diagnostics of interfaces are appended to ``notes``."""
    job = OperatorJob(plan, grid, scene, i, stats, projection, device, workspace,
                      [] if notes is None else notes)
    return kind_of(scene.layers[i]).operator(job)


def _lobes(plan: Plan, mono: Scene) -> dict:
    """The near-specular lobes that the BSDF of the one-channel scene ``mono`` evaluates
    (:attr:`BSDF.lobes`): under a smooth boundary the plan's (a near-specular coat); else those
    the top layer's kind evaluates in place of its operator (a near-specular conductor alone, a
    brushed coat's direct reflection: :meth:`layersim.layers.LayerKind.evaluated_lobes`)."""
    if plan.boundary:
        return dict(plan.lobes)
    return kind_of(mono.layers[0]).evaluated_lobes(plan, mono, 0)


@contextlib.contextmanager
def _singular_as_infeasible(where: str, advice: str):
    """Report a singular or ill-conditioned linear system met inside the block (numpy's and
    SciPy's ``LinAlgError``, SuperLU's "singular" ``RuntimeError``) as an
    :class:`InfeasibleError` naming ``where`` and what to change (``advice``)."""
    try:
        yield
    except np.linalg.LinAlgError as exc:
        raise InfeasibleError(f"{where}: singular or ill-conditioned linear system ({exc}); "
                              f"{advice}") from None
    except RuntimeError as exc:
        if "singular" not in str(exc).lower():
            raise
        raise InfeasibleError(f"{where}: singular linear system ({exc}); {advice}") from None


#: What to change when the adding equations are singular: ``I - Rb1 Rt2`` is singular only when
#: light can bounce between the two operands without loss in some Fourier order.
_ADDING_ADVICE = ("the layers trap light without loss between them; give a medium an albedo "
                  "slightly below 1, a conductor some absorption, or change n / md in "
                  "[discretization]")


def solve(scene: Scene, like: BSDF | None = None, threads: int | None = None,
          verbose: bool = False, projection: str = "numeric", device=None,
          progress=None, tol: float | None = None, error_estimate: bool = False) -> BSDF:
    """Solve a scene with the adding equations in the Fourier basis.

    Parameters
    ----------
    scene : Scene, path or dict
        Validated scene (``Scene.from_toml`` / ``Scene.from_dict``), or what those read: the
        path of a TOML scene file or a dict of the same content. RGB scenes are solved per
        channel on one shared plan.
    like : BSDF or path, optional
        Reuse the discretisation (rule, n, md) of another solved BSDF (or of the saved BSDF at
        this path), so that the two can be combined with :func:`add` or
        :func:`layersim.subtract`.
    threads : int, optional
        Threads for the Fourier orders in the adding equations.
    verbose : bool
        Print the plan and timings.
    projection : {"numeric", "semi-analytic"}
        How interfaces are projected (see :data:`PROJECTIONS`).
    device : str, optional
        Warp device for the projection kernels (e.g. "cuda"; default: $LAYERSIM_DEVICE or cpu).
    progress : callable, optional
        ``progress(phase, done, total, what)``, called as each phase starts (``done = 0``) and
        after each of its steps: phase ``"projection"`` (a step per layer operator built, all
        channels) then ``"adding"`` (a step per channel); ``what`` names the step under way.
        The solver prints nothing through it; the command line draws progress bars with it.
    tol : float, optional
        Solve to this relative error of bin energies (18 x 36 bins per side, worst of 0, 30,
        60 and 80 degrees) instead of on the planner's ``n`` and ``md``: a ladder of
        discretisations, each the error estimate of the next (:mod:`layersim.plan.accuracy`). Also
        ``tol`` in the scene's ``[discretization]``.
    error_estimate : bool
        Estimate the discretisation error from companion solves at ``n`` and ``md`` over
        ``sqrt 2`` and over 2 (about half as much time again). With ``tol`` the estimate is
        always made.

    Returns
    -------
    BSDF
        With :attr:`BSDF.error_estimate` and ``info["accuracy"]`` when estimated.

    Raises
    ------
    TypeError
        For a ``scene`` or ``like`` of another type, saying what to pass.
    SceneError, FileFormatError, ConfigError, InfeasibleError
        For an invalid scene, an unreadable ``like`` file, an unusable device, or a plan over
        the limits; all before the layers are projected.
    """
    scene = as_scene(scene, "solve()")
    like = _like_argument(like)
    tol = scene.discretization.tol if tol is None else tol
    if tol is not None or error_estimate:
        if like is not None:
            raise ValueError("tol and error_estimate choose or vary the discretisation, which "
                             "like= fixes: give one or the other")
        # the rungs and the companion solve quietly: their plans are the ladder's business
        plain = functools.partial(solve, threads=threads, projection=projection,
                                  device=device, progress=progress)
        if tol is not None:
            return _solve_to_tolerance(scene, tol, plain, log=print if verbose else None)
        return _with_estimate(scene, plain, plain(scene))
    if device is not None or settings().device != "cpu":
        device_for(device)          # an unusable device is refused before the plan
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int)
                                or threads < 1):
        raise ValueError(f"threads must be an integer >= 1 or None, got {threads!r}")
    if projection not in PROJECTIONS:
        raise ValueError(f"unknown projection {projection!r}; expected one of "
                         + ", ".join(PROJECTIONS))
    # Single-threaded BLAS: the projection's batched small QRs and the adding's small dense
    # products run several times slower with OpenBLAS threads on matrices of this size, where
    # the threads' synchronisation outweighs the arithmetic.
    with threadpool_limits(1, user_api="blas"), _singular_as_infeasible(
            f"scene {scene.name!r}", "change n / md in [discretization] or the stiffest layer"):
        return _solve(scene, like, threads, verbose, projection, device,
                      progress or _no_progress)


def _solve_to_tolerance(scene: Scene, tol: float, solve_one, log=None) -> BSDF:
    """Climb the ladder of discretisations of :class:`layersim.plan.accuracy.Ladder`, solving each
    rung with ``solve_one(scene) -> BSDF``, until a rung meets ``tol``."""
    ladder = accuracy.Ladder(scene, tol, log)
    for rung in ladder.rungs():
        t0 = time.perf_counter()
        try:
            bsdf = solve_one(rung)
        except InfeasibleError as exc:
            ladder.refused(rung, exc)
            continue
        if ladder.solved(bsdf, time.perf_counter() - t0):
            return bsdf
    return ladder.not_met()


def _with_estimate(scene: Scene, solve_one, bsdf: BSDF) -> BSDF:
    """``bsdf`` (solved from ``scene``) with its error estimate from the companion solves
    of :func:`layersim.plan.accuracy.companion_scenes`, each solved by ``solve_one(scene)``."""
    t0 = time.perf_counter()
    companions = []
    for coarser in accuracy.companion_scenes(scene, bsdf.info):
        try:
            companions.append(solve_one(coarser))
        except InfeasibleError as exc:
            accuracy.companion_refused(coarser, exc, companions)
            break
    return accuracy.with_estimate(bsdf, companions, t0)


def _no_progress(phase: str, done: int, total: int, what: str) -> None:
    """The default ``progress`` of :func:`solve`: reports nothing."""


def _like_argument(like) -> BSDF | None:
    """``like`` of :func:`solve`: None, a BSDF, or the path of a saved one."""
    if like is None or isinstance(like, BSDF):
        return like
    if isinstance(like, (str, os.PathLike)):
        return BSDF.load(like)
    raise TypeError("like= takes a solved BSDF (from layersim.solve or BSDF.load) or the path "
                    f"of a saved one, whose discretisation to reuse, got {type(like).__name__}")


def _discretisation_of(like: BSDF, scene: Scene) -> Scene:
    """``scene`` on the discretisation (rule, n, md, ms) of the solved BSDF ``like``."""
    op = like.operators[0]
    return replace(scene, discretization=replace(
        scene.discretization, n=op.grid.n, md=op.m, quadrature=op.grid.rule,
        ms=like.info.get("ms", getattr(op, "ms", None)) or scene.discretization.ms))


class _Phases:
    """Progress reports and timings of the phases of a solve (``"projection"``: a step per
    layer operator built, ``"adding"``: a step per channel; see ``progress`` of
    :func:`solve`). ``seconds[phase]`` sums the time spent in its steps."""

    def __init__(self, progress, totals: dict):
        self.progress = progress
        self.totals = totals
        self.done = dict.fromkeys(totals, 0)
        self.seconds = dict.fromkeys(totals, 0.0)

    def start(self, phase: str) -> None:
        """Report that ``phase`` starts, before its first step."""
        self.progress(phase, 0, self.totals[phase], "")

    @contextlib.contextmanager
    def step(self, phase: str, what: str):
        """Time the block as a step of ``phase`` named ``what``, reported as it starts and
        after it ends (not when it raises)."""
        t0 = time.perf_counter()
        self.progress(phase, self.done[phase], self.totals[phase], what)
        yield
        self.seconds[phase] += time.perf_counter() - t0
        self.done[phase] += 1
        self.progress(phase, self.done[phase], self.totals[phase], what)


class _OperatorCache:
    """The layer operators of one solve, shared by the channels: keyed by ``(layer,
    eta_above)``, each is built once, for the first channel that uses it, and dropped when
    the last channel that uses it takes it (:meth:`take`), so that its adding can release its
    blocks as it goes.

    Parameters
    ----------
    keys : list of list
        Per channel, the keys of its layer operators, top to bottom.
    """

    def __init__(self, keys: list):
        self.keys = keys
        self.size = len({k for ks in keys for k in ks})
        self._ops: dict = {}

    def __contains__(self, key) -> bool:
        return key in self._ops

    def __setitem__(self, key, op) -> None:
        self._ops[key] = op

    def _later(self, c: int) -> set:
        return {k for ks in self.keys[c + 1:] for k in ks}

    def owned(self, c: int) -> list[bool]:
        """Per layer of channel ``c``: True if its operator is used by no later channel and
        nowhere else in this one, so that channel ``c``'s adding may consume it
        (``aniso_adding.add(consume=...)``)."""
        later = self._later(c)
        return [key not in later and self.keys[c].count(key) == 1 for key in self.keys[c]]

    def take(self, c: int) -> list:
        """The operators of channel ``c``, top to bottom; those that no later channel uses
        leave the cache."""
        ops = [self._ops[key] for key in self.keys[c]]
        for key in set(self.keys[c]) - self._later(c):
            del self._ops[key]
        return ops


def _solve(scene, like, threads, verbose, projection, device, progress) -> BSDF:
    t_start = time.perf_counter()
    if like is not None:
        scene = _discretisation_of(like, scene)
    plan = make_plan(scene)
    if verbose:
        print(plan.report())
    t_plan = time.perf_counter() - t_start
    if plan.representation == "specular-paths":
        return _solve_paths(scene, plan, t_start, t_plan, verbose)
    stats = AnisoProjectionStats() if plan.representation == "anisotropic" \
        else ProjectionStats()
    used = [lp for lp in plan.layers if lp.action != "left out"]
    # the scene as projected: a brushed top coat raised to the lowest floor of its
    # extrapolation (its operator combines the floors: layersim.layers.brushed), near-specular
    # inner interfaces raised below their reflection from above
    # (layersim.layers.near_specular_inner)
    projected = inner_projected(brushed_projected(scene, plan), plan)
    monos = [projected.channel(c) for c in range(scene.channels)]
    cache = _OperatorCache([[(m.layers[lp.index], m.ior_above(lp.index)) for lp in used]
                            for m in monos])
    memory.release()                # the plan's temporaries
    phases = _Phases(progress, {"projection": cache.size, "adding": scene.channels})
    phases.start("projection")
    notes: list[str] = []           # diagnostics of the solve, for info["notes"]
    project = lambda mono: functools.partial(_layer_operator, plan, plan.grid, mono,
                                             stats=stats, projection=projection,
                                             device=device, notes=notes)
    stacks = _channel_stacks(plan, used, monos, cache, project, phases, threads,
                             scene.top_ior)
    info = _info(scene, plan, projection, stats, stacks, notes,
                 {"plan": t_plan, "layers": phases.seconds["projection"],
                  "projection": stats.seconds, "adding": phases.seconds["adding"],
                  "total": time.perf_counter() - t_start})
    if verbose:
        s = info["seconds"]
        print(f"solved in {s['total']:.2f} s (plan {s['plan']:.2f} s, layers {s['layers']:.2f} s, "
              f"adding {s['adding']:.2f} s)")
    # the operators hold the radiance inside the smooth boundaries (layersim.solved.boundary)
    return BSDF(stacks, plan, info, boundary=plan.boundary,
                lobes=[_lobes(plan, mono) for mono in monos])


def _channel_stacks(plan: Plan, used: list, monos: list, cache: _OperatorCache, project,
                    phases: _Phases, threads, top_ior: float) -> list:
    """The solved stack of every one-channel scene of ``monos`` (as projected) on ``plan``:
    its layers (``used``) built with ``project(mono)(i, workspace=...)`` into ``cache`` and
    added."""
    stacks = []
    for c, mono in enumerate(monos):
        owned = cache.owned(c)
        # anisotropic operators that a coupled adding step will consume wait in the workspace
        # as their blocks are built (aniso_interface_operator(workspace=...))
        workspace = Workspace.for_bytes(plan.memory_bytes) \
            if plan.representation == "anisotropic" and len(used) > 1 else Workspace()
        _project_channel(c, used, cache, owned, project(mono), workspace, phases)
        with phases.step("adding", f"channel {c}" if len(monos) > 1 else ""):
            stacks.append(_add_channel(plan, used, cache.take(c), owned, threads, workspace,
                                       top_ior))
    return stacks


def _solve_paths(scene, plan, t_start: float, t_plan: float, verbose: bool):
    """The BSDF of a stack that the plan routes to specular paths
    (:class:`layersim.specular_paths.SpecularPathsBSDF`)."""
    bsdf = SpecularPathsBSDF(scene, plan, {"scene": scene.name, "notes": list(plan.notes)})
    bsdf.info["seconds"] = {"plan": t_plan, "total": time.perf_counter() - t_start}
    if verbose:
        print(f"solved in {bsdf.info['seconds']['total']:.2f} s (specular paths)")
    return bsdf


def _project_channel(c: int, used: list, cache: _OperatorCache, owned: list, project,
                     workspace: Workspace, phases: _Phases) -> None:
    """Build the operators of channel ``c``'s layers (``used``, their :class:`LayerPlan`)
    that are not in ``cache`` yet, with ``project(i, workspace=...)`` for layer ``i``; an
    operator its channel's adding consumes (``owned``) waits in ``workspace``."""
    # projected bottom up: the base of a coated stack is the smaller operator (one block
    # below an opaque interface), so the coating's projection, the larger transient, runs
    # beside it rather than the base's projection beside the larger coating
    for lp, key, own in reversed(list(zip(used, cache.keys[c], owned))):
        if key in cache:
            continue
        with phases.step("projection", f"layer {lp.index} ({lp.kind})"):
            with _singular_as_infeasible(f"layer {lp.index} ({lp.kind})",
                                         "change its parameters or n / md in "
                                         "[discretization]"):
                cache[key] = project(lp.index, workspace=workspace if own else None)
            memory.release()


def _add_channel(plan: Plan, used: list, ops: list, owned: list, threads, workspace,
                 top_ior: float):
    """The operator of one channel's stack: its layer operators ``ops`` (top to bottom, of the
    layers ``used``) added with the adding equations, the isotropic ones or the coupled-mode
    ones (:func:`_add_mixed`, which consumes the ``owned`` operators and empties ``ops``); no
    layers: the identity."""
    if not ops:
        return IsoOperator.identity(plan.grid, plan.md, top_ior)
    if plan.representation == "anisotropic":
        with _singular_as_infeasible("adding the layers (coupled modes)", _ADDING_ADVICE):
            return _add_mixed(ops, owned, threads, workspace)
    stack = ops[-1]
    for lp, op in reversed(list(zip(used[:-1], ops[:-1]))):
        with _singular_as_infeasible(f"adding layer {lp.index} ({lp.kind}) onto the "
                                     "layers below it", _ADDING_ADVICE):
            stack = adding.add(op, stack, threads)
    return stack


def _info(scene: Scene, plan: Plan, projection: str, stats, stacks: list, notes: list,
          seconds: dict) -> dict:
    """``BSDF.info`` of a solve: the scene, its discretisation, ``seconds`` per phase, the
    projection's statistics, size of the solved operators and the diagnostics ``notes``."""
    return {
        "scene": scene.name, "source": scene.source, "channels": scene.channels,
        "n": plan.n, "md": plan.md, "ms": plan.ms, "rule": plan.rule,
        "seconds": seconds,
        "projection": {"method": projection, "pairs": stats.pairs,
                       "projected": stats.projected, "refit": stats.refit,
                       "truncated": stats.truncated, "tapered": stats.tapered,
                       "aliased": stats.aliased},
        "representation": plan.representation,
        "nnz": sum(op.nnz() for op in stacks),
        "memory_bytes": sum(op.memory_bytes() for op in stacks),
        "notes": notes,
        # rough interfaces with a compensation term (layersim.compensation), JSON-stable
        "energy_compensation": [
            {"layer": i, "kind": layer.kind, "mode": layer.energy_compensation}
            for i, layer in enumerate(scene.channel(0).layers)
            if getattr(layer, "energy_compensation", "none") != "none" and not layer.smooth],
    }


def _add_mixed(ops, owned, threads, workspace=None):
    """Stack a list of isotropic and anisotropic operators (top to bottom): runs of isotropic
    operators are added with the cheaper isotropic equations, then the runs and the anisotropic
    operators with the coupled-mode ones (adding is associative). ``ops`` is emptied; the
    operators flagged in ``owned`` (referenced nowhere else) and the intermediate stacks are
    consumed by the adding steps, which release their blocks as soon as they are used and
    keep idle blocks and intermediate pieces in ``workspace``."""
    reduced = _reduce_isotropic_runs(ops, owned, threads)
    stack, own_stack = reduced.pop()
    while reduced:
        op, own = reduced.pop()
        consume = {(True, True): "both", (True, False): "top",
                   (False, True): "bottom"}.get((own, own_stack))
        stack = aniso_adding.add(op, stack, relerr=STACK_RELERR,
                                 relerr_intermediate=STACK_RELERR_INTERMEDIATE,
                                 consume=consume, workspace=workspace)
        own_stack = True
        del op
    return stack


def _reduce_isotropic_runs(ops, owned, threads) -> list:
    """``[(operator, owned), ...]`` for :func:`_add_mixed`: each run of consecutive isotropic
    operators added into one, marked not owned (the coupled adding converts an isotropic
    operand to a new operator: there is nothing of it to release), anisotropic ones passed
    through with their flag. ``ops`` is emptied, so that the returned list holds the only
    references (the locals of this function go with it)."""
    groups = []          # runs of isotropic operators (lists) and (anisotropic op, owned)
    for op, own in zip(ops, owned):
        if op.representation != "isotropic":
            groups.append((op, own))
        elif groups and isinstance(groups[-1], list):
            groups[-1].append(op)
        else:
            groups.append([op])
    ops.clear()
    reduced = []
    for g in groups:
        if isinstance(g, list):
            acc = g[-1]
            for op in reversed(g[:-1]):
                acc = adding.add(op, acc, threads)
            reduced.append((acc, False))
        else:
            reduced.append(g)
    return reduced


#: The adding equations of each representation (:func:`common_representation` of the operands).
_ADDERS = {"isotropic": adding.add,
           "anisotropic": lambda top, bottom, threads: aniso_adding.add(top, bottom)}


def add(top, bottom, threads: int | None = None):
    """Stack ``top`` on ``bottom`` with the adding equations.

    Both must be solved on the same discretisation (see ``solve(..., like=...)``) and
    ``top`` must be transmissive, ending in the medium that ``bottom`` starts in. Accepts
    :class:`BSDF` objects (per channel; a 1-channel operand is shared by all channels of the
    other) or two :class:`~layersim.operators.operator.Operator` objects (an isotropic one is
    converted when the other is coupled), and returns the same type.
    """
    if isinstance(top, Operator) and isinstance(bottom, Operator):
        return _ADDERS[common_representation(top, bottom)](top, bottom, threads)
    if not (isinstance(top, BSDF) and isinstance(bottom, BSDF)):
        raise TypeError("add() takes two BSDF objects (from layersim.solve) or two operators")
    refuse_boundary("add", top, bottom)
    pairs = channel_pairs(top, bottom, "cannot add a {a}-channel BSDF to a {b}-channel one")
    channels = len(pairs)
    ops = [add(a, b, threads) for a, b in pairs]
    info = {"scene": f"{top.info.get('scene', 'top')} + {bottom.info.get('scene', 'bottom')}",
            "channels": channels}
    return BSDF(ops, None, info)
