"""Planning of anisotropic stacks: the coupling width ``ms`` per layer, the truncation of the
coupled coefficients, and the size of coupled operators (the pre-pass of their Fourier orders
is the projection's, :func:`layersim.ingredients.aniso_microfacet.series_lengths`).

``ms`` (coupling half-width, modes ``s in [-ms, ms]`` of the azimuth sum) grows with the
roughness ratio ``r = max(alpha_u / alpha_v, alpha_v / alpha_u)``. Zeltner & Jakob 2018,
eq. (25), fit ``ms = ceil(2.58 r - 1.82)`` as the smallest ``ms`` with a relative L2 error
below 1 %. ``benchmarks/accuracy/ms_study.py`` (relative cosine-weighted L2 norm of the dropped
``f_{d,s}`` of Beckmann and GGX conductors and Beckmann dielectrics, r = 1.5 ... 6,
alpha_min = 0.1 and 0.2) confirms the fit where ``max(alpha) <= 0.5`` and shows that rougher
layers need one more mode to stay below 1 %: :func:`ms_one_percent` adds it. 1 % of the
coefficients is about 1.5e-3 of the bin energies, which a 1e9-path Monte Carlo reference
resolves; the planner keeps :data:`MS_MARGIN` more modes (:func:`ms_for_layer`). Isotropic layers
(``r = 1``) need ``ms = 0``, and a stack pays for coupling only if one of its layers is
anisotropic.
"""

from __future__ import annotations

import math

import numpy as np

#: ms = ceil(MS_SLOPE * r + MS_OFFSET) for r > 1 (Zeltner & Jakob 2018, eq. (25); see the
#: module docstring), plus one mode when the roughest axis exceeds MS_ROUGH.
MS_SLOPE, MS_OFFSET = 2.58, -1.82
MS_ROUGH = 0.5
#: Target of the ms rule: relative (cosine-weighted) L2 error of the dropped coefficients.
MS_TARGET = 0.01
#: Modes the planner keeps beyond the 1 % rule. Each mode divides the error of the dropped
#: coefficients by 1.4-3 for roughness ratios 6-2 (``benchmarks/accuracy/aniso_ms_decay.txt``),
#: and two modes take the bin energies' truncation error from about 1.5e-3 to 1.4-2.8e-4
#: (``benchmarks/accuracy/aniso_ms_cost.txt``), for 1.2-1.3 times the solve time and 1.3-1.4
#: times the memory estimate. Against 1e9 Monte Carlo paths per direction, Zeltner & Jakob
#: 2018's additive validation stack (Fig. 9a) has 54-76 % of its bins within 3 standard errors
#: with the 1 % rule and 100 % with two more modes (``benchmarks/accuracy/plans_vs_gpu_mc.txt``).
MS_MARGIN = 2
#: Relative truncation of each ordinate pair's coefficients ``f_{d,s}`` on the coupled path
#: (projection and the pre-pass that sets ``md``); the isotropic path keeps
#: ``layersim.ingredients.microfacet.RELERR`` = 1e-7. The ``ms`` rule already accepts a
#: relative L2 error of up to :data:`MS_TARGET` (1 %); dropping coefficients below 1e-5 of
#: their pair's largest removes a large share of the nonzeros of coupled layers (the work of
#: the adding equations scales with them) for changes of the BSDF and the albedo far below
#: that error (docs/performance.md, Table 2).
COUPLED_RELERR = 1e-5
#: Truncation per ordinate pair of the operators of a stack (:func:`layersim.aniso.adding.add`:
#: the result, and the intermediate products). Tighter than the layers': subtraction inverts
#: the adding equations, which amplifies errors of the stack (through the inverse transmission
#: of the known layer) but not those that the layers share with the stack. Recovering a
#: conductor (0.3, 0.2) from under a dust layer (tests/test_subtract.py) keeps its energy error
#: near 1e-6 with these values; looser ones raise it by one to three orders of magnitude.
STACK_RELERR, STACK_RELERR_INTERMEDIATE = 1e-7, 1e-6


def anisotropy_ratio(layer) -> float:
    """``max(alpha_u / alpha_v, alpha_v / alpha_u)`` (1 for isotropic layers)."""
    au, av = layer.alpha_u, layer.alpha_v
    if au == av:
        return 1.0
    return max(au / av, av / au)


def ms_for_ratio(r: float) -> int:
    """Coupling half-width needed for roughness ratio ``r`` (0 for ``r == 1``)."""
    if r <= 1.0:
        return 0
    return max(1, math.ceil(MS_SLOPE * r + MS_OFFSET))


def ms_one_percent(layer) -> int:
    """The smallest coupling half-width of an interface whose dropped coefficients stay below
    :data:`MS_TARGET`: :func:`ms_for_ratio` of its roughness ratio (Zeltner & Jakob 2018, eq.
    (25)), plus one mode if its roughest axis exceeds :data:`MS_ROUGH`
    (``benchmarks/accuracy/ms_study.py``)."""
    ms = ms_for_ratio(anisotropy_ratio(layer))
    if ms and max(layer.alpha_u, layer.alpha_v) > MS_ROUGH:
        ms += 1
    return ms


def ms_for_layer(layer) -> int:
    """The planner's coupling half-width of an interface: :func:`ms_one_percent` plus
    :data:`MS_MARGIN` (0 for an isotropic layer)."""
    ms = ms_one_percent(layer)
    return ms + MS_MARGIN if ms else 0


#: Fraction of the (d, s) coefficients of a pair's rectangle that survive pruning (Zeltner &
#: Jakob 2018, Table 2: 0.41 for gold (0.05, 0.15), 0.55 for glass (0.3, 0.1)). At
#: :data:`COUPLED_RELERR` the projected operators hold 0.52-0.82 of :func:`operator_entries`
#: (``benchmarks/speed/plan_estimates.py`` cases); the cost model (:mod:`layersim.plan.cost`) is
#: calibrated on this estimate.
FILL = 0.5


def operator_entries(lengths: np.ndarray, md: int, ms: int) -> int:
    """Estimated nonzeros of an anisotropic interface operator in the slot basis: per pair
    ``(2 min(len, md) - 1) (2 ms + 1)`` coefficients, :data:`FILL` of them nonzero."""
    return int(FILL * np.sum((2 * np.minimum(lengths, md) - 1) * (2 * ms + 1)))
