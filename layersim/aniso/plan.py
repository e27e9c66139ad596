"""Planning of anisotropic stacks: the coupling width ``ms`` per layer, the pre-pass of the
Fourier orders of anisotropic interfaces, and memory estimates.

``ms`` (coupling half-width, modes ``s in [-ms, ms]`` of the azimuth sum) grows with the
roughness ratio ``r = max(alpha_u / alpha_v, alpha_v / alpha_u)``. Seed 000 eq. (25) fits
``ms = ceil(2.58 r - 1.82)`` as the smallest ``ms`` with a relative L2 error below 1 %; our own
study (``benchmarks/ms_study.py``: cosine-weighted L2 norm of the truncated ``f_{d,s}`` of
Beckmann and GGX conductors and dielectrics, relative to the untruncated series) is summarised
by :data:`MS_SLOPE`, :data:`MS_OFFSET`. Isotropic layers (``r = 1``) need ``ms = 0``, and a stack
pays for coupling only if one of its layers is anisotropic.
"""

from __future__ import annotations

import math

import numpy as np

#: ms = ceil(MS_SLOPE * r + MS_OFFSET) for r > 1 (see module docstring).
MS_SLOPE, MS_OFFSET = 2.58, -1.82
#: Target of the ms rule: relative (cosine-weighted) L2 error of the dropped coefficients.
MS_TARGET = 0.01


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


def interface_prepass(grid, layer, eta_above: float, ms: int, relerr: float):
    """Series lengths (in ``phi_d``) of the significant ordinate pairs of an anisotropic
    interface (maximum over ``phi_s``) and whether both elevations are within the plan's
    ``THETA_FULL``: the same quantities as the isotropic pre-pass, from one cheap kernel pass
    per block (:func:`layersim.ingredients.aniso_microfacet.coarse_lengths`)."""
    from ..ingredients.aniso_microfacet import coarse_lengths
    return coarse_lengths(grid, layer, eta_above, ms, relerr)


def operator_entries(lengths: np.ndarray, md: int, ms: int) -> int:
    """Estimated nonzeros of an anisotropic interface operator in the slot basis: per pair
    ``(2 min(len, md) - 1) (2 ms + 1)`` complex coefficients, about one real entry each."""
    return int(np.sum((2 * np.minimum(lengths, md) - 1) * (2 * ms + 1)))


def factor_bytes(h: int, md: int, ms_total: int) -> int:
    """Upper estimate of the dense block-LU factors of the adding equations: two components
    per parity (cosine and sine) of ``md / 2`` orders, a band of ``ms_total`` orders each side,
    blocks of at most ``h`` active ordinates (half of them on average: high orders only
    scatter near grazing)."""
    blocks = max(1, md // 2)
    band = 2 * ms_total + 1
    return int(4 * blocks * band * (0.5 * h) ** 2 * 8)
