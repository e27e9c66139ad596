"""The subtracting equations (Zeltner & Jakob 2018 sec. 3.4, eq. (13)-(16)): recover the unknown
layer of a two-layer stack from the stack and the known layer.

Removing a known **top** layer 1 (eq. (13)-(15); tildes denote the stack)::

    X   = Tbt1^+ (Rt~ - Rt1) Ttb1^+                 Rt2 = X (I + Rb1 X)^-1
    Ttb2 = Ttb~ Ttb1^+ (I - Rb1 Rt2)                 Tbt2 = (I - Rt2 Rb1) Tbt1^+ Tbt~
    Rb2 = Rb~ - Ttb2 (I - Rb1 Rt2)^-1 Rb1 Tbt2

Removing a known **bottom** layer 2 (eq. (16))::

    Y   = Ttb2^+ (Rb~ - Rb2) Tbt2^+                 Rb1 = Y (I + Rt2 Y)^-1
    Ttb1 = (I - Rb1 Rt2) Ttb2^+ Ttb~                 Tbt1 = Tbt~ Tbt2^+ (I - Rt2 Rb1)
    Rt1 = Rt~ - Tbt1 (I - Rt2 Rb1)^-1 Rt2 Ttb1

All four blocks of the unknown layer are recovered when the stack is transmissive (an opaque
stack yields the unknown bottom layer's ``Rt`` only).

Regularisation
--------------
The inverses of the known transmissions ``T^+`` are Tikhonov-regularised (Zeltner & Jakob 2018
sec. 5.5): ``T^+ = (T^T T + eps^2 I)^-1 T^T``, computed in the energy basis ``W B W^-1`` with
``W = diag(sqrt(w_j mu_j))`` per ordinate (and ``sqrt 2`` for the order-0 slot of coupled
operators), where a clear layer is the identity, singular values of a transmission are at most
~1, and reciprocal reflection blocks are symmetric. ``eps`` is thus the transmitted amplitude
below which components of the hidden layer are damped (filter factors
``s^2 / (s^2 + eps^2)``). The paper used 5e-4 for synthetic and 0.06-0.09 for measured data.

With ``eps=None`` it is chosen automatically. For a stack without noise (noise level at most
:data:`CORRECT_NOISE`) in two steps:

1. **Discrepancy principle**: the largest ``eps`` (bisection in ``log eps``) for which
   re-adding the known layer to the recovered one reproduces the stack to ``TAU`` times the
   noise level, ``||add(known, L_eps) - stack||_F <= TAU * noise * ||stack||_F`` (energy basis).
   The noise level (relative, per operator entry) is the ``noise`` argument or, when not given,
   estimated from the stack's violation of reciprocity (independent noise on the entries of a
   reflection block breaks its symmetry: ``||B - B^T|| ~ sqrt(2) noise ||B||``), at least
   :data:`NOISE_FLOOR` (a solved stack is reciprocal to ~1e-13).
2. **No oscillation** (the paper's own rule, sec. 5.5: "the smallest eps that still leads to a
   solution without oscillatory behavior"): if the recovered BSDF has negative lobes deeper
   than ``max(TAU * noise, NEG_FLOOR)`` of its peak (Fejer means of the low orders at every
   ordinate pair, :func:`negativity`), eps is increased (bisection) to the smallest value
   without them.

With noise the discrepancy principle over-regularises by a decade or more: the adding map from
the four blocks of the unknown layer to the four blocks of the stack is square, so the noise
is fitted at any small eps, and the residual reaches the noise level only where the
regularisation has already biased the result. There eps minimises the **estimated error** of the
result (:func:`_choose_eps_by_error`): the bias from the round trip of
:mod:`layersim.stacking.determined` and the spread from a second recovery with independent noise of
the estimated level, on common directions.

What the stack determines
-------------------------
The result reports the directions that the data determine (``info["subtract"]["determined"]``,
:mod:`layersim.stacking.determined`): the ordinates reached through the known layer, those among
them where the estimated error is within the tolerance (1e-3, or twice the noise level) and the
result has no negative lobes deeper than ``max(TAU * noise, NEG_FLOOR)`` of its peak, and the rule
that fills the hidden ones (a continuation of the BSDF coefficients; for isotropic data without
noise also a correction for the light that returns through them).

Ill-posed problems
------------------
A layer below an opaque (or almost opaque) one, or below a strongly diffusing one, cannot be
recovered: :class:`~layersim.errors.InfeasibleError` is raised, naming the reason, when the known
layer transmits less than :data:`OPAQUE` of the energy, or when its transmission resolves fewer
than :data:`VISIBLE_MIN` of the angular components (effective rank
``sum s^2 / (s^2 + e^2)`` of the order-0 transmission over the number of ordinates, with
``e = max(eps, VISIBLE_EPS)``: a thick scattering slab transmits a few diffuse components and a
direct beam attenuated below ``VISIBLE_EPS``). The
result reports what was chosen: ``result.info["subtract"]`` (``eps``, ``method``, ``noise``,
``noise_source``, ``residual`` of the regularised solution and ``residual_filled`` of the
returned one, ``visible``, ``negative_lobes`` and ``negative_lobes_determined``, ``determined``,
``energy_max``).
"""

from __future__ import annotations

import copy
import math
from contextlib import nullcontext

import numpy as np
import scipy.sparse as sps
from threadpoolctl import threadpool_limits

