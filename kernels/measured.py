"""Measured isotropic BRDFs in the MERL layout (:mod:`layersim.layers.merl`) as Warp functions: the
trilinear lookup shared by the projection and the random walk, and its sampling.

``tab[off + (i * 90 + j) * 180 + k]`` holds one channel's BRDF (1/sr) at the sample
``(theta_h, theta_d, phi_d) = ((i / 90)^2 pi/2, j pi/180, k pi/180)``. Generic over the scalar
type; only the subset that :mod:`layersim.kernels.opencl_codegen` translates.

The walk samples ``wo`` from the cosine-weighted hemisphere (density ``wo.z / pi``), so the
weight is ``f(wi, wo) |wo.z| / pdf = pi f(wi, wo)``: unbiased for any BRDF, and what a measured
table allows without a per-direction inversion.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from . import sampling

wp.set_module_options({"enable_backward": False})

# samples in theta_h, theta_d, phi_d (layersim.layers.merl.DIMS) are written as literals below


@wp.func
def half_diff(wi: Any, wo: Any):
    """Rusinkiewicz's ``(theta_h, theta_d, phi_d)`` of a pair above the surface (``phi_d``
    folded to [0, pi) by reciprocity), as :func:`layersim.layers.merl.half_diff`."""
    h = wp.normalize(wi + wo)
    th = wp.atan2(wp.sqrt(h[0] * h[0] + h[1] * h[1]), h[2])
    ph = wp.atan2(h[1], h[0])
    c = wp.cos(ph)
    s = wp.sin(ph)
    x = wi[0] * c + wi[1] * s
    y = wi[1] * c - wi[0] * s
    ct = wp.cos(th)
    st = wp.sin(th)
    dx = x * ct - wi[2] * st
    dz = x * st + wi[2] * ct
    td = wp.atan2(wp.sqrt(dx * dx + y * y), dz)
    pd = wp.atan2(y, dx)
    if pd < type(th)(0.0):
        pd = pd + type(th)(3.141592653589793)
    return th, td, pd


@wp.func
def measured_eval(wi: Any, wo: Any, tab: Any, off: int):
    """BRDF (1/sr, no cosine) of one channel of a MERL table at ``off`` for ``wi``, ``wo``
    above the surface (0 otherwise), trilinear in the index coordinates."""
    zero = wi[2] * type(wi[2])(0.0)
    if wi[2] <= zero or wo[2] <= zero:
        return zero
    one = type(wi[2])(1.0)
    th, td, pd = half_diff(wi, wo)
    u = wp.sqrt(wp.clamp(th / type(th)(1.5707963267948966), zero, one)) * type(th)(90.0)
    v = td / type(th)(1.5707963267948966) * type(th)(90.0)
    w = pd / type(th)(3.141592653589793) * type(th)(180.0)
    # lower sample and fraction of each index coordinate, clamped to the last interval
    i = wp.min(wp.max(int(wp.floor(u)), 0), 88)
    a = wp.clamp(u - type(th)(i), zero, one)
    j = wp.min(wp.max(int(wp.floor(v)), 0), 88)
    b = wp.clamp(v - type(th)(j), zero, one)
    k = wp.min(wp.max(int(wp.floor(w)), 0), 179)
    c = wp.clamp(w - type(th)(k), zero, one)
    k1 = k + 1
    if k1 >= 180:
        k1 = 0
    acc = zero
    for di in range(2):
        wa = one - a
        if di == 1:
            wa = a
        for dj in range(2):
            wb = one - b
            if dj == 1:
                wb = b
            base = off + ((i + di) * 90 + (j + dj)) * 180
            acc = acc + wa * wb * ((one - c) * tab[base + k] + c * tab[base + k1])
    return acc


@wp.func
def sample_measured(wi: Any, tab: Any, off: int, u1: Any, u2: Any):
    """Cosine-weighted ``wo`` and the weight ``pi f(wi, wo)`` (0 for light from below)."""
    zero = wi[2] * type(wi[2])(0.0)
    wo = sampling.sample_cosine_hemisphere(u1, u2)
    if wi[2] <= zero:
        return wo, zero
    return wo, type(u1)(3.141592653589793) * measured_eval(wi, wo, tab, off)
