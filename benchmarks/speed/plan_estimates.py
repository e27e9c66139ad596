"""The plan's memory and time estimates against the measured peak memory and time.

Every case is solved in a fresh process (``resource.getrusage`` peak RSS is per process): numpy,
SciPy, Warp and layersim are imported, glibc's arenas capped as the command line does, Warp's
kernels warmed up by a small solve, and the baseline peak RSS read; then the plan is made
(``layersim.make_plan``; the limits are lifted so that every plan is solved) and the scene
solved. Printed per case: the discretisation; the plan's memory estimate
(``Plan.memory_bytes``) beside the peak RSS above the baseline; the time estimate
(``Plan.seconds["total"]``) beside the CPU time (user + system, all threads) and the wall
time of the solve; their ratios (estimate / measured; the target is 1/1.5 .. 1.5); and the
estimate of each part of the time model (projection, media, adding) beside the CPU time of
the solver's layer operators and adding steps. A solve shorter than :data:`REPEAT_BELOW`
seconds is repeated in the same process and the run with the shortest wall time kept. The
machine may be shared: the load averages before each case are printed, and the time model is
fitted to the CPU time, which other jobs inflate less than the wall time (on an idle 2-core
machine the wall time is at most the CPU time: the projection and the coupled adding's
products and substitutions run on both cores, the rest on one).

Cases: the bench scenes (``benchmarks/scenes/*.toml``), a car paint (a coat over an RGB
medium over RGB aluminium) and its first channel alone, the RGB and anisotropic examples, an
RGB anisotropic paint, media-dominated and interface-dominated stacks, four rows of Table 2
of Zeltner & Jakob 2018 (coupled modes), and coated gold at 1.41 and twice the planned ``n``
and ``md`` (scaling).

Usage::

    python benchmarks/speed/plan_estimates.py                  # every case
    python benchmarks/speed/plan_estimates.py car_paint ...    # selected cases
    python benchmarks/speed/plan_estimates.py --json out.json  # also write the measurements
    python benchmarks/speed/plan_estimates.py --child NAME     # one case in this process (internal)

Output in ``benchmarks/speed/plan_estimates.txt``.
"""

from __future__ import annotations

import json
import os
import platform
import resource
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: Solves shorter than this (seconds) are repeated, and the shortest wall time kept.
REPEAT_BELOW = 20.0
#: At most this many solves of one case.
REPEATS = 3

GOLD = [0.143552, 3.98397]
#: Aluminium at about 650, 550 and 450 nm (eta, k).
ALUMINIUM = [[1.65746, 9.22387], [0.880369, 6.26952], [0.521229, 4.837]]


#: Environment of the cases that need one.
ENV = {"gold_under_hg, unparked (coupled)": {"LAYERSIM_PARK_DIR": "off"}}


def _car_paint(conductor_roughness=0.25, channels=3, n=None):
    """A car paint: a coat (eta 1.5, alpha 0.05) over an RGB medium (g 0.3) over aluminium."""
    pick = (lambda v: v) if channels == 3 else (lambda v: v[0])
    data = {"stack": {"name": "car_paint"}, "layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.05},
        {"kind": "medium", "tau": pick([0.3, 0.8, 1.5]), "albedo": pick([0.9, 0.6, 0.3]),
         "g": 0.3},
        {"kind": "conductor", "ior": pick(ALUMINIUM), "roughness": conductor_roughness}]}
    return data


def _coated_gold(top, bottom, **disc):
    """A dielectric coat (eta 1.5) over gold, roughness ``(alpha_u, alpha_v)`` each."""
    return {"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": list(top)},
                      {"kind": "conductor", "ior": GOLD, "roughness": list(bottom)}],
            "discretization": disc}


def _scene_file(name):
    return {"file": str(HERE.parent / "scenes" / f"{name}.toml")}


def _example(name):
    return {"file": str(HERE.parents[1] / "examples" / f"{name}.toml")}


