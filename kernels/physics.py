"""Per-interface and per-medium physics, written once as Warp functions.

These functions are the single source of the BSDF formulas: the Fourier projection kernels
(:mod:`layersim.kernels.projection`) and the Monte Carlo random walk call them, and the host
solver only ever sees their values. All functions are generic over the scalar type (``float32``
for the random walk, ``float64`` for projection); literals are cast with ``type(x)(...)``.

Conventions (``docs/conventions.md``)
-------------------------------------
* Local frame: ``z`` is the macro-surface normal pointing out of the top of the interface; the
  roughness ``alpha_u`` acts along ``x`` and ``alpha_v`` along ``y`` (callers rotate directions into
  the interface's tangent frame first).
* ``wi`` and ``wo`` both point *away* from the surface. Reflection on the top side has
  ``wi.z > 0, wo.z > 0``; top-to-bottom transmission ``wi.z > 0, wo.z < 0``.
* ``eta`` is the index of the medium below the interface relative to the medium above it
  (``eta + i k`` for a conductor, which is only ever lit from above).
* BSDF values are in 1/sr, without the cosine factor, in the radiance convention: transmission
  obeys ``f(wi, wo) / eta_o^2 == f(wo, wi) / eta_i^2``.

Microfacet split
----------------
Both distributions are written as ``D(m) = P(h) * peak(q)`` with an unnormalised half vector
``h``, the slope-space quadratic form ``q = (hx^2/au^2 + hy^2/av^2) / hz^2`` and the prefactor
``P = |h|^4 / (pi au av hz^4)``; ``peak(q) = exp(-q)`` (Beckmann) or ``1 / (1 + q)^2`` (GGX).
For a fixed pair of elevations, ``q`` is an affine function of ``cos(phi_o - phi_i)`` (isotropic
case) or of the phasors of Zeltner & Jakob 2018 eq. (22), so the peak factor has a closed-form
Fourier series (Bessel functions for Beckmann, a geometric series for GGX); everything else,
returned as the *smooth factor* by :func:`microfacet_smooth_q`, is low-frequency. The projection
relies on this split; the random walk uses :func:`microfacet_eval`, which multiplies the two back
together.

References
----------
Walter, Marschner, Li, Torrance (2007), "Microfacet models for refraction through rough surfaces",
eq. 19-21 (BSDF), 25-27 (Beckmann, Smith); Heitz (2014), "Understanding the masking-shadowing
function", sec. 5 (anisotropic Smith Lambda), sec. 6, eq. 99-100 (height-correlated G2). Zeltner & Jakob 2018 eq. (18)-(22).
"""

from __future__ import annotations

from typing import Any

import warp as wp

#: Distribution codes shared by host and kernels.
BECKMANN = wp.constant(0)
GGX = wp.constant(1)
DISTRIBUTION_CODES = {"beckmann": 0, "ggx": 1}
#: Shadowing-masking codes shared by host and kernels (:func:`smith_g2`).
SEPARABLE = wp.constant(0)
HEIGHT_CORRELATED = wp.constant(1)
HEIGHT_CORRELATED_BETA = wp.constant(2)
SHADOWING_CODES = {"separable": 0, "height-correlated": 1, "height-correlated-beta": 2}

# ---------------------------------------------------------------------------------------------
# Fresnel
# ---------------------------------------------------------------------------------------------


@wp.func
def fresnel_dielectric(cos_i: Any, eta: Any):
    """Unpolarised Fresnel reflectance of a dielectric boundary.

    ``cos_i`` is the cosine between the incident direction (pointing away) and the boundary
    normal; ``eta`` the index on the far side (``cos_i < 0``: the light arrives from the ``eta``
    side, and the relative index is inverted). Total internal reflection returns 1.
    """
    one = type(cos_i)(1.0)
    c = cos_i
    e = eta
    if c < type(cos_i)(0.0):
        c = -c
        e = one / eta
    sin2_t = (one - c * c) / (e * e)
    if sin2_t >= one:
        return one
    cos_t = wp.sqrt(one - sin2_t)
    rs = (c - e * cos_t) / (c + e * cos_t)
    rp = (e * c - cos_t) / (e * c + cos_t)
    return type(cos_i)(0.5) * (rs * rs + rp * rp)


