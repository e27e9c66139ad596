"""Brushed near-specular coats (layersim.layers.brushed) against the Monte Carlo walk.

A dielectric top coat whose narrow roughness is near-specular (0.001-0.03) and whose wide one is
rough (0.2-0.5), over rough gold (alpha 0.2, the layerlab tutorial's index; one case in RGB),
rotated in one case, indices 1.3-1.7. The route as built solves the coat with its narrow
roughness raised to each floor of ``layersim.layers.brushed.BRUSHED_FLOORS`` on one
discretisation (the plan of the lowest floor) and extrapolates in the slope variance, its own
reflection replaced by the exact microfacet lobe. For each case it prints the plan (n, md, ms,
floors, weights, estimated memory and time), the solve's wall time and the process's peak RSS;
at 0, 30, 60 and 70 degrees the albedo against the walk's (difference, standard errors,
whether within max(4 se, 1e-3)) and the fraction of populated 10 x 12 bins (uniform in |cos
theta|, phi; the top side) within 3 sigma (the walk's standard error with the Poisson floor,
``SimulationResult.z_scores``); and the most negative value of the solved interpolant (which
``eval`` clips to zero) over 64 x 128 outgoing directions at each incidence, relative to the
largest. The walk walks the coat as given. Walks are read from (or written to) the cache of
``brushed_richardson.py`` (``out/brushed_walks/``, same scenes and seeds). Its last lines are
the plan's ``MEASURED_ERROR`` rows.

``control`` solves the first case's raised coat, (0.1, 0.3) over the same gold, exactly (an
ordinary coupled projection, its own reflection included) against its own walk: what the Fourier
solve of the raised stack alone achieves (``benchmarks/features/brushed_coats_control.txt``).

Usage: python benchmarks/features/brushed_coats.py [paths] [backend] [cases|control] [indices]
(default 1e6, auto, cases, all six)
"""

from __future__ import annotations

import platform
import resource
import sys
import time

import numpy as np

import layersim
import layersim.montecarlo as mc
from layersim.layers import brushed

MU_EDGES = np.linspace(0.0, 1.0, 11)
PHI_EDGES = np.linspace(0.0, 2 * np.pi, 13)
GOLD = [0.143552, 3.98397]
GOLD_RGB = [[0.143552, 3.98397], [0.377438, 2.38495], [1.43825, 1.60434]]
INCIDENCE = (0.0, 30.0, 60.0, 70.0)
#: (label, coat roughness, coat index, rotation in degrees, gold index) of the cases.
CASES = [("(0.03, 0.3) eta 1.5", [0.03, 0.3], 1.5, 0.0, GOLD),
         ("(0.001, 0.3) eta 1.5", [0.001, 0.3], 1.5, 0.0, GOLD),
         ("(0.01, 0.5) eta 1.3", [0.01, 0.5], 1.3, 0.0, GOLD),
         ("(0.2, 0.02) eta 1.7 rotated 30", [0.2, 0.02], 1.7, 30.0, GOLD),
         ("(0.03, 0.3) eta 1.5 RGB", [0.03, 0.3], 1.5, 0.0, GOLD_RGB),
         ("(0.03, 0.3) eta 1.3", [0.03, 0.3], 1.3, 0.0, GOLD)]
def scene(rough, eta: float, rotation: float, gold) -> layersim.Scene:
    return layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": eta, "roughness": rough, "rotation": rotation},
        {"kind": "conductor", "ior": gold, "roughness": 0.2}]})


def unit(theta_deg: float, phi_deg: float = 20.0) -> np.ndarray:
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def walks(sc: layersim.Scene, paths: int, backend: str, seed: int) -> list:
    """The walk's results at :data:`INCIDENCE` (seeds ``seed``, ``seed + 1``, ...)."""
    return [mc.simulate(sc, unit(theta), paths, mu_edges=MU_EDGES, phi_edges=PHI_EDGES,
                        backend=backend, seed=seed + k) for k, theta in enumerate(INCIDENCE)]


def solve(label: str, sc: layersim.Scene):
    t0 = time.perf_counter()
    bsdf = layersim.solve(sc)
    seconds = time.perf_counter() - t0
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    p, b = bsdf.plan, bsdf.plan.brushed
    route = "exact" if b is None else (
        f"floors {', '.join(f'{f:g}' for f in b['floors'])} weights "
        f"{', '.join(f'{w:+.3f}' for w in b['weights'])}")
    print(f"{label}: n={p.n} md={p.md} ms={p.ms} {route}; plan {p.memory_bytes / 2**30:.2f} GiB, "
          f"{p.seconds['total']:.0f} s estimated; solve {seconds:.1f} s wall, peak RSS of this "
          f"process so far {rss:.2f} GiB", flush=True)
    return bsdf


