"""Accuracy of the anisotropic projection against a support-adapted brute-force reference.

For sample ordinate pairs of every block of a few interfaces, the 2-D coefficients
``f_{d,s}`` (Zeltner & Jakob 2018 eq. (17)) are computed by brute force from
``physics.microfacet_eval`` (through :func:`layersim.kernels.projection.microfacet_values_ds`):

* in ``phi_s``: trapezoidal rule with 512 samples (periodic, spectrally accurate);
* in ``phi_d``: composite Gauss-Legendre (24 nodes per panel) on panels graded geometrically
  towards the peak azimuth ``theta0(phi_s)`` (width ratio 2, smallest panel 1e-4 rad, none
  wider than a quarter period of the highest ``exp(-i d phi_d)`` or 0.1 rad), so that grazing
  lobes a few thousandths of a radian wide are resolved (a uniform FFT under-resolves them).

and compared with the projection's coefficients of the same pair (``|s| <= ms``, ``d`` up to
the series length): the error of each pair is the largest coefficient error relative to the
pair's largest coefficient. Pairs are drawn among those with both elevations within 80 degrees
(where the plan keeps all orders), a significant lobe, and a peak series within ``md``
(longer ones are tapered on purpose).

Usage::

    python benchmarks/accuracy/aniso_projection.py
"""

from __future__ import annotations

import sys
import time

import numpy as np

from layersim.aniso import series
from layersim.ingredients import aniso_microfacet as am
from layersim.ingredients.microfacet import block_pairs
from layersim.kernels import projection as kproj
from layersim.operators.operator import Grid
from layersim.scene import Conductor, Dielectric

N_PS = 512
GL = np.polynomial.legendre.leggauss(24)


def graded_panels(center: float, largest: float, smallest=1e-4, ratio=2.0):
    """Panel edges on [center - pi, center + pi] graded towards ``center``, no panel wider
    than ``largest`` (so that exp(-i d phi) is resolved too)."""
    w = [0.0]
    step = smallest
    while w[-1] + step < np.pi:
        w.append(w[-1] + step)
        step = min(step * ratio, largest)
    w.append(np.pi)
    w = np.array(w)
    return center + np.concatenate([-w[::-1], w[1:]])


def reference(mu_i, mu_o, layer, D, S):
    """Brute-force f_{d,s} for d = 0..D-1, |s| <= S (real part; the coefficients are real)."""
    eta = complex(layer.ior)
    ps = np.arange(N_PS) * (2 * np.pi / N_PS)
    # peak azimuth per phi_s from the kernel's q (same construction as the projection)
    three = np.array([0.0, 0.5 * np.pi, np.pi])
    _, q = kproj.microfacet_split_ds(np.array([mu_i]), np.array([mu_o]),
                                     np.tile(three, N_PS)[None, :], np.repeat(ps, 3)[None, :],
                                     eta, layer.alpha_u, layer.alpha_v, layer.distribution)
    q = q.reshape(N_PS, 3)
    theta0, _, _ = series.peak_shift_params(q[:, 0], q[:, 1], q[:, 2])
    x, w = GL
    G = np.zeros((N_PS, D), complex)
    for j in range(N_PS):
        edges = graded_panels(theta0[j], largest=min(0.1, 2 * np.pi * 4 / max(D, 1)))
        a, b = edges[:-1], edges[1:]
        nodes = (0.5 * (a + b))[:, None] + (0.5 * (b - a))[:, None] * x[None, :]
        weights = (0.5 * (b - a))[:, None] * w[None, :]
        nodes, weights = nodes.ravel(), weights.ravel()
        f = kproj.microfacet_values_ds(np.array([mu_i]), np.array([mu_o]), nodes[None, :],
                                       np.full((1, nodes.size), ps[j]), eta, layer.alpha_u,
                                       layer.alpha_v, layer.distribution)[0]
        G[j] = (np.exp(-1j * np.outer(np.arange(D), nodes)) * (f * weights)).sum(axis=1) \
            / (2 * np.pi)
    s = np.arange(-S, S + 1)
    return (np.exp(-1j * np.outer(s, ps)) @ G / N_PS).real.T        # (D, 2S+1)


def main() -> int:
    grid = Grid.make("gauss-lobatto", 96)
    md, ms = 240, 8
    cases = [("conductor (0.05, 0.15)", Conductor(ior=complex(0.143552, 3.98397),
                                                  alpha_u=0.05, alpha_v=0.15), ("Rt",)),
             ("conductor GGX (0.1, 0.3)", Conductor(ior=complex(0.143552, 3.98397),
                                                    alpha_u=0.1, alpha_v=0.3,
                                                    distribution="ggx"), ("Rt",)),
             ("dielectric (0.3, 0.1)", Dielectric(ior=1.5, alpha_u=0.3, alpha_v=0.1),
              ("Rt", "Ttb", "Rb"))]
    rng = np.random.default_rng(0)
    print(f"n = {grid.n}, md = {md}, ms = {ms}; per-pair error = max |f_ds - ref| / max |ref|")
    for label, layer, names in cases:
        for name in names:
            t0 = time.perf_counter()
            mu_i, mu_o, o, i = block_pairs(grid, name, False)
            stats = am.AnisoProjectionStats()
            chunks = am._project_block(grid, name, md, ms, complex(layer.ior), layer.alpha_u,
                                       layer.alpha_v, layer.distribution, stats)
            table = {(int(a), int(b)): F[k] for oo, ii, F in chunks
                     for k, (a, b) in enumerate(zip(oo, ii))}
            ok = [p for p in table if min(grid.mu[p[0]], grid.mu[p[1]]) > np.cos(np.radians(80))
                  and np.abs(table[p]).max() > 0]
            peak = max(np.abs(table[p]).max() for p in ok)
            ok = [p for p in ok if np.abs(table[p]).max() > 1e-3 * peak]
            # leave out pairs whose peak series is longer than md: the projection tapers them
            # on purpose (Jackson kernel factors), the reference does not
            sign_i = 1.0 if name in ("Rt", "Ttb") else -1.0
            sign_o = 1.0 if name in ("Rb", "Ttb") else -1.0
            po, pi_ = np.array([p[0] for p in ok]), np.array([p[1] for p in ok])
            _, q0, qpi, _ = am._coarse(sign_i * grid.mu[pi_], sign_o * grid.mu[po],
                                       complex(layer.ior), layer.alpha_u, layer.alpha_v,
                                       layer.distribution, 32)
            plen = am.fourier.peak_length(q0.ravel(), qpi.ravel(), layer.distribution,
                                          am.RELERR).reshape(q0.shape).max(axis=1)
            tapered = int(np.sum(plen > md))
            ok = [p for p, n in zip(ok, plen) if n <= md]
            pick = [ok[k] for k in rng.choice(len(ok), min(12, len(ok)), replace=False)]
            errs = []
            for oo, ii in pick:
                F = table[(oo, ii)]
                ref = reference(sign_i * grid.mu[ii], sign_o * grid.mu[oo], layer, F.shape[0], ms)
                errs.append(np.abs(F - ref).max() / np.abs(ref).max())
            errs = np.array(errs)
            print(f"{label:>26} {name:>3}: {len(pick)} pairs, median {np.median(errs):.1e}, "
                  f"max {errs.max():.1e} ({tapered} tapered pairs left out; "
                  f"{time.perf_counter() - t0:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