@wp.func
def fresnel_conductor(cos_i: Any, eta: Any, k: Any):
    """Unpolarised Fresnel reflectance of a conductor with relative index ``eta + i k``
    (exact formula; ``cos_i`` in [0, 1])."""
    one = type(cos_i)(1.0)
    half = type(cos_i)(0.5)
    two = type(cos_i)(2.0)
    cos2 = cos_i * cos_i
    sin2 = one - cos2
    temp1 = eta * eta - k * k - sin2
    a2pb2 = wp.sqrt(temp1 * temp1 + type(cos_i)(4.0) * k * k * eta * eta)
    a = wp.sqrt(wp.max(half * (a2pb2 + temp1), type(cos_i)(0.0)))
    term1 = a2pb2 + cos2
    term2 = two * cos_i * a
    rs = (term1 - term2) / (term1 + term2)
    term3 = a2pb2 * cos2 + sin2 * sin2
    term4 = term2 * sin2
    rp = rs * (term3 - term4) / (term3 + term4)
    return half * (rs + rp)


# ---------------------------------------------------------------------------------------------
# Thin films: Airy reflectance
# ---------------------------------------------------------------------------------------------
#
# Complex numbers are written as pairs of reals (``re, im``): the OpenCL translation has no
# complex type (:mod:`layersim.kernels.opencl_codegen`).


@wp.func
def _cmul(ar: Any, ai: Any, br: Any, bi: Any):
    return ar * br - ai * bi, ar * bi + ai * br


@wp.func
def _cdiv(ar: Any, ai: Any, br: Any, bi: Any):
    """``a / b``; 0 where ``b`` is exactly 0 (the Fresnel coefficients of two media of equal
    index at their common critical angle, whose limit is 0)."""
    d = br * br + bi * bi
    if d == br * type(br)(0.0):
        return d, d
    return (ar * br + ai * bi) / d, (ai * br - ar * bi) / d


@wp.func
def _csqrt(ar: Any, ai: Any):
    """Principal square root, with the imaginary part taken >= 0 on the negative real axis
    (an evanescent wave decays into the medium: ``Im(n cos theta) >= 0`` for the ``exp(-i
    omega t)`` convention)."""
    zero = ar * type(ar)(0.0)
    m = wp.sqrt(ar * ar + ai * ai)
    t = wp.sqrt(type(ar)(0.5) * (m + wp.abs(ar)))
    if t == zero:
        return zero, zero
    if ar >= zero:
        return t, ai / (type(ar)(2.0) * t)
    if ai < zero:
        return wp.abs(ai) / (type(ar)(2.0) * t), -t
    return wp.abs(ai) / (type(ar)(2.0) * t), t


@wp.func
def _airy_amplitude(r12r: Any, r12i: Any, r23r: Any, r23i: Any, er: Any, ei: Any):
    """``|r|^2`` of ``r = (r12 + r23 E) / (1 + r12 r23 E)`` (Airy summation of the film's
    multiple reflections, ``E = exp(i phi)``; Belcour & Barla 2017, eq. 2)."""
    one = r12r * type(r12r)(0.0) + type(r12r)(1.0)
    ar, ai = _cmul(r23r, r23i, er, ei)
    br, bi = _cmul(r12r, r12i, ar, ai)
    rr, ri = _cdiv(r12r + ar, r12i + ai, one + br, bi)
    return rr * rr + ri * ri


