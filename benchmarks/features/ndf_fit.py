"""Single-view NDF fitting and completion (Wang et al. 2008 sec. 5.1-5.2) on synthetic data.

Part 1, as the paper's Fig. 5: from one view (30, 40, 45 degrees) and 800 light directions
(Fibonacci cap to 85 degrees, lights beyond 80 degrees excluded by the fit) of an anisotropic GGX
or Beckmann surface with 1 % multiplicative noise, the partial NDF is fitted with the isotropically
constrained shadowing (Wang et al.) and with the shadowing of the partial NDF alone (Ngan et al.
2005). Printed per case, mean over 3 noise seeds: the relative L2 error of D over the covered
region Omega, its bias (solid-angle weighted mean relative error over Omega) and the fitted S at
the view against the closed-form Smith term.

Part 2: completion of the first of K partial NDFs of rotated samples (rotations 15 + k * 360 / K +
an irregular offset, view 40 degrees) from the other K - 1 (eq. 13-17); relative L2 error of the
normalised result over the covered region and over the whole hemisphere after the push-pull fill
of what no view reaches, with a flat or a zero condition at the horizon (the normalisation
depends on the fill, so both errors do).

Usage: python benchmarks/features/ndf_fit.py [n_theta n_phi]   (default 91 180)
"""

from __future__ import annotations

import platform
import sys
import time

import numpy as np

from layersim.ndf import complete as cp
from layersim.ndf import microfacet as mf
from layersim.ndf import synthetic as sy
from layersim.ndf.fit import fit_partial_ndf
from layersim.ndf.halfgrid import HalfGrid


def rel_l2(g, d, ref, mask=1.0):
    wts = g.weights * mask
    return float(np.sqrt(np.sum(wts * np.nan_to_num(d - ref) ** 2) / np.sum(wts * ref ** 2)))


def fit_case(g, dist, alpha, view_deg, constrained, seeds=(0, 1, 2)):
    view = sy.direction(view_deg, 10.0)
    ndf, shadow = sy.analytic_ndf(dist, *alpha, 20.0)
    truth = ndf(g.directions())
    rows = []
    for seed in seeds:
        m = sy.measure(view, sy.fibonacci_lights(800, 85.0), dist, *alpha, 20.0, noise=0.01,
                       seed=seed)
        p = fit_partial_ndf(m, g, constrained=constrained)
        mask = p.w > 0
        wts = g.weights * mask
        bias = np.sum(wts * np.nan_to_num(p.d - truth)) / np.sum(wts * truth)
        rows.append((rel_l2(g, p.d, truth, mask), bias, p.shadow_view - float(shadow(view))))
    return np.mean(rows, axis=0), float(shadow(view))


def completion_case(g, dist, alpha, k):
    rots = [15.0 + j * 360.0 / k + 7.0 * j * j for j in range(k)]
    view = sy.direction(40.0, 0.0)
    parts = [fit_partial_ndf(sy.measure(view, sy.fibonacci_lights(800, 85.0), dist, *alpha, r,
                                        noise=0.01, seed=j), g) for j, r in enumerate(rots)]
    truth = sy.analytic_ndf(dist, *alpha, rots[0])[0](g.directions())
    out = []
    done = cp.complete_ndf(parts[0], parts[1:])
    for horizon in ("flat", "zero"):
        d, filled = cp.fill_uncovered(done, horizon)
        d = d / g.projected_area(d)
        merges = sum(n.startswith("merged") for n in done.notes)
        out.append((done.coverage, filled, merges, rel_l2(g, d, truth, done.w > 0),
                    rel_l2(g, d, truth)))
    return out


def main():
    nt, nph = (int(sys.argv[1]), int(sys.argv[2])) if len(sys.argv) > 2 else (91, 180)
    g = HalfGrid(nt, nph)
    print(f"# grid {nt} x {nph}, {platform.machine()}, numpy {np.__version__}")
    print("# part 1: partial NDF from one view, 800 lights, 1 % noise; mean of 3 seeds")
    print(f"# {'dist':8s} {'alpha':>11s} {'view':>4s} | {'constrained S':^29s} | "
          f"{'unconstrained S':^29s} | S(o) exact")
    print(f"# {'':8s} {'':>11s} {'':>4s} | {'L2':>7s} {'bias':>8s} {'dS(o)':>10s}  | "
          f"{'L2':>7s} {'bias':>8s} {'dS(o)':>10s}  |")
    t0 = time.perf_counter()
    for dist in ("ggx", "beckmann"):
        for alpha in ((0.1, 0.25), (0.2, 0.4), (0.3, 0.6)):
            for view_deg in (30.0, 40.0, 45.0):
                (c, s_exact), (u, _) = (fit_case(g, dist, alpha, view_deg, flag)
                                        for flag in (True, False))
                print(f"  {dist:8s} {str(alpha):>11s} {view_deg:4.0f} | {c[0]:7.4f} "
                      f"{c[1]:+8.4f} {c[2]:+10.2e}  | {u[0]:7.4f} {u[1]:+8.4f} {u[2]:+10.2e}  | "
                      f"{s_exact:.4f}")
    print(f"# part 1 took {time.perf_counter() - t0:.0f} s")
    print("# part 2: completion from K rotated partial NDFs (view 40 deg)")
    print("#  dist     alpha        K  method          covered  filled  merges  L2(covered)  "
          "L2(full, filled)")
    for dist in ("ggx", "beckmann"):
        for alpha in ((0.2, 0.4), (0.3, 0.6)):
            for k in (4, 6):
                for name, (cov, fil, mer, l2c, l2f) in zip(("fill flat", "fill zero"),
                                                           completion_case(g, dist, alpha, k)):
                    print(f"  {dist:8s} {str(alpha):11s} {k:2d}  {name:14s}  {100 * cov:6.1f}%"
                          f"  {100 * fil:5.1f}%  {mer:6d}  {l2c:11.4f}  {l2f:16.4f}")
    print(f"# total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
