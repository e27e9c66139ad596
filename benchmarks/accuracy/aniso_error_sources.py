"""Which discretisation parameter leaves the error of an anisotropic (coupled-mode) solve.

Solves ``benchmarks/scenes/additive_validation.toml`` (Zeltner & Jakob 2018, sec. 5.5: a
dielectric of alpha (0.1, 0.2) over gold of alpha (0.2, 0.1)) on the planner's n and md with
the coupling half-width of the 1 % rule (Zeltner & Jakob 2018, eq. (25):
``layersim.aniso.plan.ms_one_percent``, the planner's ``ms`` less ``MS_MARGIN``; "default" below)
and with one parameter refined at a time:

* ``n`` (ordinates) x sqrt 2 and x 2, ``md`` (Fourier orders in the azimuth difference) x 2,
* ``ms`` (coupling half-width, modes -ms..ms of the azimuth sum) +1, +2, +4,
* the relative truncation of the coupled layer coefficients
  (``layersim.aniso.plan.COUPLED_RELERR``) and of the stack's operators (``STACK_RELERR``,
  ``STACK_RELERR_INTERMEDIATE``) 100 times tighter,
* ``theta_full`` (elevation within which pairs keep every order their lobes need) 89 degrees,

and prints, per variant, the relative L2 distance of its bin energies from the default's
(18 x 36 bins per side, ``layersim.plan.accuracy.bin_table``) at 0, 30, 60 and 80 degrees
incidence and the change of the albedo R. With ``--mc PATHS`` it adds a walk on Warp's CPU
device (``layersim.montecarlo``) at 0, 30 and 60 degrees and compares the albedos of the
default plan and of the solve at twice ``n`` with it, in the walk's standard errors.

Usage: python benchmarks/accuracy/aniso_error_sources.py [--mc PATHS]
Output of a run: benchmarks/accuracy/aniso_error_sources.txt.
"""

from __future__ import annotations

import contextlib
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import layersim
import layersim.aniso.plan as aplan
import layersim.montecarlo as mc
import layersim.solver as solver
from layersim.plan import accuracy

SCENE = Path(__file__).resolve().parents[1] / "scenes" / "additive_validation.toml"


@contextlib.contextmanager
def truncation(coupled: float, stack: tuple):
    """Tighter truncations of the coupled operators for the duration of a solve (the solver
    and the planner read these module constants at call time)."""
    saved = (aplan.COUPLED_RELERR, solver.COUPLED_RELERR, solver.STACK_RELERR,
             solver.STACK_RELERR_INTERMEDIATE)
    aplan.COUPLED_RELERR = solver.COUPLED_RELERR = coupled
    solver.STACK_RELERR, solver.STACK_RELERR_INTERMEDIATE = stack
    try:
        yield
    finally:
        (aplan.COUPLED_RELERR, solver.COUPLED_RELERR, solver.STACK_RELERR,
         solver.STACK_RELERR_INTERMEDIATE) = saved


def albedos(bsdf) -> np.ndarray:
    """R at the incidence angles of :data:`layersim.plan.accuracy.ANGLES`."""
    out = []
    for theta in np.radians(accuracy.ANGLES):
        wi = np.array([[math.sin(theta), 0.0, math.cos(theta)]])
        out.append(float(np.ravel(bsdf.albedo(wi)[0])[0]))
    return np.array(out)


def main() -> None:
    paths = int(float(sys.argv[2])) if sys.argv[1:2] == ["--mc"] else 0
    scene = layersim.Scene.from_toml(SCENE)
    plan = layersim.make_plan(scene)
    scene = replace(scene, discretization=replace(
        scene.discretization, n=plan.n, md=plan.md, ms=plan.ms - aplan.MS_MARGIN))
    base = layersim.solve(scene)
    n, md, ms = base.info["n"], base.info["md"], base.info["ms"]
    disc = scene.discretization

    def at(**kw):
        return replace(scene, discretization=replace(disc, **{"n": n, "md": md, "ms": ms, **kw}))

    n2 = 2 * int(round(n * math.sqrt(2.0) / 2.0))
    variants = [
        (f"n x sqrt2 = {n2}", at(n=n2), None), (f"n x 2 = {2 * n}", at(n=2 * n), None),
        (f"md x 2 = {2 * md}", at(md=2 * md), None),
        *[(f"ms {ms} -> {ms + k}", at(ms=ms + k), None) for k in (1, 2, 4)],
        ("COUPLED_RELERR / 100", at(), (aplan.COUPLED_RELERR / 100,
                                        (solver.STACK_RELERR, solver.STACK_RELERR_INTERMEDIATE))),
        ("STACK_RELERR(_INTERMEDIATE) / 100", at(),
         (aplan.COUPLED_RELERR, (solver.STACK_RELERR / 100,
                                 solver.STACK_RELERR_INTERMEDIATE / 100))),
        ("theta_full 89 (md from the planner)", at(theta_full=89.0, md=None), None),
    ]
    table0, r0 = accuracy.bin_table(base), albedos(base)
    angles = ", ".join(f"{a:g}" for a in accuracy.ANGLES)
    print(f"# additive_validation, default plan n = {n}, md = {md}, ms = {ms}; "
          f"R at {angles} deg: " + " ".join(f"{x:.6f}" for x in r0))
    print(f"# {'variant':34s} | relative L2 of bin energies vs default at {angles} deg "
          "| R - R_default | md  | seconds")
    by_n = {n: r0}
    for label, sc, trunc in variants:
        t0 = time.perf_counter()
        with truncation(*trunc) if trunc else contextlib.nullcontext():
            b = layersim.solve(sc)
        sec = time.perf_counter() - t0
        d = accuracy.relative_errors(accuracy.bin_table(b), table0)
        r = albedos(b)
        if label.startswith("n x"):
            by_n[b.info["n"]] = r
        print(f"{label:36s} | " + " ".join(f"{x:.1e}" for x in d) + " | "
              + " ".join(f"{x:+.1e}" for x in r - r0) + f" | {b.info['md']:4d} | {sec:6.1f}",
              flush=True)
    fine = by_n[max(by_n)]
    print(f"# n x 2 - default: R " + " ".join(f"{x:+.1e}" for x in fine - r0)
          + f"; n x 2 - n x sqrt2: R " + " ".join(f"{x:+.1e}" for x in fine - by_n[n2]))
    if paths:
        for k, theta in enumerate((0.0, 30.0, 60.0)):
            t = math.radians(theta)
            res = mc.simulate(scene, np.array([math.sin(t), 0.0, math.cos(t)]), paths,
                              backend="warp-cpu", seed=11 + k)
            rr = float(np.ravel(res.reflectance)[0])
            se = float(np.ravel(res.reflectance_stderr)[0])
            print(f"# walk, {paths:.0e} paths, {theta:2.0f} deg: R = {rr:.6f} +- {se:.1e}; "
                  f"default - walk = {(r0[k] - rr) / se:+.1f} se, n x 2 - walk = "
                  f"{(fine[k] - rr) / se:+.1f} se ({res.seconds:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