def _layers(*layers, **disc):
    data = {"layer": list(layers)}
    if disc:
        data["discretization"] = disc
    return data


MED = lambda g, tau=5.0, albedo=0.95: {"kind": "medium", "tau": tau, "albedo": albedo, "g": g}
DIEL = lambda a, eta=1.5: {"kind": "dielectric", "ior": eta, "roughness": a}

#: name -> (scene: a dict of Scene.from_dict or {"file": path}, scale of the planned n and md)
#: Coupled solves park idle blocks in the system's temporary directory; the "unparked" cases
#: keep them in memory (:data:`ENV`).
CASES = {
    "vandehulst_slab": (_scene_file("vandehulst_slab"), 1.0),
    "coated_gold": (_scene_file("coated_gold"), 1.0),
    "coated_gold x2": (_scene_file("coated_gold"), 2.0),
    "coated gold 0.05/0.05 x1.41": (_layers(DIEL(0.05), {"kind": "conductor", "ior": GOLD,
                                                          "roughness": 0.05}), 1.41),
    "coated_hg_diffuse": (_scene_file("coated_hg_diffuse"), 1.0),
    "dusty_gold": (_scene_file("dusty_gold"), 1.0),
    "ggx_coated_gold (RGB)": (_scene_file("ggx_coated_gold"), 1.0),
    "rgb_coated_gold (RGB)": (_example("rgb_coated_gold"), 1.0),
    "car_paint (RGB)": (_car_paint(), 1.0),
    "car_paint red": (_car_paint(channels=1), 1.0),
    "dielectric 0.05": (_layers(DIEL(0.05)), 1.0),
    "medium g0.9 over diffuse, n 256": (_layers(MED(0.9), {"kind": "diffuse", "albedo": 0.5},
                                                n=256), 1.0),
    "medium g0.5 alone, n 400": (_layers(MED(0.5), n=400), 1.0),
    "medium g0.99 between alpha 0.1": (_layers(DIEL(0.1), MED(0.99, albedo=1.0),
                                               DIEL(0.1, eta=1.0)), 1.0),
    "dielectric 0.3 over medium, n 600": (_layers(DIEL(0.3), MED(0.7, tau=2.0), n=600), 1.0),
    "gold_under_hg (coupled)": (_scene_file("gold_under_hg"), 1.0),
    "gold_under_hg, unparked (coupled)": (_scene_file("gold_under_hg"), 1.0),
    "additive_validation (coupled)": (_scene_file("additive_validation"), 1.0),
    "brushed_metal (coupled)": (_example("brushed_metal"), 1.0),
    # Zeltner & Jakob 2018, Table 2 rows 4, 5 and 7 (coated gold) at the paper's ms (eq. (25)),
    # and row 6 at the reduced discretisation of benchmarks/speed/table2.py
    "Table 2 row 4 (coupled)": (_coated_gold((0.1, 0.1), (0.05, 0.15), ms=6), 1.0),
    "Table 2 row 5 (coupled)": (_coated_gold((0.1, 0.1), (0.1, 0.3), ms=6), 1.0),
    "Table 2 row 7 (coupled)": (_coated_gold((0.3, 0.1), (0.1, 0.3), ms=6), 1.0),
    "Table 2 row 6, n 224 (coupled)": (_coated_gold((0.15, 0.05), (0.05, 0.15), ms=6, n=224,
                                                    md=300), 1.0),
    "brushed paint (coupled, RGB)": (_layers(
        DIEL(0.2), {"kind": "medium", "tau": [0.3, 0.8, 1.5], "albedo": [0.9, 0.6, 0.3],
                    "g": 0.3},
        {"kind": "conductor", "ior": ALUMINIUM, "roughness": [0.3, 0.15]}), 1.0),
    "gold_blue_hg_coated red (coupled)": (_layers(
        DIEL(0.05), {"kind": "medium", "albedo": 0.6, "g": 0.2, "tau": 1.0},
        {"kind": "conductor", "ior": GOLD, "roughness": [0.05, 0.3]}), 1.0),
    "gold_blue_hg_coated (coupled, RGB)": (_scene_file("gold_blue_hg_coated"), 1.0),
}