@wp.func
def airy_reflectance(cos_1: Any, n1: Any, n2: Any, n3: Any, k3: Any, phase_scale: Any):
    """Unpolarised reflectance of a film of real index ``n2`` between a medium of real index
    ``n1`` (the light's side) and a substrate of index ``n3 + i k3``.

    ``cos_1`` in [0, 1] is the cosine of incidence in medium 1; indices are relative to one
    common reference (any: only ratios and ``phase_scale`` enter). ``phase_scale = 4 pi n d /
    lambda`` for a film of absolute index ``n`` and thickness ``d`` at vacuum wavelength
    ``lambda``, so that the round-trip phase is ``phi = phase_scale cos(theta_2)``
    (Belcour & Barla 2017, eq. 2 and the phase of their sec. 4; Born & Wolf, Principles of
    Optics, sec. 1.6.4, eq. 58). With the normal components ``q_j = n_j cos(theta_j) =
    sqrt(n_j^2 - n1^2 sin^2 theta_1)`` (complex: evanescent in the film beyond its critical
    angle, absorbing in a conductor), the Fresnel amplitudes are ``r_ij = (q_i - q_j) / (q_i +
    q_j)`` (s) and ``(n_j^2 q_i - n_i^2 q_j) / (n_j^2 q_i + n_i^2 q_j)`` (p), and
    ``R = (|r_s|^2 + |r_p|^2) / 2`` with ``r`` of :func:`_airy_amplitude` for each. Grazing
    incidence and total internal reflection into a real substrate (``k3 = 0``) return exactly
    1, as :func:`fresnel_dielectric`.
    """
    zero = cos_1 * type(cos_1)(0.0)
    one = type(cos_1)(1.0)
    if cos_1 <= zero:
        return one
    s2 = n1 * n1 * (one - cos_1 * cos_1)            # (n sin theta)^2, the same in every medium
    if k3 == zero and s2 >= n3 * n3:
        return one
    q1 = n1 * cos_1
    q2r, q2i = _csqrt(n2 * n2 - s2, zero)
    e3r = n3 * n3 - k3 * k3                         # n3^2 (complex)
    e3i = type(cos_1)(2.0) * n3 * k3
    q3r, q3i = _csqrt(e3r - s2, e3i)
    # round trip through the film: E = exp(i phi), phi = phase_scale q2 / n2 (complex where
    # the film is evanescent: then E decays)
    phi_r = phase_scale * q2r / n2
    phi_i = phase_scale * q2i / n2
    decay = wp.exp(-phi_i)
    er = decay * wp.cos(phi_r)
    ei = decay * wp.sin(phi_r)
    # s polarisation
    a12r, a12i = _cdiv(q1 - q2r, -q2i, q1 + q2r, q2i)
    a23r, a23i = _cdiv(q2r - q3r, q2i - q3i, q2r + q3r, q2i + q3i)
    rs = _airy_amplitude(a12r, a12i, a23r, a23i, er, ei)
    # p polarisation
    e1 = n1 * n1
    e2 = n2 * n2
    b12r, b12i = _cdiv(e2 * q1 - e1 * q2r, -e1 * q2i, e2 * q1 + e1 * q2r, e1 * q2i)
    xr, xi = _cmul(e3r, e3i, q2r, q2i)
    b23r, b23i = _cdiv(xr - e2 * q3r, xi - e2 * q3i, xr + e2 * q3r, xi + e2 * q3i)
    rp = _airy_amplitude(b12r, b12i, b23r, b23i, er, ei)
    return type(cos_1)(0.5) * (rs + rp)


@wp.func
def fresnel_film_dielectric(cos_i: Any, eta: Any, eta_film: Any, phase_scale: Any):
    """Unpolarised reflectance of a dielectric boundary (relative index ``eta``) carrying a
    film of relative index ``eta_film`` (both relative to the medium on the ``cos_i > 0``
    side): :func:`airy_reflectance`, with the signed-cosine convention of
    :func:`fresnel_dielectric` (``cos_i < 0``: the light arrives from the ``eta`` side).
    Without absorption the transmittance is ``1 - R``, the same from both sides at
    Snell-related angles (so the BSDF built on it stays reciprocal)."""
    one = type(cos_i)(1.0)
    if cos_i < type(cos_i)(0.0):
        return airy_reflectance(-cos_i, eta, eta_film, one, cos_i * type(cos_i)(0.0),
                                phase_scale)
    return airy_reflectance(cos_i, one, eta_film, eta, cos_i * type(cos_i)(0.0), phase_scale)


