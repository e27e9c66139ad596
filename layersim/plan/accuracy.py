"""How accurate a solved BSDF is: an a-posteriori error estimate, and solves to a tolerance.

The discretisation error of a solve (ordinates ``n``, Fourier orders ``md``) is estimated from
companion solves of the same scene on coarser discretisations, ``n`` and ``md`` over ``sqrt 2``
and over 2, the way an embedded pair estimates the error of an integrator: all are reduced to
bin energies (18 x 36 bins per side, at the incidence angles :data:`ANGLES`) and compared by
relative L2 distance, ``d1`` to the first companion and ``d2`` to the second. Where the error
falls like ``s^-p`` in the scale ``s`` of ``n`` and ``md``, ``d1`` is ``2^(p/2) - 1`` times the
error and ``d2 / d1 = 2^(p/2) + 1``. The estimate is :data:`SAFETY` x ``max(d1, d2 / 5)`` at the
worst incidence: ``d1`` carries it, and a ``d2`` more than 5 times ``d1`` (more than fourth-order
convergence, which the method does not show) marks an accidental agreement of the first
companion, where ``d2 / 5`` takes over (:data:`COMPANIONS` holds the weights).

The factor is measured, not derived: convergence is not monotone (a narrow lobe moves across
bin edges and between ordinates as ``n`` changes, and an incident direction between ordinates is
interpolated), so the ratio of the error to ``d1`` spreads over 0.2 ... 1.4 on the ladders of 18
scenes in ``benchmarks/accuracy/estimator_study.txt``. There the estimate lies above the error
(against a solve at twice ``n`` and ``md``) in 41 of 42 cases, the exception a solve whose error
grew with ``n``; ``d1`` alone misses twice as often, and Richardson-type weightings miss more. No
estimate made from coarser solves follows the error within a constant factor while the error
itself jumps between neighbouring discretisations: the estimate is within 3 times the error in
about 60 % of the cases. The estimate per angle (``per_angle``) is less reliable than the
worst-angle value (about 90 % conservative).

A solve to a tolerance (:class:`Ladder`) climbs a ladder of scales of the planner's
``n`` and ``md`` (:data:`LADDER`, a factor ``sqrt 2`` apart, so that the two rungs below are
each rung's companions) and stops at the first rung from the second on whose estimate is at
most ``tol`` (on the second, with one companion, :data:`SINGLE` times its distance); a rung the
memory or time limits refuse ends the ladder with a refusal that says the best estimate reached
and at which incidence angles it meets ``tol``.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np

from ..errors import InfeasibleError
from . import make_plan
from ..scene import Scene

#: Incidence angles (degrees) at which the estimate compares bin energies; the estimate is the
#: worst of them.
ANGLES = (0.0, 30.0, 60.0, 80.0)

#: Bins in the cosine of the elevation and in the azimuth, per side.
BINS = (18, 36)

#: Scales of the companion solves' ``n`` and ``md`` relative to the estimated solve's, and the
#: weight of the distance to each (module docstring).
COMPANIONS = ((1.0 / math.sqrt(2.0), 1.0), (0.5, 0.2))

#: Estimate = SAFETY x the largest weighted distance to a companion (module docstring).
SAFETY = 1.5

#: Factor on an estimate that rests on the first companion alone (the second too coarse to
#: solve, or the second rung of a ladder).
SINGLE = 2.0

#: Scales of the planner's ``n`` and ``md`` that a solve to a tolerance climbs; a rung is
#: accepted from the second solved on.
LADDER = tuple(0.25 * 2.0 ** (k / 2.0) for k in range(1, 10))


def bin_table(bsdf, angles=ANGLES, bins=BINS) -> np.ndarray:
    """Bin energies of ``bsdf`` for beams from ``angles`` (degrees, azimuth 0): an array
    (angles, 2 sides, channels, bins[0], bins[1])."""
    mu_edges = np.linspace(0.0, 1.0, bins[0] + 1)
    phi_edges = np.linspace(0.0, 2.0 * np.pi, bins[1] + 1)
    out = []
    for theta in np.radians(angles):
        wi = np.array([math.sin(theta), 0.0, math.cos(theta)])
        e = bsdf.bin_energies(wi, mu_edges, phi_edges)
        sides = [np.moveaxis(np.asarray(e[side]).reshape(*bins, -1), -1, 0)
                 for side in ("top", "bottom")]
        out.append(np.stack(sides))
    return np.array(out)


def relative_errors(table: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Relative L2 distance of bin energies per incidence angle (first axis):
    ``sqrt(sum (E - E_ref)^2 / sum E_ref^2)`` over sides, channels and bins."""
    axes = tuple(range(1, table.ndim))
    den = np.sum(reference ** 2, axis=axes)
    num = np.sum((table - reference) ** 2, axis=axes)
    return np.sqrt(num / np.where(den > 0, den, 1.0))


