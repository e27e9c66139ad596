"""Energy-loss compensation of rough interfaces, as Warp functions: the albedo tables (float64)
and the compensation lobe of the random walk (float32).

Albedo tables
-------------
:data:`albedo_kernel` integrates the single-scattering interface of
:func:`layersim.kernels.physics.microfacet_eval` over the outgoing directions, for incident
directions on either side, split into the reflected and the transmitted energy::

    E_R(wi) = int_{wo same side} f(wi, wo) |wo.z| dwo,   E_T(wi) = int_{wo other side} ...

The integral is taken over the microfacet normal ``m`` (the directions are a function of it:
reflection, Walter et al. 2007 eq. 13-14; refraction, eq. 15-17), against the slope density
``D(m) m.z dm`` written in polar slope coordinates: the radial coordinate is its cumulative
distribution ``u`` (:func:`layersim.kernels.physics.slope_radius`), so that ``D(m) m.z dm =
du dphi / (2 pi)``. Gauss-Legendre nodes in ``u`` and the trapezoidal rule in the azimuth of
the slope (the integrand is even in it: incidence lies in the ``xz`` plane) are exact for the
smooth parts; the integrand is continuous with kinks where ``wo`` reaches the horizon or total
internal reflection sets in.

With ``unit_fresnel`` the Fresnel factor of a conductor is divided out: the table of Kulla &
Conty 2017 ("Revisiting physically based shading at Imageworks", sec. "Energy compensation")
and of layerlab's conductor correction.

Compensation lobe of the walk
-----------------------------
The compensation terms (:mod:`layersim.compensation`) are azimuth independent and separable per
block: ``f_b(mu_i, mu_o) = u_b(mu_i) v_b(mu_o)``. The walk reads, per side of incidence, the
block albedos ``a_R(mu_i), a_T(mu_i)`` and the outgoing shapes ``g_b = pi v_b / V_b``
(``V_b = 2 pi int v_b mu dmu``, so that ``g_b`` averages to 1 over the cosine lobe), tabulated
at :data:`TABLE_NODES` nodes uniform in the polar angle (0 to 90 degrees) and interpolated
linearly in that angle, the interpolation the solver uses too. :func:`choose_lobe` draws the
compensation lobe with probability ``a_R + a_T`` (weight ``g_b(mu_o)``, cosine-distributed
``mu_o``) and otherwise hands the rescaled random number back to the single-scattering sampler,
whose weight is then divided by ``1 - a_R - a_T``: each term of ``f = f_ss + f_c`` is estimated
by its own sampler, an unbiased one-sample mixture.
"""

from __future__ import annotations

from typing import Any

import warp as wp

from . import physics

wp.set_module_options({"enable_backward": False})

#: Nodes of the compensation tables, uniform in the polar angle from 0 to 90 degrees.
TABLE_NODES = wp.constant(181)
#: Floats per side of incidence in a boundary's table record: a_R, a_T, g_R, g_T.
SIDE_FLOATS = wp.constant(4 * 181)
HALF_PI32 = wp.constant(wp.float32(1.5707963267948966))


@wp.func
def refracted(wi: wp.vec3d, m: wp.vec3d, ratio: wp.float64):
    """Refraction of ``wi`` (pointing away) at normal ``m`` (on the side of ``wi``) with
    ``ratio = eta_i / eta_o``; returns ``(wo, ok)``, ``ok`` false under total internal
    reflection."""
    c = wp.dot(wi, m)
    ct2 = wp.float64(1.0) - ratio * ratio * (wp.float64(1.0) - c * c)
    if ct2 <= wp.float64(0.0):
        return wi, False
    return -wi * ratio + m * (ratio * c - wp.sqrt(ct2)), True


@wp.func
def normal_contributions(wi: wp.vec3d, m: wp.vec3d, eta: wp.float64, k: wp.float64,
                         alpha: wp.float64, dist: int, shadow: int, unit_fresnel: int):
    """``(r, t)``: reflected and transmitted energy per unit slope probability carried by the
    microfacet normal ``m`` (upper hemisphere) for ``wi``: ``f |wo.z| |dwo / dm| / (D m.z)``,
    ``f`` with the Smith term ``shadow`` (:func:`layersim.kernels.physics.smith_g2`)."""
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    side = one
    eta_i = one
    eta_o = eta
    if wi[2] < zero:
        side = -one
        eta_i = eta
        eta_o = one
    ms = m * side
    c = wp.dot(wi, ms)
    r = zero
    t = zero
    if c <= zero:
        return r, t
    dens = physics.ndf(m, alpha, alpha, dist) * m[2]
    wo = ms * (wp.float64(2.0) * c) - wi
    if wo[2] * side > zero:
        f = physics.microfacet_eval_shadowed(wi, wo, eta, k, zero, zero, alpha, alpha, dist,
                                             shadow)
        if unit_fresnel != 0:
            f = f / physics.fresnel_conductor(c, eta, k)
        r = f * wp.abs(wo[2]) * wp.float64(4.0) * wp.abs(wp.dot(wo, ms)) / dens
    if k == zero:
        wt, ok = refracted(wi, ms, eta_i / eta_o)
        if ok and wt[2] * side < zero:
            co = wp.dot(wt, ms)
            denom = eta_i * c + eta_o * co
            f = physics.microfacet_eval_shadowed(wi, wt, eta, k, zero, zero, alpha, alpha, dist,
                                                 shadow)
            t = f * wp.abs(wt[2]) * denom * denom / (eta_o * eta_o * wp.abs(co) * dens)
    return r, t