@wp.func
def fresnel_film_conductor(cos_i: Any, eta: Any, k: Any, eta_film: Any, phase_scale: Any):
    """Unpolarised reflectance of a conductor ``eta + i k`` carrying a film of relative index
    ``eta_film`` (``cos_i`` in [0, 1]): :func:`airy_reflectance`, the conductor's phase
    shifts entering through its complex Fresnel amplitudes."""
    return airy_reflectance(cos_i, type(cos_i)(1.0), eta_film, eta, k, phase_scale)


@wp.func
def fresnel_interface(cos_i: Any, eta: Any, k: Any, eta_film: Any, phase_scale: Any):
    """Fresnel reflectance of an interface as the microfacet BSDF uses it: a conductor
    (``k > 0``, ``|cos_i|``) or a dielectric (signed ``cos_i``), with a film where
    ``phase_scale > 0`` and the bare formulas (:func:`fresnel_dielectric`,
    :func:`fresnel_conductor`) otherwise."""
    zero = cos_i * type(cos_i)(0.0)
    if phase_scale > zero:
        if k > zero:
            return fresnel_film_conductor(wp.abs(cos_i), eta, k, eta_film, phase_scale)
        return fresnel_film_dielectric(cos_i, eta, eta_film, phase_scale)
    if k > zero:
        return fresnel_conductor(wp.abs(cos_i), eta, k)
    return fresnel_dielectric(cos_i, eta)


# ---------------------------------------------------------------------------------------------
# Microfacet distributions and Smith shadowing-masking
# ---------------------------------------------------------------------------------------------


@wp.func
def ndf_peak(q: Any, dist: int):
    """Peak factor of the NDF as a function of the slope-space form ``q`` (see module doc)."""
    if dist == GGX:
        s = type(q)(1.0) + q
        return type(q)(1.0) / (s * s)
    return wp.exp(-q)


@wp.func
def ndf(m: Any, au: Any, av: Any, dist: int):
    """Microfacet normal distribution D(m) (1/sr) for a unit normal ``m`` in the tangent frame;
    normalised so that the projected area integrates to one."""
    zero = au * type(au)(0.0)
    if m[2] <= zero:
        return zero
    z2 = m[2] * m[2]
    q = (m[0] * m[0] / (au * au) + m[1] * m[1] / (av * av)) / z2
    return ndf_peak(q, dist) / (type(au)(wp.pi) * au * av * z2 * z2)


@wp.func
def slope_radius(u: Any, alpha: Any, dist: int):
    """Slope radius ``tan(theta_m)`` whose cumulative probability under the isotropic slope
    distribution of roughness ``alpha`` is ``u`` in [0, 1): ``alpha sqrt(u / (1 - u))`` (GGX)
    or ``alpha sqrt(-log(1 - u))`` (Beckmann) (Walter et al. 2007, eq. 28 and 35). A
    quadrature in ``u`` (and the slope azimuth) integrates against ``D(m) m.z dm``."""
    one = type(u)(1.0)
    if dist == GGX:
        return alpha * wp.sqrt(u / (one - u))
    return alpha * wp.sqrt(-wp.log(one - u))


@wp.func
def smith_lambda(w: Any, au: Any, av: Any, dist: int):
    """Smith's Lambda for direction ``w`` (any hemisphere; uses |w.z|), anisotropic roughness."""
    zero = au * type(au)(0.0)
    one = type(au)(1.0)
    s2 = w[0] * w[0] + w[1] * w[1]
    if s2 <= zero:
        return zero
    # alpha along the projected direction (Heitz 2014, eq. 80) times tan(theta)
    alpha_tan2 = (w[0] * w[0] * au * au + w[1] * w[1] * av * av) / (w[2] * w[2])
    if dist == GGX:
        return type(au)(0.5) * (wp.sqrt(one + alpha_tan2) - one)
    a = one / wp.sqrt(alpha_tan2)
    if a > type(au)(8.0):  # Lambda < 1e-29: avoid 0/0 in the tail
        return zero
    return type(au)(0.5) * (wp.erf(a) - one) + wp.exp(-a * a) / (
        type(au)(2.0) * a * type(au)(1.7724538509055159))


