"""Belcour's statistical model against exact transport on designed stacks (Bati et al. 2021).

For every target set of examples/design_targets.toml: the preferred design (`layersim.design`),
per lobe the target, the statistical model's lobe and exact transport's (energy at normal
incidence per channel; GGX roughness: the model's, and the fit to the exact lobe of the cut
stacks, layersim/statistical/verify.py), the statistical BSDF's relative L2 error against the
exact solve over 18 x 36 top bins at 0, 30 and 60 degrees, the albedos at normal incidence of
the model, the exact solve and a Monte Carlo run (its standard error), and the run times of the
design, the model (lobes and bins at one angle) and the exact solve. Stacks the solver refuses
(near-specular interfaces inside a stack need more memory than it may plan) are listed with the
reason and checked against the Monte Carlo reference instead (1e6 paths per direction, the
same lobe and bin comparisons; its time is that of the whole verification: the walks of the
cut stacks and of the three angles, and the width fits).

Usage: python benchmarks/features/statistical_vs_exact.py [paths] [max_seconds]   (default 1e5, 300)
"""

from __future__ import annotations

import platform
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

import layersim
import layersim.montecarlo as mc
from layersim.config import configure
from layersim.outofcore import memory
from layersim.statistical import parse_targets
from layersim.statistical.design import designs
from layersim.statistical.verify import montecarlo_solve, verify

ROOT = Path(__file__).resolve().parents[2]
#: Paths per incident direction of the Monte Carlo reference where the solver refuses a stack.
MC_REFERENCE_PATHS = 1_000_000


def fmt(x, f="{:.4f}") -> str:
    return "/".join(f.format(v) for v in np.atleast_1d(np.asarray(x, dtype=float)))


def one(name, lobes, paths, seed) -> list[str]:
    targets = parse_targets(lobes)
    t0 = time.perf_counter()
    d = designs(lobes)[0]
    t_design = time.perf_counter() - t0
    lines = [f"## {name}  (design {t_design:.2f} s, class position {d.choice})"]
    lines += ["   " + s for s in d.scene.describe().splitlines()[1:]]
    reference = "exact"
    try:
        res = verify(d)
    except layersim.LayersimError as exc:
        lines.append(f"   exact solve refused: {exc}")
        lines.append(f"   reference: Monte Carlo, {MC_REFERENCE_PATHS:.0e} paths per direction")
        t0 = time.perf_counter()
        res = verify(d, solve=montecarlo_solve(MC_REFERENCE_PATHS, seed=100 * seed))
        res["exact_seconds"] = time.perf_counter() - t0 - res["model_seconds"]
        reference = "MC"
    for k, (t, (me, ma), (ee, ea)) in enumerate(zip(targets.lobes, res["lobes"],
                                                   res["exact_lobes"]), start=1):
        lines.append(f"   lobe {k}: target E {fmt(t.energy)} a {t.roughness:.3f} | model E "
                     f"{fmt(me)} a {fmt(ma, '{:.3f}')} | {reference} E {fmt(ee)} a "
                     f"{fmt(ea, '{:.3f}')}")
    errs = res["errors"]
    timing = (f" | times: model {res['model_seconds']:.3f} s, {reference} "
              f"{res['exact_seconds']:.2f} s")
    if reference == "MC":
        lines.append(f"   R(0): model {fmt(errs[0.0]['R_model'])} MC {fmt(errs[0.0]['R_exact'])}")
        lines.append("   BSDF rel. L2 (model vs MC): " + "  ".join(
            f"{th:.0f} deg {e['l2']:.3f}" for th, e in errs.items()) + timing)
        return lines
    wi = np.array([0.0, 0.0, 1.0])
    sim = mc.simulate(d.scene, wi=wi, particles=paths, mu_edges=np.linspace(0, 1, 2),
                      phi_edges=np.linspace(0, 2 * np.pi, 2), backend="warp-cpu", seed=seed)
    lines.append(f"   R(0): model {fmt(errs[0.0]['R_model'])} exact "
                 f"{fmt(errs[0.0]['R_exact'])} MC {fmt(sim.reflectance)} +- "
                 f"{fmt(sim.reflectance_stderr, '{:.4f}')}")
    lines.append("   BSDF rel. L2 (model vs exact): " + "  ".join(
        f"{th:.0f} deg {e['l2']:.3f}" for th, e in errs.items()) + timing)
    return lines


def main() -> None:
    memory.cap_arenas(1)
    paths = int(float(sys.argv[1])) if len(sys.argv) > 1 else 100_000
    max_seconds = float(sys.argv[2]) if len(sys.argv) > 2 else 300.0
    sets = tomllib.loads((ROOT / "examples" / "design_targets.toml").read_text())["set"]
    print(f"# python benchmarks/features/statistical_vs_exact.py {paths:g} {max_seconds:g}  "
          f"# {platform.node()} ({platform.machine()})")
    with configure(max_seconds=max_seconds):
        for i, s in enumerate(sets):
            for line in one(s["name"], s["lobe"], paths, 7000 + i):
                print(line, flush=True)


if __name__ == "__main__":
    main()
