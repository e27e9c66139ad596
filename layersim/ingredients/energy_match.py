"""Reciprocal rescaling of an interface operator to a given loss per inside elevation.

An operator projected for a slightly rougher interface (a brushed coat's narrow roughness
raised, :mod:`layersim.layers.brushed`) loses more energy to the microsurface (the
single-scattering loss ``1 - E_R - E_T``, Heitz 2014, sec. 5) than the interface itself, most
at grazing inside angles, where light trapped by total internal reflection between a coat and
its base meets the coat many times: the differences add up in the stack's albedo. This module
rescales the blocks the light inside the coat sees by one diagonal factor over the inside
ordinates (the same in every azimuthal slot), which keeps reciprocity exactly (the pattern of
:func:`layersim.operators.energy.limit_energy`)::

    Rb' = A Rb A          Ttb' = A Ttb          Tbt' = Tbt A

``A`` is found by a symmetric Sinkhorn iteration (Sinkhorn & Knopp 1967) so that the energy
that inside light keeps, ``E_Rb + E_Tbt`` for azimuthally uniform illumination
(:meth:`layersim.operators.operator.Operator.albedo`), becomes the target's. How that energy
splits between reflection and transmission stays the projected operator's: matching the split
as well needs factors that no longer keep each block's angular shape
(``benchmarks/features/brushed_coats.txt`` says what is left).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

__all__ = ["energy_kernel", "kept_energy_factors", "match_kept_energy", "two_sided_factors",
           "scaled_block", "rescaled", "diag_scaled", "FACTOR_RANGE"]

#: Bounds of each factor: a node whose projected energy is far from the target stays within
#: them rather than amplify a near-empty column.
FACTOR_RANGE = (0.5, 2.0)

_ITERATIONS = 200
_TINY = 1e-12


def energy_kernel(op, name: str) -> np.ndarray:
    """``K[o, i] = B[o, i] w_o mu_o / (w_i mu_i)`` of block ``name``'s azimuthally uniform part
    (h, h; :func:`_slot0`): the energy for uniform illumination from node ``i`` is
    ``K[:, i].sum()`` (:meth:`layersim.aniso.operator.AnisoOperator.albedo_slots`)."""
    fw = op.grid.flux_weight
    return _slot0(op, name).toarray() * fw[:, None] / fw[None, :]


def kept_energy_factors(K_refl: np.ndarray, K_trans: np.ndarray,
                        target: np.ndarray) -> np.ndarray:
    """Factors ``a`` (h,) with ``a_i (sum_o a_o K_refl[o, i] + sum_o K_trans[o, i]) =
    target_i``: reflection scaled on both sides, transmission on its incident side, within
    :data:`FACTOR_RANGE` (the square root damps the symmetric update)."""
    a = np.ones(K_refl.shape[0])
    leave = K_trans.sum(axis=0)
    for _ in range(_ITERATIONS):
        kept = a * (a @ K_refl + leave)
        ratio = np.where(kept > _TINY, target / np.maximum(kept, _TINY), 1.0)
        a = np.clip(a * np.sqrt(ratio), *FACTOR_RANGE)
    return a


def match_kept_energy(op, kept: np.ndarray):
    """The transmissive operator ``op`` (blocks in the slot layout ``slot * h + node``, either
    representation's) rescaled so that the energy inside light keeps, ``E_Rb + E_Tbt`` at each
    inside node, is ``kept`` (h,); ``Rt`` and the outside side of ``Ttb`` and ``Tbt`` are
    kept.

    Returns
    -------
    (operator, ndarray)
        The rescaled operator (same class) and the factors ``A`` (h,).
    """
    a = kept_energy_factors(energy_kernel(op, "Rb"), energy_kernel(op, "Tbt"), kept)
    A = np.tile(a, op.blocks["Rt"].shape[0] // op.h)
    blocks = dict(op.blocks)
    blocks["Rb"] = diag_scaled(blocks["Rb"], A, A)
    blocks["Ttb"] = diag_scaled(blocks["Ttb"], A, None)
    blocks["Tbt"] = diag_scaled(blocks["Tbt"], None, A)
    return (type(op)(op.grid, op.md, blocks, op.eta_top, op.eta_bottom, op.delta, ms=op.ms), a)


def _slot0(op, name: str):
    """Block ``name``'s azimuthally uniform part (h, h): order 0 of an isotropic operator,
    the slot-0 rows and columns of a coupled one."""
    blk = op.blocks[name]
    return blk[0] if op.representation == "isotropic" else blk[:op.h, :op.h]


def two_sided_factors(op, transmitted_top: np.ndarray, kept_bottom: np.ndarray,
                      sweeps: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """Factors ``(a_top, a_bottom)`` (h,) each, within :data:`FACTOR_RANGE`, such that the
    transmissive operator ``op`` rescaled by :func:`rescaled` transmits ``transmitted_top``
    of light from above (``a_top_i sum_o a_bottom_o Kttb[o, i]``) and keeps
    ``kept_bottom`` of light from below (``E_Rb + E_Tbt``), per node.

    Within a few ordinates of a critical angle from above the raised interface transmits where
    the interface itself does not (or far less), and the factor stops at the range's bound.
    Alternates the closed-form top update with the Sinkhorn update of
    :func:`kept_energy_factors` on the bottom side (the top factors scale the rows of ``Tbt``
    that the bottom side sees).
    """
    Kttb, Krb, Ktbt = (energy_kernel(op, n) for n in ("Ttb", "Rb", "Tbt"))
    a_top, a_bot = np.ones(op.h), np.ones(op.h)
    for _ in range(sweeps):
        a_bot = kept_energy_factors(Krb, a_top[:, None] * Ktbt, kept_bottom)
        sent = a_bot @ Kttb
        a_top = np.clip(np.where(sent > _TINY, transmitted_top / np.maximum(sent, _TINY), 1.0),
                        *FACTOR_RANGE)
    return a_top, a_bot


def scaled_block(op, name: str, left: np.ndarray, right: np.ndarray):
    """Block ``name`` of ``op`` (either representation) as ``diag(left) B diag(right)`` in
    every Fourier order or slot (``left``, ``right``: (h,) factors on the outgoing and incident
    nodes)."""
    iso = op.representation == "isotropic"
    slots = 1 if iso else op.blocks["Rt"].shape[0] // op.h
    L, R = (np.tile(a, slots) for a in (left, right))
    blk = op.blocks[name]
    return [diag_scaled(b, L, R) for b in blk] if iso else diag_scaled(blk, L, R)


def diag_scaled(B, left: np.ndarray | None, right: np.ndarray | None):
    """``diag(left) B diag(right)`` (CSR; a factor None is the identity), scaling a copy of
    ``B``'s stored entries in place: the same products as the sparse ones, without their
    symbolic pass and temporaries (on a coupled coat's blocks, 1e8 entries, seconds)."""
    B = sps.csr_matrix(B, copy=True)
    if left is not None:
        B.data *= np.repeat(np.asarray(left, float), np.diff(B.indptr))
    if right is not None:
        B.data *= np.asarray(right, float)[B.indices]
    return B


def rescaled(op, a_top: np.ndarray, a_bottom: np.ndarray, Rt, Rt_delta=None):
    """``op`` (either representation) with every block scaled on its top-side nodes by
    ``a_top`` and its bottom-side nodes by ``a_bottom`` (the same in every Fourier order or
    slot), which keeps reciprocity exactly::

        Ttb' = A_b Ttb A_t     Tbt' = A_t Tbt A_b     Rb' = A_b Rb A_b

    and ``Rt`` replaced by ``Rt`` (the representation's block, with its delta ``Rt_delta``
    (h,) or none); the scattered parts carry no delta."""
    scale = {"Ttb": (a_bottom, a_top), "Tbt": (a_top, a_bottom), "Rb": (a_bottom, a_bottom)}
    blocks = {name: scaled_block(op, name, *lr) for name, lr in scale.items()}
    blocks["Rt"] = Rt
    delta = {k: v for k, v in op.delta.items() if k not in scale and k != "Rt"}
    if Rt_delta is not None:
        delta["Rt"] = Rt_delta
    if op.representation == "isotropic":
        return type(op)(op.grid, blocks, op.eta_top, op.eta_bottom, delta)
    return type(op)(op.grid, op.md, blocks, op.eta_top, op.eta_bottom, delta, ms=op.ms)
