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

__all__ = ["energy_kernel", "kept_energy_factors", "match_kept_energy", "FACTOR_RANGE"]

#: Bounds of each factor: a node whose projected energy is far from the target stays within
#: them rather than amplify a near-empty column.
FACTOR_RANGE = (0.5, 2.0)

_ITERATIONS = 200
_TINY = 1e-12


def energy_kernel(op, name: str) -> np.ndarray:
    """``K[o, i] = B[o, i] w_o mu_o / (w_i mu_i)`` of block ``name``'s slot-0 rows and columns
    (h, h): the energy for uniform illumination from node ``i`` is ``K[:, i].sum()``
    (:meth:`layersim.aniso.operator.AnisoOperator.albedo_slots`)."""
    h, fw = op.h, op.grid.flux_weight
    block = op.blocks[name][:h, :h].toarray()
    return block * fw[:, None] / fw[None, :]


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
    A = sps.diags(np.tile(a, op.blocks["Rt"].shape[0] // op.h))
    blocks = dict(op.blocks)
    blocks["Rb"] = sps.csr_matrix(A @ blocks["Rb"] @ A)
    blocks["Ttb"] = sps.csr_matrix(A @ blocks["Ttb"])
    blocks["Tbt"] = sps.csr_matrix(blocks["Tbt"] @ A)
    return (type(op)(op.grid, op.md, blocks, op.eta_top, op.eta_bottom, op.delta, ms=op.ms), a)