def scaled(scene: Scene, n: int, md: int, scale: float, ms: int | None = None) -> Scene:
    """``scene`` with ``n`` and ``md`` set to ``scale`` times the given ones (``n`` even, at
    least 8; ``md`` at least 1), and for an anisotropic solve (``ms`` > 0) its coupling
    half-width to :func:`scaled_ms` of it.

    The truncation of the coupled modes at the planner's ``ms`` dominates the error of
    anisotropic stacks (``benchmarks/accuracy/aniso_error_sources.txt``): a companion on the same
    ``ms`` cannot see it, and a rung of the ladder on the same ``ms`` cannot reduce it.
    ``ms`` = 0 or None (isotropic) leaves the scene's ``ms`` as it is."""
    n = max(8, 2 * int(round(n * scale / 2.0)))
    md = max(1, int(round(md * scale)))
    disc = replace(scene.discretization, n=n, md=md, tol=None)
    if ms:
        disc = replace(disc, ms=scaled_ms(ms, scale))
    return replace(scene, discretization=disc)


def scaled_ms(ms: int, scale: float) -> int:
    """The coupling half-width of a companion or rung at ``scale``: ``ms sqrt(scale)``,
    rounded, at least 1.

    The relative L2 error of keeping ``|s| <= m`` falls like ``exp(-K m / ms)`` near the
    planner's ``ms`` (Zeltner & Jakob 2018, eq. (25) plus ``layersim.aniso.plan.MS_MARGIN``),
    with ``K`` = 5.4-6.8 for roughness ratios 2-6 (``benchmarks/accuracy/aniso_ms_decay.txt``).
    Scaling ``m`` by ``sqrt(scale)`` then multiplies that error by ``exp(K (1 - sqrt(scale)))``:
    2-3 at ``scale = 1/sqrt 2`` and 5-7 at ``1/2``, near what scaling ``n`` and ``md`` does to an
    error falling like ``n^-2``, which the weights of :data:`COMPANIONS` assume."""
    return max(1, int(round(ms * math.sqrt(scale))))


def estimate(bsdf, companions: list, tables: list | None = None) -> dict:
    """The error estimate of ``bsdf`` from its coarser ``companions`` (same scene, at the
    scales of :data:`COMPANIONS`, in that order; the last may be missing).

    ``tables`` (optional) are the :func:`bin_table` of ``bsdf`` followed by those of the
    companions, where the caller has them already.

    Returns
    -------
    dict
        ``estimate`` (relative L2 error of bin energies, worst incidence), ``per_angle`` (the
        same per angle of :data:`ANGLES`), ``angles``, ``bins``, ``safety`` and the companions'
        ``n`` and ``md``.
    """
    if tables is None:
        tables = [bin_table(b) for b in (bsdf, *companions)]
    per_angle = estimate_from_distances(
        [relative_errors(tables[0], table) for table in tables[1:1 + len(companions)]])
    return {"estimate": float(per_angle.max()), "per_angle": [float(x) for x in per_angle],
            "angles": list(ANGLES), "bins": list(BINS), "safety": SAFETY,
            "companions": [{"n": c.info.get("n"), "md": c.info.get("md")} for c in companions]}


def estimate_from_distances(distances: list) -> np.ndarray:
    """The estimate from the distances of a solve to its companions (relative L2 of bin
    energies; arrays over the incidence angles), in the order of :data:`COMPANIONS` (the
    second may be missing): :data:`SAFETY` x the largest weighted distance, :data:`SINGLE`
    times more with one companion (an accidental agreement cannot be told then)."""
    alone = SINGLE if len(distances) == 1 else 1.0
    out = np.zeros(np.shape(distances[0]))
    for (_, weight), d in zip(COMPANIONS, distances):
        out = np.maximum(out, SAFETY * alone * weight * np.asarray(d))
    return out


def meeting(acc: dict, tol: float) -> str:
    """Which incidence angles of ``acc`` (:func:`estimate`) have an estimate within ``tol``,
    as text for a message."""
    ok = [f"{a:g}" for a, e in zip(acc["angles"], acc["per_angle"]) if e <= tol]
    over = ", ".join(f"{e:.2g} at {a:g} deg" for a, e in zip(acc["angles"], acc["per_angle"])
                     if e > tol)
    return f"within tol at {', '.join(ok)} deg; {over}" if ok else "over tol at every angle"


def companion_scenes(scene: Scene, info: dict) -> list:
    """The companions of a solve of ``scene`` whose ``BSDF.info`` is ``info``: ``scene`` at
    the scales of :data:`COMPANIONS` of its ``n``, ``md`` (and ``ms``), to be solved in this
    order; the first refused ends the list (:func:`companion_refused`)."""
    return [scaled(scene, info["n"], info["md"], ratio, info.get("ms"))
            for ratio, _ in COMPANIONS]


def companion_refused(coarser: Scene, exc: InfeasibleError, solved: list) -> None:
    """A companion solve of ``coarser`` was refused with ``exc``: too coarse to resolve a
    lobe. With companions ``solved`` before it the estimate rests on them (returns);
    without, there is no estimate (raises :class:`InfeasibleError`)."""
    if not solved:
        raise InfeasibleError(
            f"no error estimate: the companion solve at n = {coarser.discretization.n} is "
            f"refused ({exc}); estimate a solve with a larger n") from None