def most_negative(bsdf) -> tuple[float, float]:
    """The most negative value of ``bsdf.interpolant`` (1/sr, over channels) over 64 x 128
    outgoing directions (cosines 0.01-1, azimuths 0-2 pi) at every incidence of
    :data:`INCIDENCE`, and the largest value there."""
    mu = np.linspace(0.01, 1.0, 64)
    phi = np.linspace(0.0, 2 * np.pi, 128, endpoint=False)
    m, p = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1 - m * m)
    wo = np.stack([s * np.cos(p), s * np.sin(p), m], axis=-1).reshape(-1, 3)
    lo, hi = np.inf, -np.inf
    for theta in INCIDENCE:
        f = bsdf.interpolant(np.broadcast_to(unit(theta), wo.shape), wo)
        lo, hi = min(lo, float(f.min())), max(hi, float(f.max()))
    return lo, hi


def compare(bsdf, results: list) -> tuple[float, float, bool]:
    """Print the albedos and bins against the walk; return the largest |albedo difference|,
    the smallest bin fraction and whether every albedo met max(4 se, 1e-3)."""
    worst_d, worst_f, ok = 0.0, 1.0, True
    for theta, res in zip(INCIDENCE, results):
        wi = unit(theta)
        R = np.atleast_1d(bsdf.albedo(wi)[0])
        mcR, se = np.atleast_1d(res.reflectance), np.atleast_1d(res.reflectance_stderr)
        z = res.z_scores("top", bsdf.bin_energies(wi, MU_EDGES, PHI_EDGES)["top"])
        d = R - mcR
        within = bool(np.all(np.abs(d) <= np.maximum(4 * se, 1e-3)))
        frac = float(np.mean(z <= 3.0))
        print(f"  theta {theta:4.0f}: R {' '.join(f'{x:.5f}' for x in R)} mc "
              f"{' '.join(f'{x:.5f}' for x in mcR)} diff "
              f"{' '.join(f'{x:+.5f} ({x / s:+.1f} se)' for x, s in zip(d, se))} "
              f"{'ok' if within else 'OVER'}; bins {z.size}: {100 * frac:.1f} % <= 3 sigma, "
              f"max {z.max():.1f}", flush=True)
        worst_d, worst_f = max(worst_d, float(np.abs(d).max())), min(worst_f, frac)
        ok = ok and within
    return worst_d, worst_f, ok


def cached_walks(k: int, sc: layersim.Scene, paths: int, backend: str) -> list:
    """Case ``k``'s walks through the cache of ``brushed_richardson.py`` (imported here: it
    imports this module)."""
    import brushed_richardson
    return brushed_richardson.walks(k, sc, paths, backend)


def main() -> None:
    paths = int(float(sys.argv[1])) if len(sys.argv) > 1 else 1_000_000
    backend = sys.argv[2] if len(sys.argv) > 2 else "auto"
    part = sys.argv[3] if len(sys.argv) > 3 else "cases"
    picked = [int(c) for c in sys.argv[4].split(",")] if len(sys.argv) > 4 else \
        list(range(len(CASES)))
    print(f"# {paths:.3g} paths per direction, backend {backend}, {platform.node()}; incidence "
          f"{', '.join(f'{t:g}' for t in INCIDENCE)} deg (phi 20 deg); floors "
          f"{', '.join(f'{f:g}' for f in brushed.BRUSHED_FLOORS)} on the plan of the lowest")
    if part == "control":
        sc = scene([0.1, 0.3], 1.5, 0.0, GOLD)
        d, f, ok = compare(solve("(0.1, 0.3) eta 1.5, exact (control)", sc),
                           walks(sc, paths, backend, 3900))
        print(f"  worst: |albedo diff| {d:.1e}, bins {100 * f:.1f} %", flush=True)
        return
    rows = []
    for k in picked:
        label, rough, eta, rot, gold = CASES[k]
        sc = scene(rough, eta, rot, gold)
        results = cached_walks(k, sc, paths, backend)
        bsdf = solve(label, sc)
        d, f, ok = compare(bsdf, results)
        lo, hi = most_negative(bsdf)
        rows.append((min(rough), d, f))
        print(f"  worst: |albedo diff| {d:.1e}, bins within 3 sigma {100 * f:.1f} %, albedos "
              f"{'all within' if ok else 'NOT all within'} max(4 se, 1e-3); interpolant "
              f"min {lo:+.2e} 1/sr, {lo / hi:+.1e} of its peak {hi:.3g}", flush=True)
    print("# MEASURED_ERROR rows (narrow alpha, largest |albedo diff|, smallest bin fraction):")
    for a, d, f in rows:
        print(f"#   ({a:g}, {d:.2g}, {f:.3f}),")


if __name__ == "__main__":
    main()