from .adding import BLAS_SINGLE_BELOW
from .adding import add as iso_add
from . import determined
from ..aniso import basis
from ..aniso.adding import add as coupled_add
from ..aniso.banded import banded_solve
from ..aniso.operator import AnisoOperator, prune
from ..aniso.plan import STACK_RELERR, STACK_RELERR_INTERMEDIATE
from ..solved.bsdf import BSDF, channel_pairs, refuse_boundary
from ..errors import InfeasibleError, OperatorError
from ..operators.operator import (BLOCKS, DROP_TOLERANCE, IsoOperator, common_representation,
                                  order_weight)

#: Discrepancy factor of the automatic choice of eps.
TAU = 1.5
#: Range searched for eps (energy basis, relative to a clear layer's 1). The two-sided inverse
#: of eq. (13) amplifies rounding errors by up to 1 / (4 eps^2).
EPS_RANGE = (1e-6, 1.0)
#: Smallest eps for coupled (anisotropic) operators, whose regularised inverse uses the normal
#: equations (conditioning squared).
EPS_MIN_ANISO = 1e-5
#: Resolution of the automatic search for eps (decades).
EPS_DECADES = 0.2
#: Smallest noise level assumed by the automatic choice.
NOISE_FLOOR = 1e-9
#: Seed of the independent noise that estimates how noise propagates into the result.
PERTURB_SEED = 12345
#: With noise, directions count as determined where the estimated error is at most this many
#: times the noise level (or layersim.stacking.determined.TOLERANCE, whichever is larger).
NOISE_TOLERANCE = 2.0
#: Largest noise level at which the recovered layer is corrected for light returned through
#: hidden directions (layersim.stacking.determined.correct).
CORRECT_NOISE = 1e-6
#: Factor on the round trip's bias term of a coupled recovery (:func:`_coupled_estimate`): the
#: round trip sees the hidden directions through the fill, a constant continuation of the BSDF
#: coefficients, which under-represents the grazing light of a rough conductor (the bias of
#: the true layer is up to 1.7 times that of the filled recovery on the anisotropic coatings
#: of benchmarks/features/subtract_study.py).
FILL_MARGIN = 2.0
#: Negative lobes allowed (fraction of the peak) regardless of noise (see negativity).
NEG_FLOOR = 1e-4
#: Orders of the Fejer means used to detect oscillation.
FEJER_ORDERS = 8
#: A known layer transmitting less than this energy fraction hides what is below it.
OPAQUE = 1e-4
#: Smallest fraction of resolved angular components of the known layer's transmission.
VISIBLE_MIN = 0.2
#: Components transmitted with an amplitude below this (energy basis) count as hidden, however
#: small eps is: no data are accurate enough to invert them.
VISIBLE_EPS = 1e-3


# ---------------------------------------------------------------------------------------------
# Public entry point
# ---------------------------------------------------------------------------------------------

def subtract(stack, known, side: str = "top", eps: float | None = None,
             noise: float | None = None):
    """Recover the unknown layer of a two-layer stack (Zeltner & Jakob 2018 eq. (13)-(16)).

    Parameters
    ----------
    stack, known : BSDF or operator
        Solved on the same discretisation (``layersim.solve(scene, like=other)``); BSDFs
        per channel (a 1-channel operand is shared by all channels of the other).
    side : {"top", "bottom"}
        Where ``known`` sits in the stack.
    eps : float, optional
        Tikhonov parameter (energy basis; see module docstring). None: discrepancy principle.
    noise : float, optional
        Relative noise level of the stack's operator entries (e.g. 0.01 for 1 %) used by the
        automatic choice; None: estimated from the stack's reciprocity defect.

    Returns
    -------
    BSDF or operator
        Same type as ``stack``; ``.info["subtract"]`` (per channel a list for RGB) reports eps,
        method, noise level and its source, re-adding residual and visibility.

    Raises
    ------
    InfeasibleError
        If the known layer hides the unknown one (opaque, or strongly diffusing at the noise
        level), or the stack is opaque while the unknown layer is on top.
    OperatorError
        If the operands are not compatible (grids, indices, opaque known layer on the wrong
        side).
    """
    if side not in ("top", "bottom"):
        raise ValueError(f"side must be 'top' or 'bottom' (where the known layer is), got "
                         f"{side!r}")
    if eps is not None and not (math.isfinite(eps) and eps >= 0):
        raise ValueError(f"eps must be a finite number >= 0, got {eps!r}")
    if noise is not None and not (math.isfinite(noise) and noise >= 0):
        raise ValueError(f"noise must be a finite number >= 0, got {noise!r}")
    if isinstance(stack, BSDF) or isinstance(known, BSDF):
        if not (isinstance(stack, BSDF) and isinstance(known, BSDF)):
            raise TypeError("subtract() takes two BSDF objects or two operators")
        refuse_boundary("subtract", stack, known)
        pairs = channel_pairs(stack, known,
                              "cannot subtract a {b}-channel BSDF from a {a}-channel one")
        ops, infos = [], []
        for s_op, k_op in pairs:
            op, info = _subtract_op(s_op, k_op, side, eps, noise)
            ops.append(op)
            infos.append(info)
        meta = {"scene": f"{stack.info.get('scene', 'stack')} - "
                         f"{known.info.get('scene', 'known')} ({side})",
                "channels": len(ops), "subtract": infos[0] if len(ops) == 1 else infos,
                # eval, albedo, export and plots show the fill in hidden directions: say so
                "notes": [f"subtracted layer{'' if len(ops) == 1 else f', channel {c}'}: "
                          + determined.describe(info["determined"])
                          for c, info in enumerate(infos)]}
        return BSDF(ops, None, meta)
    op, info = _subtract_op(stack, known, side, eps, noise)
    op.info = {"subtract": info}
    return op