def load_scene(name):
    import layersim
    from layersim.plan import accuracy
    from layersim.plan import make_plan
    source, scale = CASES[name]
    scene = (layersim.Scene.from_toml(source["file"]) if "file" in source
             else layersim.Scene.from_dict(source))
    if scale != 1.0:
        plan = make_plan(scene, refuse=False)
        scene = accuracy.scaled(scene, plan.n, plan.md, scale)
    return scene


def _part_timer(parts: dict):
    """Wrap the solver's layer operators and adding steps so that the CPU seconds (user +
    system, all threads) of each part accumulate in ``parts`` (``projection``: interfaces,
    ``media``, ``adding``: isotropic and coupled steps, not counted twice where one calls the
    other)."""
    from layersim.stacking import adding
    from layersim import solver
    from layersim.aniso import adding as aniso_adding
    from layersim.scene import Medium
    cpu = lambda: sum(resource.getrusage(resource.RUSAGE_SELF)[:2])
    depth = [0]

    def timed(fn, part):
        def wrapped(*args, **kwargs):
            name = part(args) if callable(part) else part
            depth[0] += 1
            c0 = cpu()
            try:
                return fn(*args, **kwargs)
            finally:
                depth[0] -= 1
                if depth[0] == 0:
                    parts[name] += cpu() - c0
        return wrapped

    kind = lambda args: "media" if isinstance(args[2].layers[args[3]], Medium) else "projection"
    solver._layer_operator = timed(solver._layer_operator, kind)
    adding.add = timed(adding.add, "adding")
    aniso_adding.add = timed(aniso_adding.add, "adding")


def child(name: str) -> dict:
    """Solve case ``name`` in this process; the measurements as a dict."""
    import warp as wp

    import layersim
    from layersim.config import settings
    from layersim.outofcore.memory import cap_arenas
    from layersim.plan import make_plan
    cap_arenas(settings().malloc_arenas)     # as the command line does
    wp.init()
    layersim.solve(layersim.Scene.from_dict({"layer": [DIEL(0.3)],
                                             "discretization": {"n": 32, "md": 8}}))
    scene = load_scene(name)
    rss = lambda: resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    cpu = lambda: sum(resource.getrusage(resource.RUSAGE_SELF)[:2])
    base = rss()
    plan = make_plan(scene, refuse=False)
    parts = dict.fromkeys(("projection", "media", "adding"), 0.0)
    _part_timer(parts)
    runs = []
    peak = None
    while True:
        for k in parts:
            parts[k] = 0.0
        c0, t0 = cpu(), time.perf_counter()
        bsdf = layersim.solve(scene)
        runs.append({"wall": time.perf_counter() - t0, "cpu": cpu() - c0, "parts": dict(parts)})
        if peak is None:
            peak = rss() - base
        del bsdf
        if sum(r["wall"] for r in runs) > REPEAT_BELOW or len(runs) >= REPEATS:
            break
    best = min(runs, key=lambda r: r["wall"])
    return {"name": name, "n": plan.n, "md": plan.md, "ms": plan.ms,
            "channels": scene.channels, "representation": plan.representation,
            "estimate_bytes": plan.memory_bytes, "estimate_seconds": plan.seconds,
            "base_bytes": base, "peak_bytes": peak, "walls": [r["wall"] for r in runs], **best}


def estimates(name: str) -> dict:
    """The plan's estimates of case ``name`` (no solve)."""
    from layersim.plan import make_plan
    plan = make_plan(load_scene(name), refuse=False)
    return {"estimate_bytes": plan.memory_bytes, "estimate_seconds": plan.seconds,
            "n": plan.n, "md": plan.md, "ms": plan.ms}


