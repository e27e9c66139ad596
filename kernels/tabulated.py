"""Tabulated-NDF microfacet interfaces as Warp functions: lookup, BSDF and importance sampling.

The table is one flat float array (``tab``) with the layout of
:meth:`layersim.ndf.table.NDFTable.packed`, starting at offset ``off``: four counts
``(T, P, ST, SP)``, then ``theta`` (T), ``phi`` (P), ``D`` (T x P), the shadowing ``S`` on a
uniform (ST x SP) grid, the marginal CDF of the theta cells (T) and the conditional CDFs of the
phi cells ((T - 1) x (P + 1)). ``D`` and ``S`` are bilinear between their nodes, periodic in
azimuth. The random walk keeps the table in its boundary-record array (float32); the projection
passes a float64 copy: every function is generic over the scalar type, and uses only the subset
that :mod:`layersim.kernels.opencl_codegen` translates.

BSDF (Wang et al. 2008, eq. (1)-(5), with Walter et al. 2007 for refraction): the microfacet
model of :mod:`.physics` with ``D`` from the table and ``G = S(wi) S(wo)``, each factor with the
side condition ``chi+((w.m) / (w.n))``; or, for a height-correlated term, ``G`` from the two
``S`` by :func:`.physics.g2_from_masking` (``S`` is Smith's ``G1`` of the table's D).

Sampling: a normal ``m`` is drawn from the table's cells (marginal in theta, conditional in phi;
uniform in ``sin^2 theta`` and ``phi`` inside the cell), with density ``p(m)`` per steradian close
to ``D(m) (m.n)``; the event (reflection or refraction) then follows as in
:func:`layersim.kernels.sampling.sample_microfacet`. The weight ``f |wo.z| / pdf(wo)`` is
``D(m) |wi.m| G / (|wi.z| p(m))`` (times ``F`` for a conductor, whose event is not chosen).
"""

from __future__ import annotations

from typing import Any

import warp as wp

from . import physics, sampling

wp.set_module_options({"enable_backward": False})

#: Distribution code of a tabulated NDF in the walk's boundary records (after the analytic
#: codes of :data:`layersim.kernels.physics.DISTRIBUTION_CODES`).
TABULATED = wp.constant(2)
#: Floats before ``theta`` in a packed table.
HEAD = wp.constant(4)