# ---------------------------------------------------------------------------------------------
# Driver
# ---------------------------------------------------------------------------------------------

def _subtract_op(stack, known, side, eps, noise):
    if any(name in op.delta for op in (stack, known) for name in ("Rt", "Rb")):
        # the recovered layer's mirror delta would need the delta algebra inverted
        # (layersim.operators.deltas); without it the delta would be smeared into the smooth part
        raise OperatorError("cannot subtract operators with a mirror (specular) reflection "
                            "delta (a smooth interface, roughness 0); give it a roughness > 0")
    if stack.grid != known.grid:
        raise OperatorError(f"stack and known layer are on different grids ({stack.grid.rule} "
                            f"n={stack.grid.n} vs {known.grid.rule} n={known.grid.n}); solve "
                            "the known layer with layersim.solve(scene, like=stack) "
                            "('layersim solve KNOWN.toml --like STACK.lsim')")
    if known.opaque and side == "top":
        raise InfeasibleError("the known top layer is opaque: it hides the layer below it "
                              "(ill-posed); nothing can be recovered")
    if known.opaque:
        raise InfeasibleError("the known bottom layer is opaque, so the stack has only its top "
                              "reflection Rt~: the four blocks of the layer above cannot be "
                              "recovered from it (ill-posed)")
    if side == "bottom" and stack.opaque:
        raise OperatorError("the stack is opaque but the known bottom layer is transmissive: "
                            "it cannot be the bottom of this stack (did you mean side='top'?)")
    tol = 1e-9
    if side == "top":
        if abs(stack.eta_top - known.eta_top) > tol * max(1.0, stack.eta_top):
            raise OperatorError(f"index mismatch: the stack starts in a medium of index "
                                f"{stack.eta_top:g}, the known top layer in {known.eta_top:g}")
    else:
        if abs(stack.eta_bottom - known.eta_bottom) > tol * max(1.0, stack.eta_bottom):
            raise OperatorError(f"index mismatch: the stack ends in a medium of index "
                                f"{stack.eta_bottom:g}, the known bottom layer in "
                                f"{known.eta_bottom:g}")
    # small dense per-order products and SVDs run faster on one BLAS thread (as in adding)
    with (threadpool_limits(1, user_api="blas") if stack.grid.h < BLAS_SINGLE_BELOW
          else nullcontext()):
        return _subtract_checked(stack, known, side, eps, noise)


def _subtract_checked(stack, known, side, eps, noise):
    """:func:`_subtract_op` after the operands have been checked."""
    alg = _ALGEBRAS[common_representation(stack, known)](stack, known)

    t_names = ("Ttb", "Tbt")
    visible, energy = alg.visibility(t_names)
    if energy < OPAQUE:
        raise InfeasibleError(
            f"the known {side} layer transmits at most {energy:.2g} of the incident energy: "
            f"it hides the layer {'below' if side == 'top' else 'above'} it (ill-posed); "
            "nothing can be recovered")
    vis0, _ = alg.visibility(t_names, VISIBLE_EPS if eps is None else max(eps, VISIBLE_EPS))
    if vis0 < VISIBLE_MIN:
        _raise_diffusing(side, vis0, VISIBLE_EPS if eps is None else max(eps, VISIBLE_EPS),
                         None, "", alg.h)
    if noise is None:
        noise_level, source = alg.reciprocity_noise(), "reciprocity"
    else:
        noise_level, source = float(noise), "given"
    noise_level = max(noise_level, NOISE_FLOOR)
    if eps is None and noise_level > CORRECT_NOISE:
        rec, resid, e, method, neg, spread = _choose_eps_by_error(alg, known, side, noise_level)
    else:
        (rec, resid, e, method, neg), spread = _choose_eps(alg, side, eps, noise_level), None
    vis, _ = alg.visibility(t_names, max(e, VISIBLE_EPS))
    info = {"eps": e, "method": method, "noise": noise_level, "noise_source": source,
            "residual": resid, "visible": vis, "negative_lobes": neg, "side": side}
    if vis < VISIBLE_MIN:
        _raise_diffusing(side, vis, max(e, VISIBLE_EPS), noise_level, source, alg.h)
    op = alg.to_operator(rec, side)
    det, op = _determine(known, op, side, e, noise_level, getattr(alg, "svd", None), spread,
                         coupled=True)
    neg_tol = max(TAU * noise_level, NEG_FLOOR)
    info["negative_lobes_determined"] = _without_oscillation(det, op, side, neg_tol)
    info["determined"] = det.as_dict()
    info["residual_filled"] = alg.residual_of(op, side)
    info["energy_max"] = alg.energy_max(op)
    return op, info


def _determine(known, op, side: str, eps: float, noise_level: float, svd: dict | None,
               spread=None, coupled: bool = False):
    """What the stack determines of the recovered ``op``, and ``op`` with its hidden directions
    filled (and corrected, if isotropic): :mod:`layersim.stacking.determined`. The estimate runs on
    the rotational averages (the azimuthal mean) of anisotropic operators. ``svd``: the SVD cache of
    the known layer's isotropic algebra, if any; ``spread``: the noise part of the error per mu
    cut (:func:`_choose_eps_by_error`), if any; ``coupled``: estimate the error of an anisotropic
    recovery in the coupled algebra (:func:`_coupled_estimate`; the final report, not each
    candidate eps of the choice)."""
    known_iso = known.rotational_average()

    def round_trip(layer):
        again = iso_add(known_iso, layer) if side == "top" else iso_add(layer, known_iso)
        alg = _IsoAlgebra(again, known_iso, svd)
        return alg.to_operator(alg.recover(side, eps), side)

    iso = op.representation == "isotropic"
    tolerance = max(determined.TOLERANCE, NOISE_TOLERANCE * noise_level)
    det, filled, corrected = determined.assess(
        known_iso, op.rotational_average(), side, eps, round_trip, tolerance=tolerance,
        correct_hidden=iso and noise_level <= CORRECT_NOISE, spread=spread)
    if iso:
        det.corrected = corrected is not None
        return det, corrected if det.corrected else filled
    filled = determined.fill(op, det.reached, side)
    if coupled and det.mu_reached is not None:
        est = _coupled_estimate(known, filled, side, eps)
        if spread is not None:
            est = np.hypot(est, spread)
        det = determined.declare(op.grid, det.reached, est, tolerance, side, det.ior)
    return det, filled


