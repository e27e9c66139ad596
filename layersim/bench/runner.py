"""Solver and Monte Carlo side by side: error against run time on a scene suite.

For each scene and a few incidence angles:

* a **reference**: the solver on a finer discretisation (``reference_scale`` times the planner's
  ordinates and orders), checked against a long Monte Carlo run (fraction of bins within 3
  standard errors, albedo differences in standard errors); where the solver refuses the scene,
  the long Monte Carlo run is the reference;
* the **solver** at a ladder of discretisations (``scales`` times the planner's n and md) with
  wall time and error against the reference;
* **Monte Carlo** at a ladder of particle counts per backend, with wall time, error and standard
  error;
* with ``render``, the rendered comparison of the planner's solve and the walk
  (:mod:`.rendercompare`).

Error metrics, over the bin energies E_b of both sides and all incidence angles:
``error`` = relative L2 = sqrt(sum (E - E_ref)^2 / sum E_ref^2); ``albedo_error`` =
max |R - R_ref| + |T - T_ref|; ``within_3sigma`` = fraction of populated bins with
|E - E_ref| <= 3 sigma (Monte Carlo rows, sigma its per-bin standard error).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..plan import accuracy
from ..errors import LayersimError
from ..plan import make_plan
from ..scene import Scene
from ..solver import solve
from . import rendercompare
from .statistical import statistical_row


#: Monte Carlo paths per incidence angle of the rendered comparison of ``--quick``.
QUICK_RENDER_PARTICLES = 200_000


@dataclass
class Settings:
    angles: tuple = (0.0, 30.0, 60.0)
    n_mu: int = 18
    n_phi: int = 36
    scales: tuple = (0.5, 0.75, 1.0, 1.5)
    tols: tuple = (1e-2, 1e-3, 1e-4)
    reference_scale: float = 2.0
    particles: tuple = (10_000, 100_000, 1_000_000, 10_000_000)
    check_particles: int = 10_000_000
    backends: tuple = ("auto",)
    seed: int = 1
    # the rendered comparison (layersim.bench.rendercompare), off unless asked for
    render: bool = False
    render_angles: int = 16
    render_bins: tuple = (18, 36)
    render_particles: int = 1_000_000
    render_resolution: int = 96
    render_spp: int = 64

    @classmethod
    def quick(cls) -> "Settings":
        """The small version of ``layersim bench --quick``, designed so that each method's
        error falls from its cheapest to its most expensive run:

        * the three incidence angles of the full run: at one angle between ordinates the
          solver's error oscillates with n for sharp lobes (the incident elevation is
          interpolated between ordinates; coated gold at 30 degrees: 9.5e-5 at n = 98,
          1.1e-3 at n = 118, 3.8e-4 at n = 196 against a solve at 3x), so a cheap rung can
          land on a lucky n; over 0, 30 and 60 degrees the errors at 0.5x and 1x the
          planner's n differ by 3.8x or more on the quick scenes;
        * a reference 2x finer than the finest rung, whose own error stays well below that
          rung's (at 1.5x it was comparable);
        * Monte Carlo from 1e4 to 1e6 paths: the noise falls by 10x from the cheapest to
          the most expensive run, while at 1e4 and 1e5 alone (3.2x expected) dusty gold's
          error, carried by a few bins of its sharp peak, fell by only 1.8x for one of ten
          seeds.
        """
        return cls(angles=(0.0, 30.0, 60.0), n_mu=9, n_phi=18, scales=(0.5, 1.0),
                   tols=(1e-2,), reference_scale=2.0,
                   particles=(10_000, 100_000, 1_000_000), check_particles=200_000,
                   render_particles=QUICK_RENDER_PARTICLES, render_spp=32)

    @property
    def mu_edges(self) -> np.ndarray:
        return np.linspace(0.0, 1.0, self.n_mu + 1)

    @property
    def phi_edges(self) -> np.ndarray:
        return np.linspace(0.0, 2.0 * np.pi, self.n_phi + 1)


def direction(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    th, ph = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)])


def montecarlo_module():
    """``layersim.montecarlo`` if installed, else None."""
    try:            # optional: the Monte Carlo reference is a separate install
        from .. import montecarlo
    except ImportError:
        return None
    return montecarlo


def _solver_bins(bsdf, s: Settings) -> tuple[np.ndarray, np.ndarray]:
    """Bin energies (angles, side, channel, mu, phi) and albedos (angles, 2, channel)."""
    bins, alb = [], []
    for theta in s.angles:
        wi = direction(theta)
        e = bsdf.bin_energies(wi, s.mu_edges, s.phi_edges)
        R, T = bsdf.albedo(wi)
        stack = lambda x: np.atleast_3d(np.asarray(x)).reshape(s.n_mu, s.n_phi, -1)
        bins.append(np.stack([np.moveaxis(stack(e["top"]), -1, 0),
                              np.moveaxis(stack(e["bottom"]), -1, 0)]))
        alb.append(np.stack([np.atleast_1d(R), np.atleast_1d(T)]))
    return np.array(bins), np.array(alb)


def _mc_bins(mc, scene, s: Settings, particles: int, backend: str):
    bins, errs, alb, alb_err = [], [], [], []
    t0 = time.perf_counter()
    for k, theta in enumerate(s.angles):
        res = mc.simulate(scene, direction(theta), particles, mu_edges=s.mu_edges,
                          phi_edges=s.phi_edges, backend=backend, seed=s.seed + k)
        shape = lambda x: np.moveaxis(np.asarray(x).reshape(s.n_mu, s.n_phi, -1), -1, 0)
        bins.append(np.stack([shape(res.bins["top"]), shape(res.bins["bottom"])]))
        errs.append(np.stack([shape(res.bins_stderr["top"]), shape(res.bins_stderr["bottom"])]))
        alb.append(np.stack([np.atleast_1d(res.reflectance), np.atleast_1d(res.transmittance)]))
        alb_err.append(np.stack([np.atleast_1d(res.reflectance_stderr),
                                 np.atleast_1d(res.transmittance_stderr)]))
        used = getattr(res, "backend", backend)
    return (np.array(bins), np.array(errs), np.array(alb), np.array(alb_err),
            time.perf_counter() - t0, used)


def _error(bins, ref) -> float:
    den = float(np.sum(ref ** 2))
    return float(np.sqrt(np.sum((bins - ref) ** 2) / den)) if den > 0 else float("nan")


def _albedo_error(alb, ref) -> float:
    return float(np.max(np.sum(np.abs(alb - ref), axis=1)))


def _within(bins, ref, sigma, particles, k=3.0) -> float:
    """Fraction of populated bins where the Monte Carlo estimate lies within k standard errors.
    A (nearly) empty Monte Carlo bin has a tiny sample standard error; its real spread is
    Poisson, variance >= E / N for a bin receiving energy E per path, so that floor is added."""
    populated = (ref > 0) | (bins > 0)
    if not populated.any():
        return float("nan")
    sigma = np.sqrt(sigma ** 2 + np.maximum(ref, 0.0) / particles)
    ok = np.abs(bins - ref) <= k * sigma + 1e-15
    return float(np.mean(ok[populated]))


def _tolerance_row(scene: Scene, tol: float, s: Settings, ref_bins, ref_alb, log) -> dict:
    """A solve to ``tol`` (:mod:`layersim.plan.accuracy`): its discretisation, time, estimate and
    error against the reference (which a rung at or above the reference's scale can reach)."""
    try:
        t0 = time.perf_counter()
        b = solve(scene, tol=tol)
        sec = time.perf_counter() - t0
    except LayersimError as exc:
        log(f"  solver tol {tol:g}: {exc}")
        return {"tol": tol, "refused": str(exc)}
    bins, alb = _solver_bins(b, s)
    row = {"tol": tol, "n": b.info["n"], "md": b.info["md"], "seconds": sec,
           "estimate": b.error_estimate, "error": _error(bins, ref_bins),
           "albedo_error": _albedo_error(alb, ref_alb)}
    log(f"  solver tol {tol:g}: n={row['n']} md={row['md']} {sec:7.2f} s  estimate "
        f"{row['estimate']:.2e}  error {row['error']:.2e}")
    return row


def run_scene(path: Path, s: Settings, log=print) -> dict:
    """Benchmark one scene file; returns the ``scenes[]`` entry of results.json."""
    scene = Scene.from_toml(path)
    out = {"name": scene.name, "file": str(path), "angles": list(s.angles), "solver": [],
           "montecarlo": []}
    mc = montecarlo_module()
    log(f"[{scene.name}]")
    plan, ref_bins, ref_alb = _solver_reference(scene, s, out, log)
    if mc is not None:
        ref_bins, ref_alb = _montecarlo_check(mc, scene, s, out, ref_bins, ref_alb, log)
    elif ref_bins is None:
        out["reference"]["note"] = "no Monte Carlo backend installed: no reference"
        return out
    out["_ref"] = (ref_bins, ref_alb)
    if plan is not None:
        _solver_ladder(scene, plan, s, out, ref_bins, ref_alb, log)
        out["tolerance"] = [_tolerance_row(scene, tol, s, ref_bins, ref_alb, log)
                            for tol in s.tols]
    if mc is not None:
        _montecarlo_ladder(mc, scene, s, out, ref_bins, ref_alb, log)
    if s.render:
        _render(scene, mc, s, out, log)
    # the statistical model: a third method, where it represents the scene
    out["statistical"] = statistical_row(scene, s, ref_bins, ref_alb, _solver_bins, _error,
                                         _albedo_error)
    if "error" in out["statistical"]:
        log(f"  statistical model: {out['statistical']['seconds']:.3f} s  error "
            f"{out['statistical']['error']:.2e}")
    return out


def _solver_reference(scene: Scene, s: Settings, out: dict, log):
    """The reference solve, ``s.reference_scale`` times the planner's discretisation:
    ``(plan, bins, albedos)`` (:func:`_solver_bins`), recorded in ``out["reference"]``; where
    the solver refuses the scene, ``(None, None, None)`` and the refusal recorded."""
    try:
        plan = make_plan(scene)
        t0 = time.perf_counter()
        # the coupled modes' ms grows too: its truncation is the larger error of anisotropic
        # stacks (layersim.plan.accuracy.scaled)
        ref = solve(accuracy.scaled(scene, plan.n, plan.md, s.reference_scale, plan.ms))
        ref_bins, ref_alb = _solver_bins(ref, s)
        out["reference"] = {"kind": "solver", "n": ref.info["n"], "md": ref.info["md"],
                            "seconds": time.perf_counter() - t0}
        log(f"  reference: solver n={ref.info['n']} md={ref.info['md']}")
    except LayersimError as exc:
        out["reference"] = {"kind": "montecarlo", "solver_refused": str(exc)}
        log(f"  solver refused: {exc}")
        return None, None, None
    return plan, ref_bins, ref_alb


def _montecarlo_check(mc, scene: Scene, s: Settings, out: dict, ref_bins, ref_alb, log):
    """A long Monte Carlo run (``s.check_particles``): the check of a solver reference
    (``out["reference"]["montecarlo_check"]``), or the reference itself where the solver
    refused (``ref_bins`` None). Returns the reference's bins and albedos."""
    try:
        b, e, a, ae, sec, used = _mc_bins(mc, scene, s, s.check_particles, s.backends[0])
    except LayersimError as exc:
        out["reference"]["montecarlo_refused"] = str(exc)
        return ref_bins, ref_alb
    check = {"particles": s.check_particles, "backend": used, "seconds": sec}
    if ref_bins is None:
        out["reference"].update(check)
        return b, a
    check["within_3sigma"] = _within(b, ref_bins, e, s.check_particles)
    check["albedo_sigma"] = float(np.max(np.abs(ref_alb - a) / np.maximum(ae, 1e-15)))
    out["reference"]["montecarlo_check"] = check
    log(f"  reference vs {s.check_particles:.0e} paths: "
        f"{100 * check['within_3sigma']:.1f}% of bins within 3 sigma, albedo "
        f"within {check['albedo_sigma']:.1f} sigma")
    return ref_bins, ref_alb


def _solver_ladder(scene: Scene, plan, s: Settings, out: dict, ref_bins, ref_alb,
                   log) -> None:
    """Solves at ``s.scales`` times the planner's discretisation, timed and compared with the
    reference: rows of ``out["solver"]``, bins in ``out["_solver_bins"]``."""
    for scale in s.scales:
        sc = accuracy.scaled(scene, plan.n, plan.md, scale, plan.ms)
        try:
            t0 = time.perf_counter()
            b = solve(sc)
            sec = time.perf_counter() - t0
        except LayersimError as exc:
            out["solver"].append({"scale": scale, "refused": str(exc)})
            continue
        bins, alb = _solver_bins(b, s)
        row = {"scale": scale, "n": b.info["n"], "md": b.info["md"], "ms": b.info.get("ms", 0),
               "seconds": sec, "error": _error(bins, ref_bins),
               "albedo_error": _albedo_error(alb, ref_alb)}
        out["solver"].append(row)
        out.setdefault("_solver_bins", {})[scale] = bins
        if scale == 1.0:
            out["_bsdf"] = b                 # the planner's solve, rendered by --render
        log(f"  solver n={row['n']:4d} md={row['md']:5d}: {sec:7.2f} s  error {row['error']:.2e}")


def _montecarlo_ladder(mc, scene: Scene, s: Settings, out: dict, ref_bins, ref_alb,
                       log) -> None:
    """Monte Carlo runs at ``s.particles`` per backend, timed and compared with the
    reference: rows of ``out["montecarlo"]`` (a backend's first refusal ends its ladder),
    the last run's bins in ``out["_mc_bins"]``."""
    for backend in s.backends:
        for particles in s.particles:
            try:
                b, e, a, ae, sec, used = _mc_bins(mc, scene, s, particles, backend)
            except LayersimError as exc:
                out["montecarlo"].append({"backend": backend, "particles": particles,
                                          "refused": str(exc)})
                break
            row = {"backend": used, "particles": particles, "seconds": sec,
                   "paths_per_second": particles * len(s.angles) / max(sec, 1e-9),
                   "error": _error(b, ref_bins), "albedo_error": _albedo_error(a, ref_alb),
                   "stderr": float(np.sqrt(np.sum(e ** 2) / np.sum(ref_bins ** 2))),
                   "within_3sigma": _within(b, ref_bins, e, particles)}
            out["montecarlo"].append(row)
            out["_mc_bins"] = b
            log(f"  MC {used} {particles:.0e}: {sec:7.2f} s  error {row['error']:.2e} "
                f"(stderr {row['stderr']:.1e}, {100 * row['within_3sigma']:.0f}% in 3 sigma)")


def _render(scene: Scene, mc, s: Settings, out: dict, log) -> None:
    """The rendered comparison (:mod:`.rendercompare`) of the solve at the planner's
    discretisation: ``out["render"]`` (results.json) and ``out["_render_images"]``."""
    bsdf = out.get("_bsdf")
    if bsdf is None:
        try:
            bsdf = solve(scene)
        except LayersimError as exc:
            out["render"] = {"skipped": f"the solver refused the scene: {exc}"}
            return
    out["render"], out["_render_images"] = rendercompare.run(scene, bsdf, mc, s, direction,
                                                             log)
