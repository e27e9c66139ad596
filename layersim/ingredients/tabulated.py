"""Interfaces with a tabulated NDF (Wang et al. 2008): projection onto the coupled-mode basis by
sampling on a uniform (phi_d, phi_s) grid and a 2-D FFT.

A tabulated D has no closed-form Fourier series (the analytic paths of :mod:`.microfacet` and
:mod:`.aniso_microfacet` rest on one), so every ordinate pair is sampled by the kernel
:func:`layersim.kernels.projection.tabulated_ds_samples`, which evaluates the same
:func:`layersim.kernels.tabulated.microfacet_eval_tabulated` as the random walk, at ``N_d``
azimuth differences and ``N_s`` sums, and the trapezoidal rule (a 2-D FFT) gives the complex
coefficients ``f_{d,s}`` of Zeltner & Jakob 2018, eq. (9)-(10). They are complex: a table need
not be mirror symmetric about the tangent axes, only symmetric under a rotation by pi
(:func:`layersim.ndf.table.from_arrays` checks it), which the basis itself assumes.

Sample counts: ``N_d`` is the smallest power of two >= ``4 md`` (at least :data:`ND_MIN`), so
that orders up to ``md`` are clean of aliasing from series up to ``3 md`` long; ``N_s`` is that
of the analytic coupled path for the layer's ``ms``. Orders beyond ``md`` that are still
significant (> ``relerr`` of the pair's largest) are cut with the Jackson kernel factors
(:func:`layersim.operators.fourier.taper_factors`), as in the analytic paths; coefficients below
``relerr`` of their pair's largest are dropped.

Assembly, reciprocity (reflection blocks from one triangle of pairs, ``Tbt`` from ``Ttb``) and
rotation are those of :func:`layersim.ingredients.aniso_microfacet.aniso_interface_operator`,
which calls the projector built here for the layer's blocks.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..operators import fourier
from ..aniso import basis
from ..kernels import projection as kproj
from ..operators.operator import Grid
from .microfacet import block_pairs

#: Smallest number of phi_d samples per pair.
ND_MIN = 128
#: Largest number of samples (pairs x N_d x N_s) of one batch (float64: 128 MiB).
BATCH_SAMPLES = 1 << 24


def sample_counts(md: int, ms: int) -> tuple[int, int]:
    """``(N_d, N_s)`` for ``md`` orders and coupling half-width ``ms`` (module docstring)."""
    n_d = max(ND_MIN, 1 << math.ceil(math.log2(4 * md)))
    n_s = max(16, 1 << math.ceil(math.log2(4 * ms + 4)))
    return n_d, n_s


def pair_coefficients(mu_i, mu_o, eta: complex, table: np.ndarray, md: int, ms: int,
                      relerr: float, device=None, shadowing: str = "separable"):
    """Coefficients ``C[p, md - 1 + d, ms + s] = f_{d,s}`` (|d| < md, |s| <= ms; complex) of
    ordinate pairs, and the number of pairs cut at ``md``.

    Parameters
    ----------
    mu_i, mu_o : ndarray, shape (P,)
        Signed ordinates (solver convention).
    eta : complex
        Relative index below/above.
    table : ndarray
        Packed NDF table (:meth:`layersim.ndf.table.NDFTable.packed`).
    shadowing : str
        The Smith term (:func:`layersim.kernels.physics.g2_from_masking`).
    """
    n_d, n_s = sample_counts(md, ms)
    f = kproj.tabulated_ds_samples(mu_i, mu_o, eta, table, n_d, n_s, device=device,
                                   shadowing=shadowing)
    c = np.fft.fft2(f, axes=(1, 2)) / (n_d * n_s)     # coefficient of exp(+i (d phi_d + s phi_s))
    del f
    d = np.arange(-(md - 1), md)
    s = np.arange(-ms, ms + 1)
    C = c[:, d % n_d][:, :, s % n_s]
    mag = np.abs(c)
    peak = mag.max(axis=(1, 2), initial=0.0)
    # orders past md still significant: the pair needs more than md orders
    beyond = np.abs(np.fft.fftfreq(n_d, 1.0 / n_d)) >= md
    cut = (mag[:, beyond].max(axis=(1, 2), initial=0.0) > relerr * peak)
    if cut.any():
        C[cut] *= fourier.taper_factors(md)[np.abs(d)][None, :, None]
    C[np.abs(C) < relerr * peak[:, None, None]] = 0.0
    return C, int(np.count_nonzero(cut))


def _entries(grid: Grid, md: int, ms: int, o, i, C):
    """Real slot-basis entries ``(rows, cols, values)`` of complex coefficients ``C`` (layout
    of :func:`pair_coefficients`): ``B_{l,k}[o, i] = 2 pi f_{d,s} w_i |mu_i|`` with
    ``l = d + s``, ``k = d - s`` (Zeltner & Jakob 2018, eq. (10)); the upper half of the modes
    (``l > 0``, or ``l = 0, k >= 0``) determines the real operator
    (:func:`layersim.aniso.basis.real_entries`)."""
    h = grid.h
    d = np.arange(-(md - 1), md)[:, None]
    s = np.arange(-ms, ms + 1)[None, :]
    l, k = d + s, d - s
    ok = (np.abs(l) < md) & (np.abs(k) < md) & ((l > 0) | ((l == 0) & (k >= 0)))
    vals = C[:, ok]                                          # (P, E)
    pp, ee = np.nonzero(vals)
    if not pp.size:
        return np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros(0)
    b = vals[pp, ee] * (2.0 * np.pi) * grid.flux_weight[i[pp]]
    rs, cs, v, src = basis.real_entries(l[ok][ee], k[ok][ee], b)
    nz = v != 0.0
    return ((rs[nz] * h + o[pp[src[nz]]]).astype(np.int32),
            (cs[nz] * h + i[pp[src[nz]]]).astype(np.int32), v[nz])


def projector(layer, eta_above: float, device=None):
    """The block projector of a tabulated-NDF interface for
    :func:`~layersim.ingredients.aniso_microfacet.aniso_interface_operator`: a function
    ``(grid, name, md, ms, triangle, stats, relerr, out)`` that appends the real entries of
    block ``name`` (one triangle of its pairs with ``triangle``) to ``out`` and returns it."""
    eta = complex(layer.ior) / eta_above
    table = layer.ndf.packed(np.float64)

    def project(grid: Grid, name: str, md: int, ms: int, triangle: bool, stats, relerr: float,
                out):
        mu_i, mu_o, o, i = block_pairs(grid, name, triangle)
        stats.pairs += mu_i.size
        stats.projected += mu_i.size
        t0 = time.perf_counter()
        n_d, n_s = sample_counts(md, ms)
        step = max(1, BATCH_SAMPLES // (n_d * n_s))
        for a in range(0, mu_i.size, step):
            sl = slice(a, a + step)
            C, cut = pair_coefficients(mu_i[sl], mu_o[sl], eta, table, md, ms, relerr, device,
                                       layer.shadowing)
            stats.truncated += cut
            out.append(_entries(grid, md, ms, o[sl], i[sl], C))
        stats.qs_max = max(stats.qs_max, n_s)
        stats.series_seconds += time.perf_counter() - t0
        return out

    return project