def _coupled_estimate(known, filled, side: str, eps: float) -> np.ndarray:
    """Estimated error per mu cut (:func:`layersim.stacking.determined.error_by_cut`) of a
    coupled recovery ``filled`` (hidden directions filled), in the coupled algebra itself.

    Two terms, added (the triangle inequality): the round trip through the exact adding
    (what the filter and the hidden directions change for a layer like ``filled``) times
    :data:`FILL_MARGIN`, and what
    the truncation of a solved stack changes in that round trip. A coupled stack from
    :func:`layersim.solve` is added with its coefficients below :data:`STACK_RELERR` of their
    ordinate pair dropped (:func:`layersim.aniso.adding.add`); the truncation is reciprocal, so
    the reciprocity defect does not see it, and the inverse transmissions amplify it like
    noise. The round trip adds with the same truncation to see that amplification. On the
    rotational averages neither shows: their anisotropic part, where the error lives, is
    averaged away."""
    def recover(truncated: bool):
        kw = ({"relerr": STACK_RELERR, "relerr_intermediate": STACK_RELERR_INTERMEDIATE}
              if truncated else {})
        again = (coupled_add(known, filled, **kw) if side == "top"
                 else coupled_add(filled, known, **kw))
        alg = _AnisoAlgebra(again, known)
        return alg.to_operator(alg.recover(side, eps), side)

    exact = recover(False)
    return (FILL_MARGIN * determined.error_by_cut(exact, filled, side)
            + determined.error_by_cut(recover(True), exact, side))


def _without_oscillation(det, op, side: str, tol: float) -> float:
    """Raise ``det.mu_min`` (bisection over the ordinates) until the result has no negative
    lobes deeper than ``tol`` of its peak over the determined directions (amplified noise rings
    where the data are weakest); returns the depth there."""
    mu = op.grid.mu
    if det.mu_min is None:
        return 0.0
    depth = negativity(determined.restrict(op, det.mu_min, side))
    if depth <= tol:
        return depth
    lo, hi = int(np.searchsorted(mu, det.mu_min)), mu.size     # lo fails; hi: nothing left
    found = None
    while hi - lo > 1:
        mid = (lo + hi) // 2
        d_mid = negativity(determined.restrict(op, float(mu[mid]), side))
        if d_mid <= tol:
            hi, found = mid, d_mid
        else:
            lo = mid
    det.mu_min = None if found is None else float(mu[hi])
    if found is not None:
        det.error = float(det.errors[hi])
    return 0.0 if found is None else found


def _choose_eps_by_error(alg, known, side: str, noise_level: float):
    """Choose eps for noisy data by the smallest estimated error of the recovered layer over the
    reached directions: ``sqrt(bias^2 + spread^2)``, the bias from the round trip of the
    recovered layer (:func:`layersim.stacking.determined.assess`), the spread from a second recovery
    of the stack with independent multiplicative noise of the estimated level added, both over the
    directions reached at ``eps = max(noise, VISIBLE_EPS)`` for every candidate. A grid of
    half decades from ``noise / 10`` (or the algebra's floor) to 1, refined by quarter decades
    around its best. Returns ``(recovered blocks, re-adding residual, eps, method, negativity,
    spread per mu cut)``."""
    noisy = alg.perturbed(noise_level, PERTURB_SEED)
    svd = getattr(alg, "svd", None)
    seen = {}

    def total(le):
        if le not in seen:
            e = 10.0 ** le
            rec = alg.recover(side, e)
            op = alg.to_operator(rec, side)
            again = noisy.to_operator(noisy.recover(side, e), side)
            spread = determined.error_by_cut(again, op, side)
            det, filled = _determine(known, op, side, e, noise_level, svd, spread)
            if det.errors is None:
                err = math.inf
            else:
                # absolute errors, on the scale of the layer recovered at eps ~ noise: a
                # relative error would hide a result inflated by amplified noise
                norm = determined.norm_by_cut(filled.rotational_average(), side)[common]
                err = det.errors[common] * norm / reference
            seen[le] = (err, rec, e, spread)
        return seen[le][0]

    # every eps is judged on the same directions: those reached at eps ~ the noise level
    reached = determined.visibility(known.rotational_average(), side,
                                    max(noise_level, VISIBLE_EPS)) >= determined.REACHED
    common = int(np.argmax(reached))
    reference = 1.0
    e_ref = max(noise_level, VISIBLE_EPS)
    reference = determined.norm_by_cut(
        alg.to_operator(alg.recover(side, e_ref), side).rotational_average(), side)[common]

    lo = math.log10(max(alg.eps_min, noise_level / 10.0, EPS_RANGE[0]))
    grid = list(np.arange(lo, math.log10(EPS_RANGE[1]) + 1e-9, 0.5))
    best = min(grid, key=total)
    best = min([best - 0.25, best, best + 0.25], key=total)
    err, rec, e, spread = seen[best]
    neg = alg.negativity(alg.to_operator(rec, side))
    return rec, alg.residual(rec, side), e, "estimated error", neg, spread


