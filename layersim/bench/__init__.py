"""Benchmark reports: solver and Monte Carlo side by side (:mod:`.runner`), and the stability
suite of stiff and extreme cases (:mod:`.stability`), written by :mod:`.report`. Driven by
``layersim bench``."""

from __future__ import annotations

import sys
from pathlib import Path

from ..config import settings as layersim_settings
from ..errors import InfeasibleError
from ..kernels.runtime import device_for
from . import report, runner, stability as stab

#: Scenes of the quick run (isotropic, solved in seconds).
QUICK_SCENES = ("vandehulst_slab", "coated_gold", "dusty_gold")


def default_scene_dir() -> Path:
    """``benchmarks/scenes`` of the source tree this package runs from."""
    return Path(__file__).resolve().parents[2] / "benchmarks" / "scenes"


def run(out, quick: bool = False, stability: bool = False, backends=("auto",),
        scene_dir=None, scenes=None, command: str | None = None, log=print,
        seed: int = 1, render: bool = False, render_particles: int | None = None) -> dict:
    """Run the benchmark and write ``out/results.json``, ``out/report.md`` and PNG plots.

    Parameters
    ----------
    out : path
        Output folder (created).
    quick : bool
        Small version (three isotropic scenes, coarse bins, two rungs per method:
        :meth:`runner.Settings.quick`): under two minutes on a 2-core CPU.
    stability : bool
        Also run the stability suite.
    backends : sequence of str
        Monte Carlo backends to time (``"auto"`` picks the fastest present).
    scene_dir : path, optional
        Folder of ``*.toml`` scenes (default :func:`default_scene_dir`).
    scenes : sequence of str, optional
        Scene names (file stems) to run (default: all, or :data:`QUICK_SCENES` when quick).
    seed : int
        Seed of the Monte Carlo runs (incidence angle ``k`` uses ``seed + k``).
    render : bool
        Also render each isotropic scene from the solver's and the walk's bin energies, with
        their difference and a Mitsuba 3 render (:mod:`.rendercompare`): ``SCENE_render.png``.
    render_particles : int, optional
        Monte Carlo paths per incidence angle of the render (default
        :attr:`runner.Settings.render_particles`, or :data:`runner.QUICK_RENDER_PARTICLES`
        when quick).
    """
    if layersim_settings().device != "cpu":
        # an unusable device is refused here: the runner takes a refused solve for the
        # scene's and goes on with Monte Carlo alone
        device_for()
    scene_dir = Path(scene_dir) if scene_dir else default_scene_dir()
    files = sorted(scene_dir.glob("*.toml"))
    if not files:
        raise InfeasibleError(f"no scene files in {scene_dir}; pass --scenes DIR")
    wanted = scenes or (QUICK_SCENES if quick else None)
    if wanted:
        missing = set(wanted) - {f.stem for f in files}
        if missing:
            raise InfeasibleError(f"scene(s) {', '.join(sorted(missing))} not found in "
                                  f"{scene_dir}")
        files = [f for f in files if f.stem in wanted]
    settings = runner.Settings.quick() if quick else runner.Settings()
    settings.backends = tuple(backends)
    settings.seed = seed
    settings.render = render
    if render_particles is not None:
        settings.render_particles = render_particles
    machine = report.machine_info(command or " ".join(["layersim"] + sys.argv[1:]))
    results_scenes = []
    for f in files:
        results_scenes.append(runner.run_scene(f, settings, log=log))
        # rewrite the report after every scene, so that an interrupted run leaves its results
        report.write(Path(out), machine, results_scenes, [], settings)
    results_stability = []
    if stability:
        mc = runner.montecarlo_module()
        check = None
        if mc is not None:
            def check(scene, wi, particles, _mc=mc, _backend=backends[0]):
                return _mc.simulate(scene, wi, particles // (10 if quick else 1),
                                    mu_edges=[0.0, 1.0], phi_edges=[0.0, 6.283185307179586],
                                    backend=_backend, seed=7)
        for case in stab.cases():
            if quick and case.name == "near_specular_0.005":
                continue
            r = stab.run_case(case, mc=check)
            log(f"  stability {r['name']:28s} {r['outcome']:8s} {r['detail'][:100]}")
            results_stability.append(r)
            report.write(Path(out), machine, results_scenes, results_stability, settings)
    return report.write(Path(out), machine, results_scenes, results_stability, settings)