@wp.func
def smith_g1(w: Any, m: Any, au: Any, av: Any, dist: int):
    """Smith masking G1(w, m) with the side condition chi+((w.m) / (w.n))."""
    zero = au * type(au)(0.0)
    if wp.dot(w, m) * w[2] <= zero:
        return zero
    return type(au)(1.0) / (type(au)(1.0) + smith_lambda(w, au, av, dist))


@wp.func
def log_gamma(x: Any):
    """``log Gamma(x)`` for ``x >= 1``: Stirling's series after shifting ``x`` past 8 with the
    recurrence ``Gamma(x + 1) = x Gamma(x)`` (Abramowitz & Stegun 6.1.40, four terms; absolute
    error below 1e-11 there, 6e-12 measured for Gamma(1) in float64). Warp has no lgamma."""
    one = type(x)(1.0)
    shift = one
    y = x
    while y < type(x)(8.0):
        shift = shift * y
        y = y + one
    r = one / (y * y)
    # 1/12, 1/360, 1/1260, 1/1680 as literals: Warp folds `1.0 / 12.0` in float32
    series = (one / y) * (type(x)(0.08333333333333333) - r * (type(x)(0.002777777777777778)
                          - r * (type(x)(0.0007936507936507937)
                                 - r * type(x)(0.0005952380952380953))))
    return ((y - type(x)(0.5)) * wp.log(y) - y + type(x)(0.9189385332046728) + series
            - wp.log(shift))


@wp.func
def smith_g2(wi: Any, wo: Any, m: Any, au: Any, av: Any, dist: int, shadow: int):
    """Smith shadowing-masking G2(wi, wo, m) of the pair (Heitz 2014, "Understanding the
    masking-shadowing function", sec. 6), with the side conditions chi+((w.m) / (w.n)) of both
    directions.

    ``shadow`` = :data:`SEPARABLE`: ``G1(wi, m) G1(wo, m)`` (Heitz 2014, sec. 6.1; Walter et
    al. 2007, eq. 23). Height-correlated: a microfacet at height ``h`` is seen from ``w`` with
    probability ``C1(h)^Lambda(w)`` from above and ``(1 - C1(h))^Lambda(w)`` from below (``C1``
    the height distribution's CDF), so averaging over heights gives ``1 / (1 + Lambda(wi) +
    Lambda(wo))`` in reflection (Heitz 2014, eq. 99). In transmission the same average gives
    the Beta function ``B(1 + Lambda(wi), 1 + Lambda(wo))`` (Heitz 2014, eq. 100):
    :data:`HEIGHT_CORRELATED_BETA`; :data:`HEIGHT_CORRELATED` uses eq. 99 in transmission too,
    as pbrt-v4's ``TrowbridgeReitzDistribution::G`` does (its ``DielectricBxDF`` and the
    layered BxDFs built on it). Every form is symmetric in ``wi, wo`` (reciprocal) and at most
    ``min(G1(wi), G1(wo))``; eq. 99 is at least the separable product (a high facet is seen
    from both directions), eq. 100 at most (a high facet, seen from above, is hidden from
    below).
    """
    zero = au * type(au)(0.0)
    one = type(au)(1.0)
    if shadow == SEPARABLE:
        return smith_g1(wi, m, au, av, dist) * smith_g1(wo, m, au, av, dist)
    if wp.dot(wi, m) * wi[2] <= zero or wp.dot(wo, m) * wo[2] <= zero:
        return zero
    li = smith_lambda(wi, au, av, dist)
    lo = smith_lambda(wo, au, av, dist)
    if wi[2] * wo[2] > zero or shadow == HEIGHT_CORRELATED:
        return one / (one + li + lo)
    return wp.exp(log_gamma(one + li) + log_gamma(one + lo) - log_gamma(type(au)(2.0) + li + lo))