def _choose_eps(alg, side: str, eps: float | None, noise_level: float):
    """Recover with the given ``eps`` (at least the algebra's floor), or choose it (module
    docstring: discrepancy principle, then no oscillation). Returns ``(recovered blocks,
    re-adding residual, eps, method, negativity or None)``."""

    def run(e):
        rec = alg.recover(side, e)
        return rec, alg.residual(rec, side)

    if eps is not None:
        e = max(float(eps), alg.eps_floor)
        rec, resid = run(e)
        method = "given"
        neg = None
    else:
        target = TAU * noise_level
        lo, hi = math.log10(max(alg.eps_min, EPS_RANGE[0])), math.log10(EPS_RANGE[1])
        rec, resid = run(10 ** lo)
        e = 10 ** lo
        if resid <= target:
            # bisection on log10(eps) for the largest eps meeting the discrepancy
            top = hi
            for _ in range(16):
                mid = 0.5 * (lo + top)
                r_mid, res_mid = run(10 ** mid)
                if res_mid <= target:
                    lo, rec, resid, e = mid, r_mid, res_mid, 10 ** mid
                else:
                    top = mid
                if top - lo < EPS_DECADES:
                    break
        method = "discrepancy"
        neg_tol = max(TAU * noise_level, NEG_FLOOR)
        neg = alg.negativity(alg.to_operator(rec, side))
        if neg > neg_tol:
            # smallest eps above the discrepancy choice without oscillation
            lo_n, hi_n = math.log10(e), hi
            best = None
            for _ in range(16):
                mid = 0.5 * (lo_n + hi_n)
                r_mid, res_mid = run(10 ** mid)
                n_mid = alg.negativity(alg.to_operator(r_mid, side))
                if n_mid <= neg_tol:
                    hi_n, best = mid, (r_mid, res_mid, 10 ** mid, n_mid)
                else:
                    lo_n = mid
                if hi_n - lo_n < EPS_DECADES:
                    break
            if best is None:
                best = (*run(10 ** hi),)
                best = (best[0], best[1], 10 ** hi, alg.negativity(alg.to_operator(best[0],
                                                                                    side)))
            rec, resid, e, neg = best
            method = "discrepancy+no-oscillation"
    return rec, resid, e, method, neg


def relative_error(a, b) -> float:
    """Relative Frobenius error of operator ``a`` against ``b`` over all blocks, in the energy
    basis (entries scaled by ``sqrt(w mu)`` of the outgoing over the incident ordinate, where a
    clear layer is the identity): the distance used to judge a recovered layer."""
    a, b = a.as_coupled(), b.as_coupled()
    w = np.tile(np.sqrt(a.grid.flux_weight), a.slots)
    W, Wi = sps.diags(w), sps.diags(1.0 / w)
    num = den = 0.0
    for k, blk in b.blocks.items():
        if blk is None:
            if a.blocks[k] is not None:
                raise ValueError(f"block {k} is present in one operator only")
            continue
        num += (W @ (a.blocks[k] - blk) @ Wi).power(2).sum()
        den += (W @ blk @ Wi).power(2).sum()
    return float(np.sqrt(num / den))


def with_noise(op, level: float, seed: int):
    """``op`` with independent multiplicative Gaussian noise of relative standard deviation
    ``level`` on every stored entry (synthetic "measured" stacks for subtraction studies)."""
    rng = np.random.default_rng(seed)
    return op.map_blocks(lambda mat: mat.multiply(1 + level * rng.standard_normal(mat.shape))
                         .tocsr())


def _raise_diffusing(side, vis, e, noise_level, source, h):
    noise = "" if noise_level is None else f", noise level {noise_level:.2g} ({source})"
    raise InfeasibleError(
        f"the known {side} layer is strongly diffusing: at eps = {e:.2g}{noise} its order-0 "
        f"transmission resolves only {100 * vis:.0f} % of the {h} angular components of the "
        f"layer {'below' if side == 'top' else 'above'} it (ill-posed; at least "
        f"{100 * VISIBLE_MIN:.0f} % needed): its BSDF cannot be recovered from this stack")


# ---------------------------------------------------------------------------------------------
# Energy basis helpers
# ---------------------------------------------------------------------------------------------

def negativity(op, L: int = FEJER_ORDERS) -> float:
    """Depth of negative lobes of an operator's BSDF relative to its peak, measured on Fejer
    means: ``sum_{|l| < L} (1 - |l| / L) f_l exp(i l phi)`` (per azimuth, or the product kernel
    over both azimuths of coupled operators) is non-negative for every non-negative BSDF, at
    every ordinate pair, however the series was truncated at ``md`` (truncation rings by ~1 %
    at coarse ``md``; the Fejer mean does not). Oscillations of a deconvolution, which run
    across ordinates, make it negative. Unscattered deltas are left out."""
    return _NEGATIVITY[op.representation](op, L)


def _negativity_iso(op, L: int) -> float:
    """:func:`negativity` of an isotropic operator (Fejer means over one azimuth)."""
    h = op.h
    fw = op.grid.flux_weight
    worst = 0.0
    L = min(L, op.m)
    phi = np.linspace(0.0, np.pi, 4 * L)
    for name in BLOCKS:
        if op.blocks[name] is None:
            continue
        f = np.zeros((h, h, phi.size))
        for l in range(L):
            c = op.coefficients(name, l)
            if name in op.delta:
                c = c - np.diag(op.delta[name] / (order_weight(l) * fw))
            f += (1.0 - l / L) * c[:, :, None] * np.cos(l * phi)[None, None, :]
        peak = float(np.abs(f).max())
        if peak > 0:
            worst = max(worst, float(max(0.0, -f.min())) / peak)
    return worst