@wp.kernel
def albedo_kernel(mu: wp.array(dtype=wp.float64), side: wp.float64,
                  u_nodes: wp.array(dtype=wp.float64), u_weights: wp.array(dtype=wp.float64),
                  n_phi: int, eta: wp.float64, k: wp.float64, alpha: wp.float64, dist: int,
                  shadow: int, unit_fresnel: int, out_r: wp.array2d(dtype=wp.float64),
                  out_t: wp.array2d(dtype=wp.float64)):
    """Partial sums of ``E_R, E_T`` for incident cosine ``mu[j]`` on ``side`` (+1 top, -1
    bottom), one slope radius ``u_nodes[a]`` per thread, ``n_phi`` trapezoid nodes on the
    slope azimuth ``[0, pi]``: ``out[j, a]``, summed by the host."""
    j, a = wp.tid()
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    c = mu[j]
    wi = wp.vec3d(wp.sqrt(wp.max(one - c * c, zero)), zero, side * c)
    rad = physics.slope_radius(u_nodes[a], alpha, dist)
    dphi = wp.float64(3.141592653589793) / wp.float64(n_phi - 1)
    sr = zero
    st = zero
    for p in range(n_phi):
        phi = dphi * wp.float64(p)
        w = one
        if p == 0 or p == n_phi - 1:
            w = wp.float64(0.5)
        m = wp.normalize(wp.vec3d(-rad * wp.cos(phi), -rad * wp.sin(phi), one))
        r, t = normal_contributions(wi, m, eta, k, alpha, dist, shadow, unit_fresnel)
        sr = sr + w * r
        st = st + w * t
    # trapezoid on [0, pi] of an even function = half of the full period: dphi / pi in all
    scale = u_weights[a] * dphi / wp.float64(3.141592653589793)
    out_r[j, a] = sr * scale
    out_t[j, a] = st * scale


@wp.kernel
def fresnel_kernel(mu: wp.array(dtype=wp.float64), eta: wp.float64, k: wp.float64,
                   out: wp.array(dtype=wp.float64)):
    """Fresnel reflectance of a conductor at cosines ``mu`` (for its hemispherical average)."""
    j = wp.tid()
    out[j] = physics.fresnel_conductor(mu[j], eta, k)


# ---------------------------------------------------------------------------------------------
# Random walk (float32)
# ---------------------------------------------------------------------------------------------


@wp.func
def table_value(tab: wp.array(dtype=wp.float32), base: int, mu: wp.float32):
    """Table ``tab[base : base + TABLE_NODES]`` (nodes uniform in the polar angle, 0 at the
    normal) at cosine ``mu``, linear in the angle."""
    c = wp.min(wp.max(mu, wp.float32(0.0)), wp.float32(1.0))
    x = wp.acos(c) * wp.float32(TABLE_NODES - 1) / HALF_PI32
    i = wp.min(int(x), TABLE_NODES - 2)
    t = x - wp.float32(i)
    return tab[base + i] * (wp.float32(1.0) - t) + tab[base + i + 1] * t


@wp.func
def choose_lobe(wi: wp.vec3, tab: wp.array(dtype=wp.float32), offset: int, u0: wp.float32,
                u1: wp.float32, u2: wp.float32):
    """Draw the compensation lobe of a boundary whose table record starts at ``tab[offset]``.

    Returns ``(taken, wo, weight, u0_rest, scale)``: if ``taken``, the particle leaves along
    ``wo`` with weight factor ``weight``; otherwise the caller samples the single-scattering
    interface with the uniform ``u0_rest`` and multiplies its weight by ``scale``.
    """
    one = wp.float32(1.0)
    base = offset
    side = one
    if wi[2] < wp.float32(0.0):
        base = offset + SIDE_FLOATS
        side = -one
    mu = wp.abs(wi[2])
    a_r = table_value(tab, base, mu)
    a_t = table_value(tab, base + TABLE_NODES, mu)
    ac = a_r + a_t
    if u0 >= ac:
        return False, wi, one, (u0 - ac) / (one - ac), one / (one - ac)
    mu_o = wp.sqrt(u0 / ac)
    s = wp.sqrt(wp.max(one - mu_o * mu_o, wp.float32(0.0)))
    phi = u1 * wp.float32(6.283185307179586)
    shape = base + 2 * TABLE_NODES
    z = side * mu_o
    if u2 * ac >= a_r:
        shape = base + 3 * TABLE_NODES
        z = -z
    return True, wp.vec3(s * wp.cos(phi), s * wp.sin(phi), z), table_value(tab, shape, mu_o), \
        u0, one