@wp.func
def g2_from_masking(g1i: Any, g1o: Any, transmission: bool, shadow: int):
    """``G2`` of a pair from the masking ``G1`` of each direction, for a masking function given
    without its Lambda: Smith's ``G1 = 1 / (1 + Lambda)`` gives ``1 + Lambda = 1 / G1``, so that
    the forms of :func:`smith_g2` become ``G1(wi) G1(wo)`` (separable), ``1 / (1 / G1(wi) +
    1 / G1(wo) - 1)`` (height-correlated, Heitz 2014 eq. 99) and ``B(1 / G1(wi), 1 / G1(wo))``
    (transmission, eq. 100). A tabulated NDF's ``S(k)`` (Wang et al. 2008, eq. (4)-(5)) is
    Smith's ``G1`` of that D, so this extends the height-correlated term to it. Side conditions
    are the caller's (a 0 stays 0)."""
    zero = g1i * type(g1i)(0.0)
    one = type(g1i)(1.0)
    if shadow == SEPARABLE:
        return g1i * g1o
    if g1i <= zero or g1o <= zero:
        return zero
    a = one / g1i
    b = one / g1o
    if transmission and shadow == HEIGHT_CORRELATED_BETA:
        return wp.exp(log_gamma(a) + log_gamma(b) - log_gamma(a + b))
    return one / (a + b - one)


@wp.func
def smith_g2_over_g1(wi: Any, wo: Any, m: Any, au: Any, av: Any, dist: int, shadow: int):
    """``G2(wi, wo, m) / G1(wi, m)`` (:func:`smith_g2`): the weight of a direction ``wo``
    scattered by the visible normal ``m`` of ``wi`` (Heitz & d'Eon 2014, eq. 11-12), for
    ``wi`` with ``chi+`` on ``m``. Separable: exactly ``G1(wo, m)``."""
    if shadow == SEPARABLE:
        return smith_g1(wo, m, au, av, dist)
    return smith_g2(wi, wo, m, au, av, dist, shadow) * (type(au)(1.0)
                                                        + smith_lambda(wi, au, av, dist))


# ---------------------------------------------------------------------------------------------
# Rough interfaces
# ---------------------------------------------------------------------------------------------


@wp.func
def half_vector(wi: Any, wo: Any, eta: Any, k: Any):
    """Generalized half vector of a rough interface (Walter et al. 2007, eq. 16): returns
    ``(h, eta_i, eta_o)`` with ``h`` unnormalised and oriented to ``+z`` (``wi + wo`` in
    reflection, ``eta_i wi + eta_o wo`` in refraction) and the relative indices of the media
    holding ``wi`` and ``wo`` (1 above the interface, ``eta`` below). ``h`` is the zero vector
    where no microfacet connects the two directions: on the horizon, for transmission through or
    light from below a conductor (``k > 0``)."""
    zero = eta * type(eta)(0.0)
    one = type(eta)(1.0)
    eta_i = one
    eta_o = one
    if wi[2] < zero:
        eta_i = eta
    if wo[2] < zero:
        eta_o = eta
    none = wi * zero
    if wi[2] == zero or wo[2] == zero:
        return none, eta_i, eta_o
    reflect = wi[2] * wo[2] > zero
    if k > zero and (not reflect or wi[2] < zero):
        return none, eta_i, eta_o
    h = wi + wo
    if not reflect:
        h = wi * eta_i + wo * eta_o
    if h[2] < zero:
        h = -h
    return h, eta_i, eta_o