def _negativity_coupled(op, L: int) -> float:
    """:func:`negativity` of a coupled operator (product Fejer kernel over both azimuths, on at
    most 4096 ordinate pairs)."""
    h = op.h
    fw = op.grid.flux_weight
    worst = 0.0
    L = min(L, op.md)
    S = basis.n_slots(L)
    mode = basis.slot_mode(L)
    fejer = 1.0 - mode / L
    grid = np.linspace(0.0, 2.0 * np.pi, 4 * L, endpoint=False)
    sin = basis.slot_is_sin(L)
    U = np.where(sin[None, :], np.sin(np.outer(grid, mode)), np.cos(np.outer(grid, mode)))
    V = 2.0 * U
    V[:, 0] = 1.0
    rng = np.random.default_rng(0)
    pairs = np.arange(h * h) if h * h <= 4096 else rng.choice(h * h, 4096, replace=False)
    o, i = pairs // h, pairs % h
    for name in BLOCKS:
        if op.blocks[name] is None:
            continue
        G = op.coefficients(name)[:S * h, :S * h].tocsr()
        if name in op.delta:
            G = G - sps.diags(np.tile(op.delta[name] / (2.0 * np.pi * fw), S))
        rows = (np.arange(S)[None, :] * h + o[:, None])            # (P, S)
        cols = (np.arange(S)[None, :] * h + i[:, None])
        g = np.asarray(G[rows.ravel()][:, np.arange(S * h)].toarray()).reshape(
            pairs.size, S, S * h)
        g = np.take_along_axis(g, cols[:, None, :], axis=2)         # (P, S, S)
        g = g * fejer[None, :, None] * fejer[None, None, :]
        f = np.einsum("xa,pab,yb->pxy", U, g, V, optimize=True)
        peak = float(np.abs(f).max())
        if peak > 0:
            worst = max(worst, float(max(0.0, -f.min())) / peak)
    return worst


_NEGATIVITY = {"isotropic": _negativity_iso, "anisotropic": _negativity_coupled}


def _frob2(mats) -> float:
    total = 0.0
    for m in mats:
        if sps.issparse(m):
            total += float(np.sum(m.data ** 2))
        else:
            total += float(np.sum(m * m))
    return total


def _energy_max(op) -> float:
    """Largest R + T over incident ordinates (azimuthally uniform illumination)."""
    alb = op.albedo()
    worst = 0.0
    for r, t in (("Rt", "Ttb"), ("Rb", "Tbt")):
        if r in alb:
            worst = max(worst, float((alb[r] + alb.get(t, 0.0)).max()))
    return worst


