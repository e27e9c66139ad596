"""Kernel that evaluates tabulated Fourier BSDFs: each query sums the cosine series of up to 16
neighbouring ordinate pairs (spline weights prepared by the host).

Series layout (shared with :class:`layersim.solved.bsdf.BSDF` and the ``.bsdf`` export): pair ``p``
owns ``coef[offsets[p]:offsets[p + 1]]`` = ``f_0, f_1, ...`` of its cosine series.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .runtime import device_for, host_array

#: Neighbouring pairs per query (4 x 4 cubic spline support).
TAPS = 16


@wp.func
def cosine_sum(coef: wp.array(dtype=wp.float64), start: wp.int64, end: wp.int64,
               c1: wp.float64):
    """sum_l coef[start + l] cos(l phi) over ``start <= start + l < end`` (``end > start``),
    given ``c1 = cos(phi)``: cos(l phi) by the Chebyshev recurrence (one cosine per query)."""
    two_c1 = wp.float64(2.0) * c1
    s = coef[start]
    c_prev = wp.float64(1.0)
    c_cur = c1
    j = start + wp.int64(1)
    while j < end:
        s += coef[j] * c_cur
        c_next = two_c1 * c_cur - c_prev
        c_prev = c_cur
        c_cur = c_next
        j += wp.int64(1)
    return s


@wp.func
def tap_series(offsets: wp.array(dtype=wp.int64), coef: wp.array(dtype=wp.float64),
               pair: wp.array2d(dtype=wp.int64), weight: wp.array2d(dtype=wp.float64), q: int,
               c1: wp.float64):
    """The interpolated series of query ``q`` over its :data:`TAPS` taps, given
    ``c1 = cos(phi)``: ``(sum_k w_k f_0(p_k), sum_k w_k f(p_k; phi))``, its constant term and
    its value."""
    g0 = wp.float64(0.0)
    g = wp.float64(0.0)
    for k in range(TAPS):
        w = weight[q, k]
        if w != wp.float64(0.0):
            p = pair[q, k]
            start = offsets[p]
            end = offsets[p + wp.int64(1)]
            if end > start:
                g0 += w * coef[start]
                g += w * cosine_sum(coef, start, end, c1)
    return wp.vec2d(g0, g)


@wp.kernel
def _eval_series(offsets: wp.array(dtype=wp.int64), coef: wp.array(dtype=wp.float64),
                 pair: wp.array2d(dtype=wp.int64), weight: wp.array2d(dtype=wp.float64),
                 dphi: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    out[q] = tap_series(offsets, coef, pair, weight, q, wp.cos(dphi[q]))[1]


def eval_series(offsets: np.ndarray, coef: np.ndarray, pair: np.ndarray, weight: np.ndarray,
                dphi: np.ndarray, device=None) -> np.ndarray:
    """Sum ``weight[q, k] * sum_l coef_l(pair[q, k]) cos(l dphi[q])`` over the 16 taps.

    Parameters
    ----------
    offsets : int64 (P + 1,)
    coef : float64 (C,)
    pair, weight : (Q, 16) int64 / float64 (weight 0 skips a tap)
    dphi : float64 (Q,) azimuth difference (radians)
    """
    device = device_for(device)
    Q = dphi.shape[0]
    if Q == 0:
        return np.zeros(0)
    out = wp.empty(Q, dtype=wp.float64, device=device)
    wp.launch(_eval_series, dim=Q, device=device, inputs=[
        host_array(offsets, wp.int64, device), host_array(coef, wp.float64, device),
        host_array(pair, wp.int64, device), host_array(weight, wp.float64, device),
        host_array(dphi, wp.float64, device)], outputs=[out])
    return out.numpy()