@wp.func
def microfacet_smooth_q_shadowed(wi: Any, wo: Any, eta: Any, k: Any, eta_film: Any,
                                 phase_scale: Any, au: Any, av: Any, dist: int, shadow: int):
    """Split microfacet BSDF of an interface: returns ``(smooth, q)`` with
    ``f(wi, wo) = smooth * ndf_peak(q, dist)``, and the shadowing-masking ``shadow``
    (:func:`smith_g2`).

    Dielectric when ``k == 0`` (reflection and transmission from both sides), conductor when
    ``k > 0`` (reflection from the top only). Radiance convention for transmission. Where
    ``phase_scale > 0`` every microfacet carries a thin film of relative index ``eta_film``
    (:func:`fresnel_interface`; Belcour & Barla 2017, sec. 4). Where the BSDF vanishes,
    ``smooth`` is 0; ``q`` is still the slope form of the half vector whenever one exists (it
    is pure geometry, and the projection reads it at phi = 0 and pi).
    """
    zero = au * type(au)(0.0)
    h, eta_i, eta_o = half_vector(wi, wo, eta, k)
    hlen2 = wp.dot(h, h)
    if hlen2 <= zero or h[2] <= zero:
        return zero, zero
    hz2 = h[2] * h[2]
    q = (h[0] * h[0] / (au * au) + h[1] * h[1] / (av * av)) / hz2
    m = h / wp.sqrt(hlen2)
    g = smith_g2(wi, wo, m, au, av, dist, shadow)
    if g <= zero:
        return zero, q
    prefactor = hlen2 * hlen2 / (type(au)(wp.pi) * au * av * hz2 * hz2)
    factor = microfacet_factor_film(wi, wo, m, eta_i, eta_o, eta, k, eta_film, phase_scale)
    return factor * g * prefactor, q


@wp.func
def microfacet_smooth_q_film(wi: Any, wo: Any, eta: Any, k: Any, eta_film: Any,
                             phase_scale: Any, au: Any, av: Any, dist: int):
    """:func:`microfacet_smooth_q_shadowed` with the separable Smith term."""
    s, q = microfacet_smooth_q_shadowed(wi, wo, eta, k, eta_film, phase_scale, au, av, dist,
                                        SEPARABLE)
    return s, q


@wp.func
def microfacet_smooth_q(wi: Any, wo: Any, eta: Any, k: Any, au: Any, av: Any, dist: int):
    """:func:`microfacet_smooth_q_film` without a film."""
    zero = au * type(au)(0.0)
    s, q = microfacet_smooth_q_film(wi, wo, eta, k, zero, zero, au, av, dist)
    return s, q


@wp.func
def microfacet_reflection_factor(f: Any, wi: Any, wo: Any):
    """The microfacet BRDF without ``D(m) G`` for a given Fresnel factor ``f``:
    ``f / (4 |wi.z wo.z|)`` (Walter et al. 2007, eq. 20; Wang et al. 2008, eq. 2). The reflection
    branch of :func:`facet_factor`; single-view NDF fitting (:mod:`layersim.ndf`) calls it
    with ``f = 1`` as the paper's fit assumes."""
    return f / (type(f)(4.0) * wp.abs(wi[2] * wo[2]))


@wp.func
def facet_factor(wi: Any, wo: Any, m: Any, eta_i: Any, eta_o: Any, F: Any):
    """The microfacet BSDF without ``D(m) G``, for the Fresnel reflectance ``F`` of the facet
    at ``wi.m``: ``F / (4 |wi.z wo.z|)`` in reflection and ``|wi.m wo.m| eta_o^2 (1 - F) /
    (|wi.z wo.z| (eta_i wi.m + eta_o wo.m)^2)`` in refraction (Walter et al. 2007, eq. 20-21;
    radiance convention), for the unit normal ``m`` of the pair (:func:`half_vector`)."""
    one = type(F)(1.0)
    ci = wp.dot(wi, m)
    co = wp.dot(wo, m)
    cos_io = wp.abs(wi[2] * wo[2])
    if wi[2] * wo[2] > type(F)(0.0):
        return microfacet_reflection_factor(F, wi, wo)
    ft = one - F
    denom = eta_i * ci + eta_o * co
    return wp.abs(ci * co) * eta_o * eta_o * ft / (cos_io * denom * denom)


