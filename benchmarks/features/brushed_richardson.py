"""Richardson extrapolation of the brushed route in the floor's slope variance, against the walk.

The brushed route (``layersim.layers.brushed``) projects a near-specular coat with its narrow
roughness raised to a floor ``f``. Slope-space variances add under convolution (Heitz 2014,
sec. 5; Belcour 2018), so a smooth output ``X`` of the solve (albedo, bin energy, eval: all
linear in the BSDF) changes, to first order, in proportion to the added variance
``v - v0`` with ``v = f^2`` and ``v0 = alpha_narrow^2``. Solving at two or three floors and
evaluating the interpolating polynomial in ``v`` at ``v0`` (Richardson 1911; Lagrange weights,
:func:`layersim.layers.brushed.extrapolation_weights`) removes that first-order (or also the
second-order) term. The exact lobe that replaces the coat's own reflection does not depend on the floor and the weights sum to one, so
it passes through unchanged.

For each case it prints, for every single floor of :data:`FLOORS` and every combination of
:data:`VARIANTS`, the albedo difference (in the walk's standard errors) and the fraction of
populated 10 x 12 top bins within 3 sigma (``MCResult.z_scores``) at 0, 30, 60 and 70 deg,
whether the issue's accuracy bar is met (every albedo within max(4 se, 1e-3), >= 97 % of bins at every
incidence; its 60 s bar is read from the summed solve times), and each solve's wall time and plan memory. The walks (those of
``brushed_coats.py``, same scenes and seeds) are cached in ``out/brushed_walks/<case>_<paths>.npz``
so that a repeated run costs only the solves.

With ``shared`` every floor is solved on the discretisation (n, md) of the lowest floor's
solve (``layersim.solve(..., like=...)``): the planner's n, md and ms jump with the floor, and
their discretisation error is not smooth in it.

Usage: python benchmarks/features/brushed_richardson.py [paths] [backend] [case indices] [shared]
(default 1e6, warp-cpu, "0,3", own discretisation per floor; indices into ``brushed_coats.CASES``)
"""

from __future__ import annotations

import platform
import resource
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import brushed_coats as bc  # noqa: E402  (the scenes, walks and bins of the route's benchmark)
import layersim  # noqa: E402
from layersim.layers import brushed  # noqa: E402
from layersim.montecarlo import MCResult  # noqa: E402

#: Floors solved for every case (descending; the last is the plan's lowest floor).
FLOORS = (0.15, 0.12, 0.1)
#: Extrapolations: the floors whose solves are combined.
VARIANTS = ((0.15, 0.1), (0.12, 0.1), (0.15, 0.12, 0.1))
#: The issue's bar: albedo within max(ALBEDO_SE * se, ALBEDO_ABS), BIN_FRACTION of bins <= 3.
ALBEDO_SE, ALBEDO_ABS, BIN_FRACTION = 4.0, 1e-3, 0.97
WALK_DIR = Path(__file__).resolve().parents[2] / "out" / "brushed_walks"


#: Lagrange weights at v0 of the solves at variances vs (the route's own function).
weights = brushed.extrapolation_weights


def case_file(k: int, paths: int) -> Path:
    return WALK_DIR / f"case{k}_{paths:.0e}.npz".replace("+", "")


def save_walks(path: Path, results: list) -> None:
    """Store what :meth:`MCResult.z_scores` and the albedo comparison need, per incidence."""
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **{name: np.array([getattr(r, attr) if key is None else getattr(r, attr)[key]
                                      for r in results])
                      for name, attr, key in (("R", "reflectance", None),
                                              ("se", "reflectance_stderr", None),
                                              ("bins", "bins", "top"),
                                              ("bins_se", "bins_stderr", "top"),
                                              ("particles", "particles", None),
                                              ("seconds", "seconds", None))})


def load_walks(path: Path) -> list:
    """The cached walks as :class:`MCResult` (only the fields the comparison reads are real)."""
    z = np.load(path)
    return [MCResult(reflectance=z["R"][i], transmittance=0.0, absorbed=0.0,
                     reflectance_stderr=z["se"][i], transmittance_stderr=0.0, absorbed_stderr=0.0,
                     bins={"top": z["bins"][i]}, bins_stderr={"top": z["bins_se"][i]},
                     particles=z["particles"][i], events=0, truncated=0, backend="cache",
                     device="cache", seconds=float(z["seconds"][i]), seed=-1,
                     wi=bc.unit(theta), mu_edges=bc.MU_EDGES, phi_edges=bc.PHI_EDGES)
            for i, theta in enumerate(bc.INCIDENCE)]


def walks(k: int, sc, paths: int, backend: str) -> list:
    """Case ``k``'s walks (seeds of ``brushed_coats.py``), from the cache or walked and cached."""
    path = case_file(k, paths)
    if not path.exists():
        t0 = time.perf_counter()
        save_walks(path, bc.walks(sc, paths, backend, 3000 + 10 * k))
        print(f"  walked {paths:.0e} x {len(bc.INCIDENCE)} in {time.perf_counter() - t0:.0f} s "
              f"-> {path.name}", flush=True)
    return load_walks(path)