class _IsoAlgebra:
    """Per-order dense algebra in the energy basis ``W B_l W^-1``, ``W = diag(sqrt(w mu))``."""

    #: Smallest eps of the automatic search, and the floor applied to a given eps.
    eps_min, eps_floor = EPS_RANGE[0], 0.0

    def __init__(self, stack: IsoOperator, known: IsoOperator, svd: dict | None = None):
        # svd: the SVDs of the known blocks, shared by algebras with the same known layer
        self.stack, self.known = stack, known
        self.grid = stack.grid
        self.h = stack.h
        self.m = max(stack.m, known.m)
        sw = np.sqrt(self.grid.flux_weight)
        self.sw = sw
        self.svd = {} if svd is None else svd

        def hat(op, name):
            if op.blocks[name] is None:
                return None
            return [sw[:, None] * op.block(name, l).toarray() / sw[None, :]
                    for l in range(self.m)]

        self.S = {k: hat(stack, k) for k in BLOCKS}
        self.K = {k: hat(known, k) for k in BLOCKS}

    # -- linear algebra per order
    def _svd_of(self, name, l):
        key = (name, l)
        if key not in self.svd:
            self.svd[key] = np.linalg.svd(self.K[name][l])
        return self.svd[key]

    def pinv(self, name, l, eps):
        """Tikhonov-regularised inverse of the known block ``name`` at order ``l``."""
        U, s, Vt = self._svd_of(name, l)
        f = s / (s * s + eps * eps) if eps > 0 else np.where(s > 0, 1.0 / np.maximum(s, 1e-300),
                                                             0.0)
        return (Vt.T * f[None, :]) @ U.T

    def visibility(self, names, eps=None):
        """(visible fraction at eps, largest transmitted energy) of the known transmissions."""
        fw = self.grid.flux_weight
        energy = 0.0
        vis = 1.0
        for name in names:
            blk = self.known.blocks[name]
            if blk is None:
                continue
            energy = max(energy, float(((blk[0].T @ fw) / fw).max()))
            if eps is not None:
                s = self._svd_of(name, 0)[1]
                vis = min(vis, float(np.sum(s * s / (s * s + eps * eps))) / self.h)
        return vis, energy

    def reciprocity_noise(self) -> float:
        num = den = 0.0
        for name in ("Rt", "Rb"):
            blk = self.S[name]
            if blk is None:
                continue
            for B in blk:
                off = B - np.diag(np.diag(B))
                num += float(np.sum((off - off.T) ** 2))
                den += float(np.sum(off * off))
        return math.sqrt(num / (2.0 * den)) if den > 0 else 0.0

    def perturbed(self, level: float, seed: int):
        """This algebra with independent multiplicative Gaussian noise of relative standard
        deviation ``level`` on every entry of the stack."""
        rng = np.random.default_rng(seed)
        other = copy.copy(self)
        other.S = {k: None if v is None else
                   [B * (1.0 + level * rng.standard_normal(B.shape)) for B in v]
                   for k, v in self.S.items()}
        return other

    def recover(self, side, eps):
        I = np.eye(self.h)
        S, K = self.S, self.K
        out = {k: [] for k in BLOCKS}
        transmissive = S["Ttb"] is not None
        for l in range(self.m):
            if side == "top":
                Rt1, Rb1 = K["Rt"][l], K["Rb"][l]
                X = self.pinv("Tbt", l, eps) @ (S["Rt"][l] - Rt1) @ self.pinv("Ttb", l, eps)
                Rt2 = np.linalg.solve((I + Rb1 @ X).T, X.T).T
                out["Rt"].append(Rt2)
                if transmissive:
                    A = I - Rb1 @ Rt2
                    Ttb2 = S["Ttb"][l] @ self.pinv("Ttb", l, eps) @ A
                    Tbt2 = (I - Rt2 @ Rb1) @ self.pinv("Tbt", l, eps) @ S["Tbt"][l]
                    Rb2 = S["Rb"][l] - Ttb2 @ np.linalg.solve(A, Rb1 @ Tbt2)
                    out["Ttb"].append(Ttb2)
                    out["Tbt"].append(Tbt2)
                    out["Rb"].append(Rb2)
            else:
                Rt2, Rb2 = K["Rt"][l], K["Rb"][l]
                Y = self.pinv("Ttb", l, eps) @ (S["Rb"][l] - Rb2) @ self.pinv("Tbt", l, eps)
                Rb1 = np.linalg.solve((I + Rt2 @ Y).T, Y.T).T
                A = I - Rt2 @ Rb1
                Ttb1 = (I - Rb1 @ Rt2) @ self.pinv("Ttb", l, eps) @ S["Ttb"][l]
                Tbt1 = S["Tbt"][l] @ self.pinv("Tbt", l, eps) @ A
                Rt1 = S["Rt"][l] - Tbt1 @ np.linalg.solve(A, Rt2 @ Ttb1)
                out["Rt"].append(Rt1)
                out["Rb"].append(Rb1)
                out["Ttb"].append(Ttb1)
                out["Tbt"].append(Tbt1)
        return {k: (v if v else None) for k, v in out.items()}

    def to_operator(self, rec, side):
        sw = self.sw
        blocks = {}
        for name in BLOCKS:
            if rec[name] is None:
                blocks[name] = None
                continue
            blocks[name] = np.stack([B / sw[:, None] * sw[None, :] for B in rec[name]])
        if side == "top":
            eta_top, eta_bottom = self.known.eta_bottom, self.stack.eta_bottom
        else:
            eta_top, eta_bottom = self.stack.eta_top, self.known.eta_top
        delta = _delta_quotient(self.stack, self.known)
        return IsoOperator.from_dense(self.grid, blocks, eta_top, eta_bottom, delta)

    def residual(self, rec, side) -> float:
        return self.residual_of(self.to_operator(rec, side), side)

    def residual_of(self, op, side) -> float:
        """Relative re-adding residual of a recovered operator (energy basis)."""
        again = iso_add(self.known, op) if side == "top" else iso_add(op, self.known)
        sw = self.sw
        num = den = 0.0
        for name in BLOCKS:
            if self.stack.blocks[name] is None:
                continue
            for l in range(self.m):
                a = again.block(name, l).toarray()
                b = self.stack.block(name, l).toarray()
                d = sw[:, None] * (a - b) / sw[None, :]
                num += float(np.sum(d * d))
                den += float(np.sum((sw[:, None] * b / sw[None, :]) ** 2))
        return math.sqrt(num / den) if den > 0 else 0.0

    negativity = staticmethod(negativity)

    energy_max = staticmethod(_energy_max)


def _delta_quotient(stack, known) -> dict:
    """Unscattered transmission of the recovered layer: the stack's divided by the known
    layer's (present only if both have one)."""
    out = {}
    for name in ("Ttb", "Tbt"):
        if name in stack.delta and name in known.delta:
            k = known.delta[name]
            out[name] = np.where(k > 0, stack.delta[name] / np.where(k > 0, k, 1.0), 0.0)
    return out


