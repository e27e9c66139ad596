"""What a stack determines of a layer recovered by the subtracting equations (Zeltner & Jakob
2018 sec. 3.4, eq. (13)-(16)), and the rule that fills what it does not.

The unknown layer is seen through the known one. On the side facing the known layer, light of
the stack reaches the unknown layer only in the directions that the known layer's transmissions
resolve: below a dielectric coating not beyond its critical angle (widened by its roughness),
below a medium not where ``exp(-tau / mu)`` and the scattered light vanish. Three sets of
ordinates (in ``mu``, in the medium between the two layers, on the unknown layer's side facing
the known one; its other side is seen directly by the stack) follow:

**Reached** ordinates: the visibility ``v_j = sum_k f_k U_jk^2`` (``U`` the singular vectors of
the known layer's order-0 transmission in the energy basis on that side, ``f_k = s_k^2 / (s_k^2
+ eps^2)`` the Tikhonov filter factors of the subtraction) is at least :data:`REACHED`, for
light going in and for light coming out.

**Hidden** ordinates (not reached): the data say nothing about them. Their values are *filled*
by continuation of the BSDF coefficients ``f_l(mu_o, mu_i)`` from the lowest reached ordinate
``k``: constant in the hidden ``mu`` where one direction is on that side, and along the diagonal
where both are (``(o, i) <- (o + d, i + d)``, ``d = k - min(o, i)``), which keeps a reflection's
specular ridge on ``mu_o = mu_i`` and keeps reciprocity: :func:`fill`.

**Determined** ordinates: those above a ``mu_min`` where the recovery is estimated to be within
the tolerance (relative L2 in the energy basis over all orders and blocks, directions with
``mu > mu_min`` on that side and all directions on the other side). Being reached is not
enough: light that the unknown layer scatters into hidden directions (e.g. into the total
internal reflection range of a coating) is sent back to it by the known layer and leaves through
reached ones, so the hidden part of the unknown layer couples into what the stack shows of the
reached part. The estimate is a simulation of the recovery: the recovered layer, filled, is
added to the known layer again and subtracted with the same ``eps``; what that round trip
changes is the error of the subtraction for a layer like the recovered one
(:func:`assess`).

**Correction** (isotropic operators, data without noise): the light returned through hidden
directions is removed by a damped fixed-point iteration for a layer whose round trip reproduces
the recovery (:func:`correct`), to the accuracy of the fill. The declared set is still the one
that the estimate for the uncorrected recovery gives (conservative). With noise the correction
is not applied: it undoes part of the Tikhonov filter and would amplify the noise.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sps

from ..aniso.operator import AnisoOperator
from ..operators.operator import BLOCKS, IsoOperator

#: Smallest visibility of a reached ordinate (fraction of a unit ordinate vector that the known
#: layer's transmission passes at the subtraction's eps).
REACHED = 0.5
#: Relative L2 error (energy basis) below which the recovery counts as determined, without noise.
TOLERANCE = 1e-3
#: Step size and largest number of steps of the correction for light returned through hidden
#: directions (:func:`correct`).
DAMPING, CORRECT_STEPS = 0.5, 8

#: Per block, which of its indices lie on the unknown layer's side facing the known layer
#: ("rows": outgoing, "cols": incident), for the known layer on top / at the bottom.
FACING = {
    "top": {"Rt": ("rows", "cols"), "Ttb": ("cols",), "Tbt": ("rows",), "Rb": ()},
    "bottom": {"Rb": ("rows", "cols"), "Ttb": ("rows",), "Tbt": ("cols",), "Rt": ()},
}

#: What the recovered layer holds in hidden directions (printed by ``layersim subtract``).
FILL_RULE = ("hidden directions hold a continuation of the BSDF coefficients from the lowest "
             "reached direction (along mu_o = mu_i where both directions are on that side; not "
             "measured)")


@dataclass
class Determined:
    """What the stack determines of a recovered layer (module docstring).

    Attributes
    ----------
    side : {"top", "bottom"}
        The recovered layer's side facing the known layer (where ordinates can be hidden).
    ior : float
        Index of the medium between the two layers (where ``mu`` is measured).
    mu_reached : float or None
        Lowest reached ``mu`` (None: none reached).
    mu_min : float or None
        Directions with ``mu >= mu_min`` on ``side`` (and all on the other side) are
        determined; None: no direction is.
    error : float
        Estimated relative L2 error over the determined directions (over the reached ones when
        none is determined).
    tolerance : float
        The tolerance ``mu_min`` was chosen for.
    corrected : bool
        Whether the defect correction was applied.
    estimates : list of (float, float)
        ``(mu, estimated error over the directions with mu' >= mu)`` for the reached ordinates.
    """

    side: str
    ior: float
    mu_reached: float | None
    mu_min: float | None
    error: float
    tolerance: float
    corrected: bool = False
    estimates: list = field(default_factory=list)
    reached: np.ndarray = field(default=None, repr=False)
    #: Estimated error over the directions with ordinate index >= k, for every k; shape (h,).
    errors: np.ndarray = field(default=None, repr=False)

    def as_dict(self) -> dict:
        """JSON-friendly form for ``info["subtract"]["determined"]``."""
        def deg(mu):
            return None if mu is None else float(np.degrees(np.arccos(min(1.0, mu))))
        return {"side": self.side, "ior": self.ior, "mu_min": self.mu_min,
                "theta_max_deg": deg(self.mu_min), "mu_reached": self.mu_reached,
                "theta_reached_deg": deg(self.mu_reached), "error": self.error,
                "tolerance": self.tolerance, "corrected": self.corrected,
                "other_side": "all directions", "fill": FILL_RULE,
                "estimates": [list(p) for p in self.estimates]}


def describe(d: dict) -> str:
    """One paragraph for the command line from :meth:`Determined.as_dict`."""
    where = f"on its {d['side']} side, in the medium of index {d['ior']:g}"
    if d["mu_min"] is None:
        det = (f"no direction is determined to {d['tolerance']:.2g} {where} (estimated error "
               f"{d['error']:.2g} over the reached directions)")
    else:
        det = (f"determined: theta < {d['theta_max_deg']:.1f} deg (mu >= {d['mu_min']:.3f}) "
               f"{where}, all directions on the other side (estimated error {d['error']:.2g}, "
               f"tolerance {d['tolerance']:.2g})")
    if d["mu_reached"] is None:
        reach = "no direction is reached through the known layer"
    else:
        reach = (f"reached through the known layer: theta < {d['theta_reached_deg']:.1f} deg; "
                 + d["fill"])
    corr = "; corrected for light returned through hidden directions" if d["corrected"] else ""
    return f"{det}; {reach}{corr}"


def visibility(known: IsoOperator, side: str, eps: float) -> np.ndarray:
    """Per ordinate of the medium between the layers, the fraction of light that the known
    layer's order-0 transmissions pass in both directions at Tikhonov parameter ``eps``
    (``sum_k f_k U_jk^2``, energy basis); shape (h,)."""
    sw = np.sqrt(known.grid.flux_weight)
    into, out_of = ("Ttb", "Tbt") if side == "top" else ("Tbt", "Ttb")
    vis = []
    for name, left in ((into, True), (out_of, False)):
        T = sw[:, None] * known.block(name, 0).toarray() / sw[None, :]
        U, s, Vt = np.linalg.svd(T)
        f = s * s / (s * s + eps * eps) if eps > 0 else (s > 0).astype(float)
        vecs = U if left else Vt.T
        vis.append((vecs * vecs) @ f)
    return np.minimum(*vis)


def continuation(reached: np.ndarray, where: tuple) -> tuple:
    """Source ordinates ``(src_o, src_i)``, shape (h, h) each, of the fill of a block whose
    facing indices are ``where``: a one-sided block continues the lowest reached ordinate ``k``
    (constant in the hidden ``mu``); a two-sided block continues along the diagonal,
    ``(o, i) <- (o + d, i + d)`` with ``d = k - min(o, i)``, so that the specular ridge
    ``mu_o = mu_i`` of a reflection stays on it."""
    h = reached.size
    o, i = np.meshgrid(np.arange(h), np.arange(h), indexing="ij")
    if not reached.any():
        return o, i
    k = int(np.argmax(reached))
    hidden = np.arange(h) < k
    if "rows" in where and "cols" in where:
        d = np.maximum(k - np.minimum(o, i), 0)
        return np.minimum(o + d, h - 1), np.minimum(i + d, h - 1)
    if "rows" in where:
        return np.where(hidden[:, None], k, o), i
    if "cols" in where:
        return o, np.where(hidden[None, :], k, i)
    return o, i


def _fill_matrix(mat, src: tuple, fw: np.ndarray, delta=None):
    """A block (one order, or all slots of a coupled block) with entry ``(o, i)`` of every slot
    pair taken from ``src`` as BSDF coefficients (entries over the incident flux weight ``w
    mu``), one slot row of ``h`` rows at a time. An unscattered delta stays where it is: only
    the scattered part is continued."""
    h = fw.size
    n = mat.shape[0]
    S = n // h
    src_o, src_i = src
    if np.array_equal(src_o, np.arange(h)[:, None] + 0 * src_o) and \
            np.array_equal(src_i, np.arange(h)[None, :] + 0 * src_i):
        return mat
    D = sps.diags(np.tile(delta, S)) if delta is not None else None
    mat = (mat if D is None else mat - D).tocsr()
    ratio = (fw[None, :] / fw[src_i])[:, None, :]                     # (h, 1, h)
    slots = np.arange(S)[None, :, None]
    rows = []
    for s in range(S):
        chunk = mat[s * h:(s + 1) * h].toarray().reshape(h, S, h)
        new = chunk[src_o[:, None, :], slots, src_i[:, None, :]] * ratio
        rows.append(sps.csr_matrix(new.reshape(h, n)))
    out = sps.vstack(rows, format="csr")
    return out if D is None else (out + D).tocsr()


def _map_iso(op, fn):
    blocks = {k: None if v is None else [fn(b, k) for b in v] for k, v in op.blocks.items()}
    return IsoOperator(op.grid, blocks, op.eta_top, op.eta_bottom, op.delta)


def _map_coupled(op, fn):
    blocks = {k: None if v is None else fn(v, k) for k, v in op.blocks.items()}
    return AnisoOperator(op.grid, op.md, blocks, op.eta_top, op.eta_bottom, op.delta, ms=op.ms)


#: Block by block map of an operator, ``fn(matrix, block name)`` on each order's matrix
#: (isotropic) or the whole coupled matrix.
_MAP = {"isotropic": _map_iso, "anisotropic": _map_coupled}


def fill(op, reached: np.ndarray, side: str):
    """``op`` with its hidden ordinates (``~reached``, on ``side``) filled by constant
    continuation of the BSDF coefficients (module docstring)."""
    fw, facing = op.grid.flux_weight, FACING[side]
    return _MAP[op.representation](op, lambda mat, name: _fill_matrix(
        mat, continuation(reached, facing[name]), fw, op.delta.get(name)))


def restrict(op, mu_min: float | None, side: str):
    """``op`` with the entries of the directions below ``mu_min`` on ``side`` set to zero (all
    of its facing entries if ``mu_min`` is None): the determined part, e.g. to judge its
    negative lobes."""
    h = op.grid.h
    keep = np.zeros(h) if mu_min is None else (op.grid.mu >= mu_min).astype(float)
    facing = FACING[side]

    def mask(mat, name):
        S = mat.shape[0] // h
        k = np.tile(keep, S)
        out = mat.tocsr()
        if "rows" in facing[name]:
            out = out.multiply(k[:, None]).tocsr()
        if "cols" in facing[name]:
            out = out.multiply(k[None, :]).tocsr()
        return out
    return _MAP[op.representation](op, mask)


def _matrices(op, name: str, orders: int) -> list:
    """The matrices of block ``name``: one per order (isotropic) or the coupled one."""
    if op.representation == "isotropic":
        return [op.block(name, l) for l in range(orders)]
    return [op.blocks[name]]


def _cut_sums(mat, sw: np.ndarray, where: tuple) -> np.ndarray:
    """``sum`` of the squared energy-basis entries of a sparse block (one order, or all slots)
    over the ordinates ``>= k`` on the facing axes, for every ``k``; shape (h,)."""
    h = sw.size
    coo = sps.coo_matrix(mat)
    o, i = coo.row % h, coo.col % h
    v2 = (coo.data * sw[o] / sw[i]) ** 2
    if "rows" in where and "cols" in where:
        first = np.minimum(o, i)
    elif "rows" in where:
        first = o
    elif "cols" in where:
        first = i
    else:
        first = np.full(o.size, h - 1)
    hist = np.bincount(first, weights=v2, minlength=h)
    return np.cumsum(hist[::-1])[::-1]


def norm_by_cut(a, side: str) -> np.ndarray:
    """L2 norm (energy basis, all orders or coupled slots, all blocks) of operator ``a`` over
    the directions with ordinate index ``>= k`` on ``side`` (all on the other side), for every
    ``k``; shape (h,)."""
    sw = np.sqrt(a.grid.flux_weight)
    total = np.zeros(a.grid.h)
    for name in BLOCKS:
        if a.blocks[name] is not None:
            for A in _matrices(a, name, a.m):
                total += _cut_sums(A, sw, FACING[side][name])
    return np.sqrt(total)


def error_by_cut(a, b, side: str) -> np.ndarray:
    """Relative L2 distance (energy basis, all orders or coupled slots, all blocks) of operator
    ``a`` from ``b`` (same representation) over the directions with ordinate index ``>= k`` on
    ``side`` (all on the other side), for every ``k``; shape (h,)."""
    sw = np.sqrt(a.grid.flux_weight)
    num, den = np.zeros(a.grid.h), np.zeros(a.grid.h)
    orders = max(a.m, b.m)
    for name in BLOCKS:
        if b.blocks[name] is None:
            continue
        for A, B in zip(_matrices(a, name, orders), _matrices(b, name, orders)):
            num += _cut_sums(A - B, sw, FACING[side][name])
            den += _cut_sums(B, sw, FACING[side][name])
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, np.sqrt(num / np.where(den > 0, den, 1.0)), np.inf)


def assess(known: IsoOperator, recovered: IsoOperator, side: str, eps: float, round_trip,
           tolerance: float = TOLERANCE, correct_hidden: bool = False, spread=None):
    """Reached, determined and hidden ordinates of a recovered layer (module docstring).

    Parameters
    ----------
    known, recovered : IsoOperator
        The known layer and the recovered one (rotational averages of anisotropic operators:
        the estimate is made on the azimuthal mean; the subtraction then replaces it, for its
        final report, by one made in the coupled algebra, which the average under-reports).
    side : {"top", "bottom"}
        Where the known layer sits in the stack.
    eps : float
        The Tikhonov parameter of the subtraction (energy basis).
    round_trip : callable
        ``round_trip(layer) -> IsoOperator``: the same subtraction (same ``eps``) applied to the
        known layer added to ``layer``.
    tolerance : float
        Relative L2 error (energy basis) up to which directions count as determined.
    spread : ndarray, optional
        The noise part of the error per cut (shape (h,)), added in quadrature to the estimate.
    correct_hidden : bool
        Also return the layer corrected for light returned through hidden directions
        (:func:`correct`).

    Returns
    -------
    determined : Determined
    filled : IsoOperator
        ``recovered`` with its hidden ordinates filled.
    corrected : IsoOperator or None
        The filled layer after :func:`correct` if ``correct_hidden``, else None.
    """
    grid = known.grid
    reached = visibility(known, side, eps) >= REACHED
    ior = float(known.eta_bottom if side == "top" else known.eta_top)
    filled = fill(recovered, reached, side)
    if not reached.any():
        return Determined(side, ior, None, None, np.inf, tolerance, reached=reached), filled, None
    again = round_trip(filled)
    est = error_by_cut(again, filled, side)
    if spread is not None:
        est = np.hypot(est, spread)
    det = declare(grid, reached, est, tolerance, side, ior)
    corrected = correct(recovered, reached, side, round_trip, again) if correct_hidden else None
    return det, filled, corrected


def declare(grid, reached: np.ndarray, est: np.ndarray, tolerance: float, side: str,
            ior: float) -> Determined:
    """The determined set from the estimated error ``est`` per cut (shape (h,), relative L2
    over the directions with ordinate index ``>= k``): ``{mu >= mu_k}`` for the smallest ``k``
    at or above the lowest reached ordinate whose every subset ``{mu >= mu_j}``, ``j >= k``, is
    within ``tolerance``."""
    lowest = int(np.argmax(reached))
    ok = est <= tolerance
    ok[:lowest] = False
    k = next((j for j in range(grid.h) if ok[j:].all()), None)
    mu = grid.mu
    return Determined(side, ior, float(mu[lowest]), None if k is None else float(mu[k]),
                      float(est[lowest] if k is None else est[k]), tolerance,
                      estimates=[(float(mu[j]), float(est[j])) for j in range(lowest, grid.h)],
                      reached=reached, errors=est)


def correct(recovered: IsoOperator, reached: np.ndarray, side: str, round_trip,
            again: IsoOperator | None = None) -> IsoOperator:
    """Remove from a recovered layer the light that the stack returned through hidden
    directions, to the accuracy of the fill: the damped fixed-point iteration
    ``L <- L + DAMPING (L0 - S(fill(L)))`` (``L0`` the recovery, ``S`` the round trip) for a
    layer whose round trip reproduces the recovery, at most :data:`CORRECT_STEPS` steps; the
    step with the smallest mismatch ``||L0 - S(fill(L))||`` is kept (undamped steps overshoot
    where the hidden paths carry more than a few per cent of the signal). Returns the filled
    layer."""
    best, best_mismatch = fill(recovered, reached, side), np.inf
    layer = recovered
    lowest = int(np.argmax(reached))
    for _ in range(CORRECT_STEPS):
        filled = fill(layer, reached, side)
        again = round_trip(filled) if again is None else again
        mismatch = float(error_by_cut(again, recovered, side)[lowest])
        if mismatch >= best_mismatch:
            break
        best, best_mismatch = filled, mismatch
        layer = _combine(layer, (recovered, again), DAMPING)
        again = None
    return best


def _combine(a: IsoOperator, bc: tuple, damping: float) -> IsoOperator:
    """``a + damping (b - c)`` block by block (isotropic operators on one grid)."""
    b, c = bc
    m = max(a.m, b.m, c.m)
    blocks = {name: None if a.blocks[name] is None else
              np.stack([(a.block(name, l) + damping * (b.block(name, l) - c.block(name, l)))
                        .toarray() for l in range(m)]) for name in BLOCKS}
    return IsoOperator.from_dense(a.grid, blocks, a.eta_top, a.eta_bottom, a.delta)
