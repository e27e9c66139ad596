"""Statistical designs (Bati et al. 2021) against their exact refinement (`layersim design
--exact`) on the target sets of examples/design_targets.toml.

Per set: the statistical design and the refined one (layers), per lobe the target and the exact
transport lobe of each design at normal incidence (energy per channel; roughness: the GGX
roughness that fits the lobe, layersim/statistical/verify.py), the largest relative errors of
each design's exact lobes against the targets, and the refinement's exact solves and wall time.
Sets whose statistical design the solver refuses (near-specular interfaces inside a stack need
more memory than it may plan) or solves as specular paths (which the fits do not take), or whose solve the plan estimates above MAX_SOLVE seconds (a
refinement takes some 30-80 solves), are listed as skipped with the reason. Not a test.

Usage: python benchmarks/features/design_exact.py [max_solve_seconds] [SET ...]   (default 0.6)
"""

from __future__ import annotations

import os
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path[:0] = [str(ROOT / "benchmarks")]
from headline import commit, machine  # noqa: E402

import layersim  # noqa: E402
from layersim.outofcore import memory  # noqa: E402
from layersim.plan import make_plan  # noqa: E402
from layersim.statistical import parse_targets  # noqa: E402
from layersim.statistical.design import designs  # noqa: E402
from layersim.statistical.refine import refine  # noqa: E402

#: Default largest estimated time of one solve of a design refined (s).
MAX_SOLVE = 0.6


def fmt(x, f="{:.4f}") -> str:
    return "/".join(f.format(v) for v in np.atleast_1d(np.asarray(x, dtype=float)))


def skip_reason(design, targets, max_solve: float) -> str | None:
    """Why a design is not refined here, or None."""
    try:
        plan = make_plan(design.scene)
    except layersim.LayersimError as exc:
        return f"the solver refuses the statistical design ({exc})"
    if plan.representation == "specular-paths":
        return ("the solver takes the statistical design as specular paths (near-specular "
                "interfaces and clear media), which the exact fits do not take")
    seconds = plan.seconds["total"]
    if seconds > max_solve:
        return (f"one solve takes about {seconds:.1f} s by the plan's estimate (n = {plan.n}, "
                f"md = {plan.md}), over {max_solve:g} s")
    if all(t.roughness == 0.0 for t in targets.lobes):
        return "every lobe is smooth: nothing to refine"
    return None


def one(name, lobes, max_solve) -> list[str]:
    targets = parse_targets(lobes)
    d = designs(lobes)[0]
    why = skip_reason(d, targets, max_solve)
    if why:
        return [f"## {name}: skipped: {why}"]
    r = refine(d, targets, progress=False)
    lines = [f"## {name}  (refinement: {r.solves} exact solves in {r.seconds:.1f} s)"]
    lines += [f"   note: {n}" for n in d.notes]
    for key in ("statistical", "refined"):
        lines.append(f"   {key}:")
        lines += ["     " + s for s in getattr(r, key).scene.describe().splitlines()[1:]]
    for k, t in enumerate(targets.lobes):
        (es, a_s), (er, ar) = r.lobes["statistical"][k], r.lobes["refined"][k]
        lines.append(f"   lobe {k + 1}: target E {fmt(t.energy)} a {t.roughness:.3f} | statistical "
                     f"E {fmt(es)} a {fmt(a_s, '{:.3f}')} | refined E {fmt(er)} a "
                     f"{fmt(ar, '{:.3f}')}")
    ms, mr = r.mismatch["statistical"], r.mismatch["refined"]
    lines.append(f"   largest relative error: energy {100 * ms['energy']:.1f} % -> "
                 f"{100 * mr['energy']:.1f} %, roughness {100 * ms['roughness']:.1f} % -> "
                 f"{100 * mr['roughness']:.1f} %")
    return lines


def main() -> None:
    memory.cap_arenas(1)
    args = sys.argv[1:]
    max_solve = float(args.pop(0)) if args and args[0][:1].isdigit() else MAX_SOLVE
    sets = tomllib.loads((ROOT / "examples" / "design_targets.toml").read_text())["set"]
    if args:
        sets = [s for s in sets if s["name"] in args]
    t0 = time.perf_counter()
    print(f"# design_exact.py: statistical designs against their exact refinement")
    print(f"# command: python benchmarks/features/design_exact.py {max_solve:g} "
          + " ".join(f"'{a}'" for a in args))
    print(f"# machine: {machine(False)}")
    print(f"# date: {time.strftime('%Y-%m-%d %H:%M')}; commit: {commit()}")
    print(f"# load average (1 min) at the start: {os.getloadavg()[0]:.2f}")
    for s in sets:
        for line in one(s["name"], s["lobe"], max_solve):
            print(line, flush=True)
    print(f"# wall time {time.perf_counter() - t0:.0f} s; load average (1 min) at the end: "
          f"{os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