class _AnisoAlgebra:
    """Sparse algebra on coupled-mode operators (slot basis), banded solves."""

    #: Smallest eps of the automatic search, and the floor applied to a given eps.
    eps_min = eps_floor = EPS_MIN_ANISO

    def __init__(self, stack, known):
        md = max(stack.m, known.m)
        self.stack, self.known = stack.as_coupled(md), known.as_coupled(md)
        self.md = md
        self.grid = stack.grid
        self.h = stack.grid.h
        scale = np.sqrt(np.where(np.arange(basis.n_slots(md)) == 0, 2.0, 1.0))
        w = np.kron(scale, np.sqrt(self.grid.flux_weight))
        self.W = sps.diags(w)
        self.Winv = sps.diags(1.0 / w)
        self.N = w.size
        self.S = {k: self._hat(self.stack, k) for k in BLOCKS}
        self.K = {k: self._hat(self.known, k) for k in BLOCKS}
        self._normal = {}

    def _hat(self, op, name):
        if op.blocks[name] is None:
            return None
        return sps.csr_matrix(self.W @ op.blocks[name] @ self.Winv)

    def _solve(self, A, B):
        return banded_solve(A, B, self.h, self.md, what="the subtracting equations")

    def left_pinv(self, name, M, eps):
        """``T^+ M`` for the known block ``name``."""
        T = self.K[name]
        A = sps.csr_matrix(T.T @ T) + (eps * eps) * sps.identity(self.N, format="csr")
        return self._solve(A, T.T @ M)

    def right_pinv(self, name, M, eps):
        """``M T^+ = M (T^T T + eps^2)^-1 T^T``."""
        T = self.K[name]
        A = sps.csr_matrix(T.T @ T) + (eps * eps) * sps.identity(self.N, format="csr")
        Z = self._solve(A, sps.csr_matrix(M.T)).T
        return sps.csr_matrix(Z @ T.T)

    def right_solve(self, M, A):
        """``M A^-1``."""
        return sps.csr_matrix(self._solve(sps.csr_matrix(A.T), sps.csr_matrix(M.T)).T)

    def visibility(self, names, eps=None):
        fw = self.grid.flux_weight
        h = self.h
        energy = 0.0
        vis = 1.0
        for name in names:
            T = self.known.blocks[name]
            if T is None:
                continue
            energy = max(energy, float(((T[:h, :h].T @ fw) / fw).max()))
            if eps is not None:
                s = np.linalg.svd(self.K[name][:h, :h].toarray(), compute_uv=False)
                vis = min(vis, float(np.sum(s * s / (s * s + eps * eps))) / h)
        return vis, energy

    def reciprocity_noise(self) -> float:
        num = den = 0.0
        for name in ("Rt", "Rb"):
            B = self.S[name]
            if B is None:
                continue
            off = B - sps.diags(B.diagonal())
            num += _frob2([sps.csr_matrix(off - off.T)])
            den += _frob2([sps.csr_matrix(off)])
        return math.sqrt(num / (2.0 * den)) if den > 0 else 0.0

    def perturbed(self, level: float, seed: int):
        """This algebra with independent multiplicative Gaussian noise of relative standard
        deviation ``level`` on every stored entry of the stack."""
        rng = np.random.default_rng(seed)
        other = copy.copy(self)

        def noisy(mat):
            out = mat.copy()
            out.data = out.data * (1.0 + level * rng.standard_normal(out.data.size))
            return out

        other.S = {k: None if v is None else noisy(v) for k, v in self.S.items()}
        return other

    def recover(self, side, eps):
        I = sps.identity(self.N, format="csr")
        S, K = self.S, self.K
        out = dict.fromkeys(BLOCKS)
        p = lambda m: prune(m, DROP_TOLERANCE * 1e-3)
        if side == "top":
            Rt1, Rb1 = K["Rt"], K["Rb"]
            X = self.right_pinv("Ttb", self.left_pinv("Tbt", S["Rt"] - Rt1, eps), eps)
            Rt2 = p(self.right_solve(X, I + Rb1 @ X))
            out["Rt"] = Rt2
            if S["Ttb"] is not None:
                A = sps.csr_matrix(I - Rb1 @ Rt2)
                Ttb2 = p(self.right_pinv("Ttb", S["Ttb"], eps) @ A)
                Tbt2 = p((I - Rt2 @ Rb1) @ self.left_pinv("Tbt", S["Tbt"], eps))
                Rb2 = S["Rb"] - Ttb2 @ self._solve(A, Rb1 @ Tbt2)
                out.update(Ttb=Ttb2, Tbt=Tbt2, Rb=p(Rb2))
        else:
            Rt2, Rb2 = K["Rt"], K["Rb"]
            Y = self.right_pinv("Tbt", self.left_pinv("Ttb", S["Rb"] - Rb2, eps), eps)
            Rb1 = p(self.right_solve(Y, I + Rt2 @ Y))
            A = sps.csr_matrix(I - Rt2 @ Rb1)
            Ttb1 = p((I - Rb1 @ Rt2) @ self.left_pinv("Ttb", S["Ttb"], eps))
            Tbt1 = p(self.right_pinv("Tbt", S["Tbt"], eps) @ A)
            Rt1 = S["Rt"] - Tbt1 @ self._solve(A, Rt2 @ Ttb1)
            out.update(Rt=p(Rt1), Rb=Rb1, Ttb=Ttb1, Tbt=Tbt1)
        return out

    def to_operator(self, rec, side):
        blocks = {k: None if v is None else prune(self.Winv @ v @ self.W, DROP_TOLERANCE)
                  for k, v in rec.items()}
        if side == "top":
            eta_top, eta_bottom = self.known.eta_bottom, self.stack.eta_bottom
        else:
            eta_top, eta_bottom = self.stack.eta_top, self.known.eta_top
        return AnisoOperator(self.grid, self.md, blocks, eta_top, eta_bottom,
                             _delta_quotient(self.stack, self.known))

    def residual(self, rec, side) -> float:
        return self.residual_of(self.to_operator(rec, side), side)

    def residual_of(self, op, side) -> float:
        """Relative re-adding residual of a recovered operator (energy basis)."""
        op = op.as_coupled(self.md)
        again = coupled_add(self.known, op) if side == "top" else coupled_add(op, self.known)
        num = den = 0.0
        for name in BLOCKS:
            if self.stack.blocks[name] is None:
                continue
            d = self.W @ (again.blocks[name] - self.stack.blocks[name]) @ self.Winv
            num += _frob2([sps.csr_matrix(d)])
            den += _frob2([self.S[name]])
        return math.sqrt(num / den) if den > 0 else 0.0

    negativity = staticmethod(negativity)

    energy_max = staticmethod(_energy_max)


#: The algebra of each representation (:func:`layersim.operators.operator.common_representation` of
#: the stack and the known layer).
_ALGEBRAS = {"isotropic": _IsoAlgebra, "anisotropic": _AnisoAlgebra}