def with_estimate(bsdf, companions: list, started: float):
    """``bsdf`` with its error estimate from its solved ``companions`` (in the order of
    :func:`companion_scenes`) in ``bsdf.info["accuracy"]``, which also records the seconds
    taken since ``started`` (the :func:`time.perf_counter` at which the companion solves
    began) up to the estimate made."""
    bsdf.info["accuracy"] = {**estimate(bsdf, companions),
                             "seconds": time.perf_counter() - started}
    return bsdf


class Ladder:
    """A solve to a tolerance: the rungs of :data:`LADDER` to solve, smallest first, until
    one's error estimate is at most ``tol`` (relative L2 of bin energies, worst incidence).

    The caller solves each scene that :meth:`rungs` yields and reports the result:
    :meth:`solved` with the BSDF (True: ``tol`` is met, the BSDF is the answer) or
    :meth:`refused` with the solver's :class:`InfeasibleError`; after the last rung,
    :meth:`not_met` raises.

    Parameters
    ----------
    scene : Scene
    tol : float
        Requested relative error, in (0, 1).
    log : callable, optional
        ``log(str)`` for a line per rung.

    Raises
    ------
    ValueError
        For a ``tol`` outside (0, 1).
    """

    def __init__(self, scene: Scene, tol: float, log=None):
        if not (isinstance(tol, (int, float)) and 0.0 < tol < 1.0):
            raise ValueError(f"tol must be a number in (0, 1), got {tol!r}")
        self.scene, self.tol, self.log = scene, tol, log
        self.plan = make_plan(scene, refuse=False)
        #: ``n``, ``md``, seconds and estimate of each rung solved (``info["accuracy"]``)
        self.steps = []
        # the last rungs solved and their bin tables (each rung is the companion of the next
        # two), and the best (bsdf, estimate) so far
        self._solved, self._tables, self._best = [], [], None
        self._scale = None

    def rungs(self):
        """The scenes of the rungs, smallest first (a generator)."""
        for scale in LADDER:
            self._scale = scale
            yield scaled(self.scene, self.plan.n, self.plan.md, scale, self.plan.ms)

    def solved(self, bsdf, seconds: float) -> bool:
        """Record the solve of the current rung (``seconds`` of wall time); True, with
        ``bsdf.info["accuracy"]`` (:func:`estimate`, plus ``tol``, ``met`` and ``ladder``:
        the rungs solved), where its estimate meets ``tol``."""
        step = {"n": bsdf.info["n"], "md": bsdf.info["md"], "seconds": seconds,
                "estimate": None}
        self.steps.append(step)
        self._solved.append(bsdf)
        self._tables.append(bin_table(bsdf))
        if len(self._solved) < 2:
            return False
        acc = estimate(bsdf, self._solved[-2::-1], self._tables[::-1])
        step["estimate"] = acc["estimate"]
        if self.log is not None:
            self.log(f"n = {step['n']}, md = {step['md']}: estimated error "
                     f"{acc['estimate']:.2g} ({step['seconds']:.2f} s)")
        if self._best is None or acc["estimate"] < self._best[1]["estimate"]:
            self._best = (bsdf, acc)
        if acc["estimate"] <= self.tol:
            bsdf.info["accuracy"] = {**acc, "tol": self.tol, "met": True, "ladder": self.steps}
            return True
        del self._solved[:-2], self._tables[:-2]
        return False

    def refused(self, rung: Scene, exc: InfeasibleError) -> None:
        """The solve of the current rung ``rung`` was refused with ``exc``: before any rung
        is solved a rung too coarse for a lobe is skipped (returns); otherwise the ladder
        ends with ``exc`` or, past the second rung, with the best estimate reached."""
        if not self._solved:  # too coarse for a lobe (or over the limits: the last rung says)
            if self._scale == LADDER[-1]:
                raise exc
            return
        if self._best is None:
            raise exc
        best, acc = self._best
        raise InfeasibleError(
            f"tol = {self.tol:g} not reached: the best estimate is {acc['estimate']:.2g} at "
            f"n = {best.info['n']}, md = {best.info['md']} ({meeting(acc, self.tol)}); the "
            f"next rung (n = {rung.discretization.n}, md = {rung.discretization.md}) is "
            f"refused: {exc}; raise LAYERSIM_MAX_MEMORY / LAYERSIM_MAX_SECONDS or ask for a "
            "larger tol") from None

    def not_met(self):
        """Raise :class:`InfeasibleError` after the last rung: ``tol`` is not reached, with
        the best estimate and its discretisation."""
        bsdf, acc = self._best
        raise InfeasibleError(
            f"tol = {self.tol:g} not reached within {LADDER[-1]:.2g} times the planned n and "
            f"md: the best estimate is {acc['estimate']:.2g} at n = {bsdf.info['n']}, md = "
            f"{bsdf.info['md']} ({meeting(acc, self.tol)}); ask for a larger tol, or set n "
            "and md in [discretization]")