@wp.func
def microfacet_factor_film(wi: Any, wo: Any, m: Any, eta_i: Any, eta_o: Any, eta: Any, k: Any,
                           eta_film: Any, phase_scale: Any):
    """:func:`facet_factor` with the interface's Fresnel reflectance at ``wi.m``
    (:func:`fresnel_interface`: filmed where ``phase_scale > 0``). Shared by the analytic and
    the tabulated NDFs (:mod:`layersim.kernels.tabulated`)."""
    F = fresnel_interface(wp.dot(wi, m), eta, k, eta_film, phase_scale)
    return facet_factor(wi, wo, m, eta_i, eta_o, F)


@wp.func
def microfacet_factor(wi: Any, wo: Any, m: Any, eta_i: Any, eta_o: Any, eta: Any, k: Any):
    """:func:`microfacet_factor_film` without a film."""
    zero = eta * type(eta)(0.0)
    return microfacet_factor_film(wi, wo, m, eta_i, eta_o, eta, k, zero, zero)


@wp.func
def microfacet_eval_shadowed(wi: Any, wo: Any, eta: Any, k: Any, eta_film: Any,
                             phase_scale: Any, au: Any, av: Any, dist: int, shadow: int):
    """Microfacet BSDF f(wi, wo) (1/sr, no cosine) of a rough dielectric (``k == 0``) or
    conductor (``k > 0``) interface, filmed where ``phase_scale > 0``, with the
    shadowing-masking ``shadow``; see :func:`microfacet_smooth_q_shadowed`."""
    s, q = microfacet_smooth_q_shadowed(wi, wo, eta, k, eta_film, phase_scale, au, av, dist,
                                        shadow)
    if s == au * type(au)(0.0):
        return s
    return s * ndf_peak(q, dist)


@wp.func
def microfacet_eval_film(wi: Any, wo: Any, eta: Any, k: Any, eta_film: Any, phase_scale: Any,
                         au: Any, av: Any, dist: int):
    """:func:`microfacet_eval_shadowed` with the separable Smith term."""
    return microfacet_eval_shadowed(wi, wo, eta, k, eta_film, phase_scale, au, av, dist,
                                    SEPARABLE)


@wp.func
def microfacet_eval(wi: Any, wo: Any, eta: Any, k: Any, au: Any, av: Any, dist: int):
    """Microfacet BSDF f(wi, wo) (1/sr, no cosine) of a rough dielectric (``k == 0``) or
    conductor (``k > 0``) interface without a film; see :func:`microfacet_smooth_q`."""
    zero = au * type(au)(0.0)
    return microfacet_eval_film(wi, wo, eta, k, zero, zero, au, av, dist)


# ---------------------------------------------------------------------------------------------
# Diffuse and media
# ---------------------------------------------------------------------------------------------


@wp.func
def lambert_eval(wi: Any, wo: Any, albedo: Any):
    """Opaque Lambertian reflector lit from the top: albedo / pi for wi.z, wo.z > 0."""
    zero = albedo * type(albedo)(0.0)
    if wi[2] <= zero or wo[2] <= zero:
        return zero
    return albedo / type(albedo)(wp.pi)


@wp.func
def hg_eval(cos_theta: Any, g: Any):
    """Henyey-Greenstein phase function (1/sr) for the cosine between the propagation
    directions before and after scattering (``cos_theta = 1``: no deflection)."""
    one = type(g)(1.0)
    denom = one + g * g - type(g)(2.0) * g * cos_theta
    # 4 pi as one literal: Warp evaluates `4.0 * wp.pi` in float32 before the cast, which cost
    # the float64 path 3e-8 relative accuracy
    return (one - g * g) / (type(g)(12.566370614359172) * denom * wp.sqrt(denom))
