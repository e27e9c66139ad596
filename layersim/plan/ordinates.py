"""The ordinates ``n``: enough to resolve the narrowest angular lobe of the stack.

``n = N_PER_WIDTH / width`` puts a few ordinates across a lobe ``width`` radians wide (the
constant is set so that alpha = 0.1, eta = 1.5 gives layerlab's n = 196). A microfacet lobe of
roughness alpha is about ``alpha`` wide in reflection and ``alpha |1 - 1/eta|`` in refraction;
a Henyey-Greenstein phase function about ``sqrt(1 - |g|)``.
"""

from __future__ import annotations

import math

from ..errors import InfeasibleError
from ..operators.operator import Grid
from ..layers.base import N_PER_WIDTH
from ..operators.quadrature import SNELL, snell_rule
from ..scene import Discretization

N_MIN, N_MAX = 64, 4096
DEFAULT_RULE = "gauss-lobatto"
#: Factor on ``n`` for stacks with a smooth dielectric boundary (Snell-matched grid): the
#: ordinates outside the escape cone serve only the light trapped by total internal reflection.
#: With it, three stacks agree with Monte Carlo at 1e7 paths (benchmarks/features/smooth_vs_mc.txt).
SNELL_N_FACTOR = 2


def n_for_width(width: float) -> int:
    """Even number of ordinates (at least :data:`N_MIN`) for a lobe ``width`` radians wide."""
    n = math.ceil(N_PER_WIDTH / width)
    n += n % 2
    return max(N_MIN, n)


def choose_n(disc: Discretization, rule: str, widths: list, notes: list,
             overridden: dict) -> int:
    """``n`` for the narrowest of ``widths`` (``(width, layer index, kind, lobe)``), or the
    scene's override (with a note if it is below that), rounded up to what ``rule`` accepts.

    Raises
    ------
    InfeasibleError
        If the narrowest lobe needs more than :data:`N_MAX` ordinates.
    """
    if disc.n is not None:
        n = disc.n
        overridden["n"] = n
        if widths:
            width, idx, kind, what = min(widths)
            if n < n_for_width(width):
                notes.append(f"n = {n} from the scene is below the ~{n_for_width(width)} that "
                             f"layer {idx} ({kind}) needs ({what} ~{width:.3g} rad wide)")
    elif widths:
        width, idx, kind, what = min(widths)
        n = n_for_width(width)
        if n > N_MAX:
            raise InfeasibleError(
                f"layer {idx} ({kind}): its {what} is {width:.2g} rad wide and needs about "
                f"n = {n} ordinates (limit {N_MAX}); increase the roughness, move the relative "
                "index away from 1, or use layersim.montecarlo")
        notes.append(f"n set by layer {idx} ({kind}): {what} ~{width:.3g} rad wide")
    else:
        n = N_MIN
    if disc.quadrature:
        overridden["quadrature"] = rule
    if rule == "simpson38" and (n - 1) % 3:
        # composite Simpson 3/8 needs n - 1 divisible by 3, and n stays even
        n = 3 * math.ceil((n - 1) / 3) + 1
        n += 3 * (n % 2)
    return n


def choose_grid(disc: Discretization, rule: str, survey, notes: list, overridden: dict) -> Grid:
    """The grid of the plan: ``rule`` with :func:`choose_n` ordinates, or, for a stack with a
    smooth dielectric boundary (``survey.snell_eta``), the Snell-matched grid of that boundary
    (:func:`layersim.operators.quadrature.snell_rule`) with :data:`SNELL_N_FACTOR` times the
    ordinates.

    Raises
    ------
    InfeasibleError
        If a Snell-matched grid would get fewer than 16 ordinates (an override).
    """
    eta = survey.snell_eta
    if eta is None:
        return Grid.make(rule, choose_n(disc, rule, survey.widths, notes, overridden))
    if disc.quadrature and not disc.quadrature.startswith(SNELL):
        notes.append(f"quadrature {disc.quadrature} from the scene replaced by the "
                     "Snell-matched grid of the smooth boundary")
    rule = snell_rule(eta)
    n = choose_n(disc, rule, survey.widths, notes, overridden)
    if n < 16:
        raise InfeasibleError(f"[discretization] n = {n}: a stack with a smooth dielectric "
                              "boundary needs n >= 16 (4 or more ordinates on either side of its "
                              "critical angle); raise n or remove the override")
    if disc.n is None:
        n *= SNELL_N_FACTOR
        notes.append(f"n doubled to {n} for the smooth boundary: the escape cone, which holds "
                     "every direction seen from outside, gets about half of the ordinates")
    return Grid.make(rule, n)