def solve_outputs(sc, floor: float, like=None) -> tuple[list, float, float, str, object]:
    """Albedos and top bin energies at every incidence of the route solved at ``floor`` (on
    the discretisation of the BSDF ``like`` if given); the solve's wall seconds, its plan
    memory (GiB), its plan (n, md, ms) and the BSDF."""
    saved, brushed.BRUSHED_FLOORS = brushed.BRUSHED_FLOORS, (floor,)   # read by the plan
    try:
        t0 = time.perf_counter()
        bsdf = layersim.solve(sc, like=like)
        seconds = time.perf_counter() - t0
    finally:
        brushed.BRUSHED_FLOORS = saved
    p = bsdf.plan
    out = [(np.atleast_1d(bsdf.albedo(bc.unit(t))[0]).astype(float),
            np.asarray(bsdf.bin_energies(bc.unit(t), bc.MU_EDGES, bc.PHI_EDGES)["top"], float))
           for t in bc.INCIDENCE]
    return out, seconds, p.memory_bytes / 2**30, f"n={p.n} md={p.md} ms={p.ms}", bsdf


def combine(outputs: list, w) -> list:
    """The weighted sum ``sum_i w_i X_i`` of several solves' outputs, per incidence."""
    return [(sum(wi * o[k][0] for wi, o in zip(w, outputs)),
             sum(wi * o[k][1] for wi, o in zip(w, outputs))) for k in range(len(outputs[0]))]


def verdict(outputs: list, results: list) -> tuple[str, bool]:
    """One line per variant: at each incidence the albedo difference in se and the bin
    fraction within 3 sigma; and whether the issue's bar is met at every incidence."""
    parts, ok = [], True
    for theta, (R, bins), res in zip(bc.INCIDENCE, outputs, results):
        mcR, se = np.atleast_1d(res.reflectance), np.atleast_1d(res.reflectance_stderr)
        d = R - mcR
        frac = float(np.mean(res.z_scores("top", bins) <= 3.0))
        good = bool(np.all(np.abs(d) <= np.maximum(ALBEDO_SE * se, ALBEDO_ABS))) \
            and frac >= BIN_FRACTION
        ok = ok and good
        parts.append(f"{theta:2.0f}: {' '.join(f'{x:+.2e} ({x / s:+5.1f}se)' for x, s in zip(d, se))}"
                     f" {100 * frac:5.1f}%{'' if good else '*'}")
    return " | ".join(parts), ok


def run_case(k: int, paths: int, backend: str, shared: bool) -> None:
    """Case ``k`` at every floor and variant; with ``shared``, every floor is solved on the
    discretisation (n, md) of the lowest floor's solve, so that only the roughness varies."""
    label, rough, eta, rot, gold = bc.CASES[k]
    sc = bc.scene(rough, eta, rot, gold)
    print(f"## case {k}: {label}{'; every floor on the discretisation of floor ' if shared else ''}"
          f"{f'{min(FLOORS):g}' if shared else ''}", flush=True)
    results = walks(k, sc, paths, backend)
    solved, cost, like = {}, {}, None
    for f in sorted(FLOORS):
        solved[f], sec, gib, plan, bsdf = solve_outputs(sc, f, like)
        like = bsdf if shared else None
        cost[f] = (sec, gib)
        print(f"  solve floor {f:g}: {plan}, plan {gib:.2f} GiB, {sec:.1f} s wall", flush=True)
    v0 = min(rough) ** 2
    rows = [((f,), np.ones(1)) for f in FLOORS]
    rows += [(fs, weights(v0, [f * f for f in fs])) for fs in VARIANTS]
    for fs, w in rows:
        line, ok = verdict(combine([solved[f] for f in fs], w), results)
        sec = sum(cost[f][0] for f in fs)
        gib = max(cost[f][1] for f in fs)
        name = "floor " + fs[0].__format__("g") if len(fs) == 1 else \
            "extrap " + ",".join(f"{f:g}" for f in fs)
        print(f"  {name:<22} {'PASS' if ok else 'fail'} solve {sec:5.1f} s, plan <= {gib:.2f} GiB"
              f" [w {' '.join(f'{x:+.3f}' for x in w)}]\n      {line}", flush=True)


def main() -> None:
    paths = int(float(sys.argv[1])) if len(sys.argv) > 1 else 1_000_000
    backend = sys.argv[2] if len(sys.argv) > 2 else "warp-cpu"
    cases = [int(c) for c in (sys.argv[3] if len(sys.argv) > 3 else "0,3").split(",")]
    shared = len(sys.argv) > 4 and sys.argv[4] == "shared"
    print(f"# {paths:.3g} paths per direction, backend {backend}, {platform.node()}; incidence "
          f"{', '.join(f'{t:g}' for t in bc.INCIDENCE)} deg (phi 20 deg); bar: albedo within "
          f"max({ALBEDO_SE:g} se, {ALBEDO_ABS:g}) and >= {100 * BIN_FRACTION:g} % of populated "
          f"10 x 12 top bins <= 3 sigma at every incidence ('*' marks an incidence that misses)",
          flush=True)
    for k in cases:
        run_case(k, paths, backend, shared)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    print(f"# peak RSS of this process {rss:.2f} GiB", flush=True)


if __name__ == "__main__":
    main()
