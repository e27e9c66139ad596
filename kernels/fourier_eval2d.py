"""Kernel that evaluates tabulated 2-D Fourier BSDFs of anisotropic layers (Zeltner & Jakob 2018
eq. (7)): each query sums, over up to 16 neighbouring ordinate pairs (spline weights prepared by the
host), ``f = 2 Re sum f_{d,s} exp(i (d phi_d + s phi_s))`` over the stored half of the
coefficients (the others are their conjugates; ``f_{0,0}`` is stored halved).

Table layout (built by :class:`layersim.aniso.bsdf.SeriesTable2D`): pair ``p`` owns runs
``run_offsets[p] .. run_offsets[p + 1] - 1``; run ``r`` holds coefficients
``f_{d,s}`` for ``s = run_s[r]`` and ``d = run_d0[r] + j``, ``j < run_len[r]``, stored at
``coef_re/coef_im[run_start[r] + j]``. Along a run the phase advances by ``exp(i phi_d)`` (a
complex multiplication per coefficient, no trigonometric call).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .fourier_eval import TAPS
from .runtime import device_for, host_array


@wp.kernel
def _eval_series2d(run_offsets: wp.array(dtype=wp.int64), run_s: wp.array(dtype=wp.int32),
                   run_d0: wp.array(dtype=wp.int32), run_start: wp.array(dtype=wp.int64),
                   run_len: wp.array(dtype=wp.int32), coef_re: wp.array(dtype=wp.float64),
                   coef_im: wp.array(dtype=wp.float64), pair: wp.array2d(dtype=wp.int64),
                   weight: wp.array2d(dtype=wp.float64), phi_d: wp.array(dtype=wp.float64),
                   phi_s: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    cd = wp.cos(phi_d[q])
    sd = wp.sin(phi_d[q])
    acc = wp.float64(0.0)
    for k in range(TAPS):
        w = weight[q, k]
        if w != wp.float64(0.0):
            p = pair[q, k]
            s_tap = wp.float64(0.0)
            r = run_offsets[p]
            r_end = run_offsets[p + wp.int64(1)]
            while r < r_end:
                theta = wp.float64(run_d0[r]) * phi_d[q] + wp.float64(run_s[r]) * phi_s[q]
                er = wp.cos(theta)
                ei = wp.sin(theta)
                j = run_start[r]
                j_end = j + wp.int64(run_len[r])
                while j < j_end:
                    s_tap += coef_re[j] * er - coef_im[j] * ei
                    t = er * cd - ei * sd
                    ei = er * sd + ei * cd
                    er = t
                    j += wp.int64(1)
                r += wp.int64(1)
            acc += w * s_tap
    out[q] = wp.float64(2.0) * acc


def eval_series2d(table, pair: np.ndarray, weight: np.ndarray, phi_d: np.ndarray,
                  phi_s: np.ndarray, device=None) -> np.ndarray:
    """Evaluate ``sum_k weight[q, k] f_{pair[q, k]}(phi_d[q], phi_s[q])``.

    Parameters
    ----------
    table : object
        With arrays ``run_offsets, run_s, run_d0, run_start, run_len, coef_re, coef_im``
        (see module doc).
    pair, weight : (Q, 16) int64 / float64
    phi_d, phi_s : (Q,) float64
        Difference and sum of the propagation azimuths (radians).
    """
    device = device_for(device)
    Q = phi_d.shape[0]
    if Q == 0:
        return np.zeros(0)
    arr = lambda a, dtype: host_array(a, dtype, device)
    out = wp.empty(Q, dtype=wp.float64, device=device)
    wp.launch(_eval_series2d, dim=Q, device=device, inputs=[
        arr(table.run_offsets, wp.int64), arr(table.run_s, wp.int32),
        arr(table.run_d0, wp.int32), arr(table.run_start, wp.int64),
        arr(table.run_len, wp.int32), arr(table.coef_re, wp.float64),
        arr(table.coef_im, wp.float64), arr(pair, wp.int64), arr(weight, wp.float64),
        arr(phi_d, wp.float64), arr(phi_s, wp.float64)], outputs=[out])
    return out.numpy()