@wp.func
def find_node(tab: Any, start: int, n: int, x: Any):
    """Largest ``i`` in ``[0, n - 1]`` with ``tab[start + i] <= x`` (0 when ``x`` is below
    ``tab[start]``), by bisection of the increasing values ``tab[start .. start + n - 1]``."""
    lo = int(0)
    hi = n
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if tab[start + mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@wp.func
def angles(w: Any):
    """Elevation from ``+z`` (of ``|w.z|``) and azimuth in ``[0, 2 pi)`` of a unit vector."""
    theta = wp.atan2(wp.sqrt(w[0] * w[0] + w[1] * w[1]), wp.abs(w[2]))
    phi = wp.atan2(w[1], w[0])
    if phi < type(theta)(0.0):
        phi = phi + type(theta)(6.283185307179586)
    return theta, phi


@wp.func
def phi_cell(tab: Any, p0: int, n_phi: int, phi: Any):
    """Azimuth cell of ``phi`` in [0, 2 pi): ``(j, j1, t)`` with ``phi`` between nodes ``j``
    and ``j1`` (``j1 = 0`` for the cell wrapping across 2 pi) at fraction ``t``."""
    two_pi = type(phi)(6.283185307179586)
    j = n_phi - 1
    lo = tab[p0 + n_phi - 1] - two_pi
    if phi >= tab[p0]:
        j = find_node(tab, p0, n_phi, phi)
        lo = tab[p0 + j]
    j1 = j + 1
    hi = tab[p0]
    if j1 >= n_phi:
        j1 = 0
        hi = hi + two_pi
    else:
        hi = tab[p0 + j1]
    t = wp.clamp((phi - lo) / (hi - lo), type(phi)(0.0), type(phi)(1.0))
    return j, j1, t


@wp.func
def ndf_lookup(tab: Any, off: int, theta: Any, phi: Any):
    """Bilinear ``D(theta, phi)`` (1/sr) of the table at ``off`` (``theta`` in [0, pi/2])."""
    n_t = int(tab[off])
    n_p = int(tab[off + 1])
    t0 = off + HEAD
    p0 = t0 + n_t
    d0 = p0 + n_p
    i = find_node(tab, t0, n_t - 1, theta)
    ti = wp.clamp((theta - tab[t0 + i]) / (tab[t0 + i + 1] - tab[t0 + i]), type(theta)(0.0),
                  type(theta)(1.0))
    j, j1, tj = phi_cell(tab, p0, n_p, phi)
    one = type(theta)(1.0)
    r0 = d0 + i * n_p
    r1 = r0 + n_p
    return ((one - ti) * ((one - tj) * tab[r0 + j] + tj * tab[r0 + j1])
            + ti * ((one - tj) * tab[r1 + j] + tj * tab[r1 + j1]))


@wp.func
def shadow_lookup(tab: Any, off: int, w: Any):
    """Tabulated ``S(w)`` (Wang et al. 2008, eq. (5)), bilinear on its grid; uses
    ``|w.z|`` (the microsurface seen from below has the same normals)."""
    n_t = int(tab[off])
    n_p = int(tab[off + 1])
    n_st = int(tab[off + 2])
    n_sp = int(tab[off + 3])
    s0 = off + HEAD + n_t + n_p + n_t * n_p
    theta, phi = angles(w)
    # the grid is uniform in 1 - sqrt(1 - theta / (pi/2)) (layersim.ndf.table.shadow_grid)
    one = type(theta)(1.0)
    x = (one - wp.sqrt(wp.max(one - theta / type(theta)(1.5707963267948966),
                              type(theta)(0.0)))) * type(theta)(n_st - 1)
    i = wp.min(int(wp.floor(x)), n_st - 2)
    ti = wp.clamp(x - type(theta)(i), type(theta)(0.0), type(theta)(1.0))
    y = phi * type(theta)(n_sp) / type(theta)(6.283185307179586)
    j = wp.min(int(wp.floor(y)), n_sp - 1)
    tj = wp.clamp(y - type(theta)(j), type(theta)(0.0), type(theta)(1.0))
    j1 = j + 1
    if j1 >= n_sp:
        j1 = 0
    r0 = s0 + i * n_sp
    r1 = r0 + n_sp
    return ((one - ti) * ((one - tj) * tab[r0 + j] + tj * tab[r0 + j1])
            + ti * ((one - tj) * tab[r1 + j] + tj * tab[r1 + j1]))


@wp.func
def masking(w: Any, m: Any, tab: Any, off: int):
    """``S(w)`` with the side condition ``chi+((w.m) / (w.n))``."""
    if wp.dot(w, m) * w[2] <= type(w[2])(0.0):
        return type(w[2])(0.0)
    return shadow_lookup(tab, off, w)


@wp.func
def microfacet_eval_tabulated(wi: Any, wo: Any, eta: Any, k: Any, tab: Any, off: int):
    """:func:`microfacet_eval_tabulated_shadowed` with the separable term."""
    return microfacet_eval_tabulated_shadowed(wi, wo, eta, k, tab, off, physics.SEPARABLE)


@wp.func
def microfacet_eval_tabulated_shadowed(wi: Any, wo: Any, eta: Any, k: Any, tab: Any, off: int,
                                       shadow: int):
    """Microfacet BSDF ``f(wi, wo)`` (1/sr, no cosine) with the tabulated NDF at ``off`` and the
    Smith term ``shadow`` (:func:`physics.g2_from_masking`): dielectric when ``k == 0`` (both
    sides, radiance convention), conductor when ``k > 0``. Directions in the interface's
    tangent frame, as :func:`physics.microfacet_eval`."""
    zero = eta * type(eta)(0.0)
    h, eta_i, eta_o = physics.half_vector(wi, wo, eta, k)
    hlen2 = wp.dot(h, h)
    if hlen2 <= zero or h[2] <= zero:
        return zero
    m = h / wp.sqrt(hlen2)
    g = physics.g2_from_masking(masking(wi, m, tab, off), masking(wo, m, tab, off),
                                wi[2] * wo[2] < zero, shadow)
    if g <= zero:
        return zero
    theta, phi = angles(m)
    d = ndf_lookup(tab, off, theta, phi)
    return physics.microfacet_factor(wi, wo, m, eta_i, eta_o, eta, k) * g * d


@wp.func
def cdf_start(tab: Any, off: int):
    """Index of the marginal CDF of the theta cells in the table at ``off``: after the
    counts, ``theta``, ``phi``, ``D`` and ``S`` (module docstring)."""
    n_t = int(tab[off])
    n_p = int(tab[off + 1])
    return off + HEAD + n_t + n_p + n_t * n_p + int(tab[off + 2]) * int(tab[off + 3])


@wp.func
def cell_pdf(tab: Any, off: int, i: int, j: int, theta: Any):
    """Density (1/sr) of the normals drawn by :func:`sample_normal` in cell ``(i, j)`` at
    elevation ``theta`` (the cell's probability over its ``sin^2``-by-``phi`` area)."""
    n_t = int(tab[off])
    n_p = int(tab[off + 1])
    t0 = off + HEAD
    p0 = t0 + n_t
    c0 = cdf_start(tab, off)
    r0 = c0 + n_t + i * (n_p + 1)
    prob = (tab[c0 + i + 1] - tab[c0 + i]) * (tab[r0 + j + 1] - tab[r0 + j])
    sa = wp.sin(tab[t0 + i])
    sb = wp.sin(tab[t0 + i + 1])
    dphi = tab[p0 + 0] + type(theta)(6.283185307179586) - tab[p0 + n_p - 1]
    if j < n_p - 1:
        dphi = tab[p0 + j + 1] - tab[p0 + j]
    return prob * type(theta)(2.0) * wp.cos(theta) / ((sb * sb - sa * sa) * dphi)


@wp.func
def sample_normal(tab: Any, off: int, u1: Any, u2: Any):
    """Draw a microfacet normal from the table's cells (see the module docstring).

    Returns ``(m, pdf)``: the unit normal (``m.z > 0``) and its density per steradian."""
    n_t = int(tab[off])
    n_p = int(tab[off + 1])
    t0 = off + HEAD
    p0 = t0 + n_t
    c0 = cdf_start(tab, off)
    zero = u1 * type(u1)(0.0)
    one = type(u1)(1.0)
    i = find_node(tab, c0, n_t - 1, u1)
    v1 = wp.clamp((u1 - tab[c0 + i]) / wp.max(tab[c0 + i + 1] - tab[c0 + i],
                                              type(u1)(1e-30)), zero, one)
    r0 = c0 + n_t + i * (n_p + 1)
    j = find_node(tab, r0, n_p, u2)
    v2 = wp.clamp((u2 - tab[r0 + j]) / wp.max(tab[r0 + j + 1] - tab[r0 + j], type(u1)(1e-30)),
                  zero, one)
    sa = wp.sin(tab[t0 + i])
    sb = wp.sin(tab[t0 + i + 1])
    s2 = sa * sa + v1 * (sb * sb - sa * sa)
    sin_t = wp.sqrt(wp.clamp(s2, zero, one))
    cos_t = wp.sqrt(wp.clamp(one - s2, zero, one))
    hi = tab[p0] + type(u1)(6.283185307179586)
    if j < n_p - 1:
        hi = tab[p0 + j + 1]
    phi = tab[p0 + j] + v2 * (hi - tab[p0 + j])
    m = wp.vector(sin_t * wp.cos(phi), sin_t * wp.sin(phi), cos_t)
    return m, cell_pdf(tab, off, i, j, wp.atan2(sin_t, cos_t))


@wp.func
def normal_pdf(tab: Any, off: int, m: Any):
    """Density (1/sr) with which :func:`sample_normal` returns the unit normal ``m``."""
    if m[2] <= type(m[2])(0.0):
        return type(m[2])(0.0)
    n_t = int(tab[off])
    n_p = int(tab[off + 1])
    t0 = off + HEAD
    theta, phi = angles(m)
    i = find_node(tab, t0, n_t - 1, theta)
    j, j1, tj = phi_cell(tab, t0 + n_t, n_p, phi)
    return cell_pdf(tab, off, i, j, theta)


@wp.func
def sample_microfacet_tabulated(wi: Any, eta: Any, k: Any, tab: Any, off: int, u1: Any,
                                u2: Any, u3: Any):
    """:func:`sample_microfacet_tabulated_shadowed` with the separable term."""
    wo, weight = sample_microfacet_tabulated_shadowed(wi, eta, k, tab, off, physics.SEPARABLE,
                                                      u1, u2, u3)
    return wo, weight


@wp.func
def sample_microfacet_tabulated_shadowed(wi: Any, eta: Any, k: Any, tab: Any, off: int,
                                         shadow: int, u1: Any, u2: Any, u3: Any):
    """Sample ``wo`` for :func:`microfacet_eval_tabulated_shadowed` (``wi`` in the tangent
    frame, either side for a dielectric): ``u1, u2`` draw the normal, ``u3`` the event. Returns
    ``(wo, weight)`` with ``weight = f |wo.z| / pdf`` (0 where the single-scattering model
    loses the particle: a normal facing away from ``wi``, or ``wo`` masked)."""
    zero = eta * type(eta)(0.0)
    m, pm = sample_normal(tab, off, u1, u2)
    ci = wp.dot(wi, m)
    if pm <= zero or ci * wi[2] <= zero:
        return wi, zero
    weight = type(eta)(1.0)
    wo = sampling.reflect(wi, m)
    if k > zero:
        weight = physics.fresnel_conductor(wp.abs(ci), eta, k)
    else:
        if u3 >= physics.fresnel_dielectric(ci, eta):
            wt, ok = sampling.refract(wi, m, eta)
            if ok:
                wo = wt
    theta, phi = angles(m)
    d = ndf_lookup(tab, off, theta, phi)
    g = physics.g2_from_masking(masking(wi, m, tab, off), masking(wo, m, tab, off),
                                wi[2] * wo[2] < zero, shadow)
    return wo, weight * g * d * wp.abs(ci) / (wp.abs(wi[2]) * pm)


@wp.func
def microfacet_pdf_tabulated(wi: Any, wo: Any, eta: Any, k: Any, tab: Any, off: int):
    """Density (1/sr) with which :func:`sample_microfacet_tabulated` returns ``wo`` for ``wi``
    (for a conductor the event is not chosen: no Fresnel factor)."""
    zero = eta * type(eta)(0.0)
    one = type(eta)(1.0)
    h, eta_i, eta_o = physics.half_vector(wi, wo, eta, k)
    if wp.dot(h, h) <= zero or h[2] <= zero:
        return zero
    m = wp.normalize(h)
    ci = wp.dot(wi, m)
    co = wp.dot(wo, m)
    if ci * wi[2] <= zero:
        return zero
    pm = normal_pdf(tab, off, m)
    if wi[2] * wo[2] > zero:
        f = one
        if k <= zero:
            f = physics.fresnel_dielectric(ci, eta)
        return f * pm / (type(eta)(4.0) * wp.abs(co))
    denom = eta_i * ci + eta_o * co
    return ((one - physics.fresnel_dielectric(ci, eta)) * pm * eta_o * eta_o * wp.abs(co)
            / (denom * denom))