def _commit() -> str:
    try:
        out = subprocess.run(["git", "-C", str(HERE), "describe", "--always", "--dirty"],
                             capture_output=True, text=True, check=True)
        return out.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def row(r: dict) -> str:
    mib = 2.0 ** -20
    est, parts = r["estimate_seconds"], r["parts"]
    disc = f"{r['n']:4d} {r['md']:4d} {r['ms']:3d} {r['channels']:2d}"
    mem = (f"{r['estimate_bytes'] * mib:8.0f} {r['peak_bytes'] * mib:8.0f} "
           f"{r['estimate_bytes'] / max(r['peak_bytes'], 1):6.2f}")
    t = (f"{est['total']:7.2f} {r['cpu']:7.2f} {est['total'] / r['cpu']:5.2f} "
         f"{r['wall']:7.2f} {est['total'] / r['wall']:5.2f}")
    sub = " ".join(f"{est[p]:6.2f} {parts[p]:6.2f}" for p in ("projection", "media", "adding"))
    return f"{r['name']:34s} {disc} | {mem} | {t} | {sub} | {r['load']}"


HEADER = (f"{'case':34s} {'n':>4s} {'md':>4s} {'ms':>3s} {'ch':>2s} | {'est MiB':>8s} "
          f"{'peak MiB':>8s} {'ratio':>6s} | {'est s':>7s} {'cpu s':>7s} {'ratio':>5s} "
          f"{'wall s':>7s} {'ratio':>5s} | {'proj':>6s} {'cpu':>6s} {'media':>6s} {'cpu':>6s} "
          f"{'adding':>6s} {'cpu':>6s} | load")


def main(argv) -> int:
    if argv[:1] == ["--child"]:
        print(json.dumps(child(argv[1])))
        return 0
    out_json = None
    if "--json" in argv:
        k = argv.index("--json")
        out_json = argv[k + 1]
        del argv[k:k + 2]
    names = argv or list(CASES)
    unknown = [n for n in names if n not in CASES]
    if unknown:
        print(f"unknown case(s): {', '.join(unknown)}; expected: {', '.join(CASES)}")
        return 2
    env = dict(os.environ, LAYERSIM_MAX_MEMORY=str(1 << 50), LAYERSIM_MAX_SECONDS="off")
    print(f"# python benchmarks/speed/plan_estimates.py {' '.join(sys.argv[1:])}")
    print(f"# {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, commit {_commit()}, "
          f"{platform.node()}: {_cpu_model()}, {os.cpu_count()} cores, "
          f"{os.sysconf('SC_PHYS_PAGES') * os.sysconf('SC_PAGE_SIZE') / 2**30:.0f} GiB; "
          f"shared with other jobs: load averages (1, 5, 15 min) before each case in the "
          f"last column")
    print("# memory: plan estimate and peak RSS above the baseline of a warmed-up process "
          "(MiB); time: plan estimate, CPU time (user + system, both threads) and wall time "
          f"of the solve (s), the solve with the shortest wall time of up to {REPEATS} for "
          f"those under {REPEAT_BELOW:g} s; ratios: estimate / measured; proj, media, adding: "
          "each part's estimate and CPU time. The time model is fitted to CPU time, which the "
          "load of other jobs inflates less than the wall time")
    print(HEADER, flush=True)
    results = []
    for name in names:
        load = "{:.1f} {:.1f} {:.1f}".format(*os.getloadavg())
        proc = subprocess.run([sys.executable, __file__, "--child", name],
                              env={**env, **ENV.get(name, {})}, capture_output=True, text=True)
        if proc.returncode:
            print(f"{name:36s} failed: {proc.stderr.strip().splitlines()[-1]}", flush=True)
            continue
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        r["load"] = load
        results.append(r)
        print(row(r), flush=True)
    if out_json:
        Path(out_json).write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
