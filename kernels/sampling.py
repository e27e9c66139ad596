"""Importance sampling of the per-interface and per-medium physics, as Warp functions.

The random walk (:mod:`layersim.kernels.walk`) draws outgoing directions with these functions and
weights them so that the walk samples *exactly* the BSDFs of :mod:`layersim.kernels.physics`:
``weight = f(wi, wo) |wo.z| / pdf(wo)``. Like ``physics.py``, everything is generic over the
scalar type (``type(x)(...)`` literals, ``wp.vector`` for vectors) and only uses the language subset
that :mod:`layersim.kernels.opencl_codegen` translates to OpenCL C.

Conventions are those of ``physics.py``: directions point away from the surface, the frame's ``z``
is the macro-normal, roughness ``alpha_u`` acts along ``x``. Uniforms ``u*`` lie in (0, 1).

Microfacet sampling
-------------------
Microfacet normals ``m`` are drawn from the distribution of visible normals (VNDF) seen from
``wi`` (from ``-wi`` when ``wi`` is below the interface: the microsurface seen from below has the
same normals, and ``G1``, ``D`` are symmetric under ``w -> -w``):

    D_wi(m) = G1(wi, m) |wi.m| D(m) / |wi.z|.

The event (reflection or refraction, chosen with probability F(wi.m) for dielectrics) then fixes
``wo``. With the separable Smith term ``G = G1(wi, m) G1(wo, m)`` of ``physics.microfacet_eval``,
``f |wo.z| / pdf = G1(wo, m)`` for dielectric reflection and refraction (radiance convention; the
``eta_o^2`` of the BTDF cancels the one of the refraction Jacobian), and ``F(wi.m) G1(wo, m)`` for
conductors. ``G1(wo, m) = 0`` when ``wo`` ends on the wrong side of the macro-surface: the
single-scattering model loses that energy and the particle is terminated. With the
height-correlated term (``physics.smith_g2``) the factor is ``G2(wi, wo, m) / G1(wi, m)``
(:func:`sample_microfacet_shadowed`).
:func:`microfacet_pdf` gives the density of the sampled ``wo`` so that tests can check
``weight == eval * |wo.z| / pdf`` pointwise.

References
----------
Heitz (2018), "Sampling the GGX distribution of visible normals", JCGT 7(4).
Heitz, d'Eon (2014), "Importance sampling microfacet-based BSDFs using the distribution of visible
normals", EGSR (stretch-invariant slope sampling, Beckmann visible slopes).
Walter, Marschner, Li, Torrance (2007), "Microfacet models for refraction through rough surfaces".
Duff, Burgess, Christensen, Hery, Kensler, Liani, Villemin (2017), "Building an orthonormal basis,
revisited", JCGT 6(1).
Henyey, Greenstein (1941), ApJ 93; inversion e.g. in Pharr, Jakob, Humphreys, PBRT 3rd ed.,
sec. 15.2.3 (rewritten here without the cancellation at small ``g``).
"""

from __future__ import annotations

from typing import Any

import warp as wp

from . import physics

wp.set_module_options({"enable_backward": False})

#: Halley iterations allowed for the Beckmann visible-slope inversion (converges in ~3; the
#: bracket guarantees termination within float precision well before this).
BECKMANN_MAX_ITER = wp.constant(40)


# ---------------------------------------------------------------------------------------------
# Frames
# ---------------------------------------------------------------------------------------------


@wp.func
def orthonormal_basis(n: Any):
    """Two unit tangents ``(t, b)`` completing the unit vector ``n`` to a right-handed
    orthonormal frame (Duff et al. 2017, listing 3; continuous except at ``n.z = 0``)."""
    nz = n[2]
    one = type(nz)(1.0)
    sign = one
    if nz < type(nz)(0.0):
        sign = -one
    a = -one / (sign + nz)
    b = n[0] * n[1] * a
    t = wp.vector(one + sign * n[0] * n[0] * a, sign * b, -sign * n[0])
    s = wp.vector(b, sign + n[1] * n[1] * a, -n[1])
    return t, s


@wp.func
def to_tangent_frame(v: Any, cos_rot: Any, sin_rot: Any):
    """Express ``v`` (local stack frame) in an interface frame rotated by ``rot`` about z
    (the frame whose x axis is ``(cos rot, sin rot, 0)``)."""
    return wp.vector(cos_rot * v[0] + sin_rot * v[1], cos_rot * v[1] - sin_rot * v[0], v[2])


@wp.func
def from_tangent_frame(v: Any, cos_rot: Any, sin_rot: Any):
    """Inverse of :func:`to_tangent_frame`."""
    return wp.vector(cos_rot * v[0] - sin_rot * v[1], sin_rot * v[0] + cos_rot * v[1], v[2])


@wp.func
def reflect(wi: Any, m: Any):
    """Mirror ``wi`` about the unit normal ``m`` (both pointing away from the surface)."""
    return m * (type(m[2])(2.0) * wp.dot(wi, m)) - wi


@wp.func
def refract(wi: Any, m: Any, eta: Any):
    """Refract ``wi`` through a boundary with unit normal ``m`` (m.z >= 0).

    ``eta`` is the index below the boundary relative to above (as ``fresnel_dielectric``);
    ``wi`` may lie on either side. Returns ``(wt, ok)``: the transmitted direction pointing away
    from the boundary on the other side, and False on total internal reflection (where
    ``physics.fresnel_dielectric`` returns exactly 1).
    """
    one = type(eta)(1.0)
    c = wp.dot(wi, m)
    n = m
    e = eta
    if c < type(eta)(0.0):
        c = -c
        n = -m
        e = one / eta
    sin2_t = (one - c * c) / (e * e)
    if sin2_t >= one:
        return wi * type(eta)(0.0), False
    cos_t = wp.sqrt(one - sin2_t)
    return n * (c / e - cos_t) - wi / e, True


# ---------------------------------------------------------------------------------------------
# Diffuse and media
# ---------------------------------------------------------------------------------------------


@wp.func
def sample_cosine_hemisphere(u1: Any, u2: Any):
    """Direction on the upper hemisphere with density ``z / pi`` (Malley's method)."""
    zero = type(u1)(0.0)
    r = wp.sqrt(u1)
    phi = type(u1)(6.283185307179586) * u2
    return wp.vector(r * wp.cos(phi), r * wp.sin(phi), wp.sqrt(wp.max(type(u1)(1.0) - u1, zero)))


@wp.func
def sample_hg_cos(g: Any, u: Any):
    """Cosine of the deflection angle, distributed as the Henyey-Greenstein phase function
    ``physics.hg_eval`` (exact inversion; ``g = 0`` gives the isotropic ``2u - 1``).

    The textbook form ``(1 + g^2 - s^2) / (2 g)`` with ``s = (1 - g^2) / (1 - g + 2 g u)`` cancels
    catastrophically for small ``|g|``. Expanding it with ``t = 2u - 1`` and ``d = 1 + g t``:

        cos = (t + g (t^2 + 3) / 2 + g^2 t + g^3 (t^2 - 1) / 2) / d^2,

    which is the same function, exact at ``g = 0`` and free of the 1/g.
    """
    one = type(g)(1.0)
    half = type(g)(0.5)
    t = type(g)(2.0) * u - one
    d = one + g * t
    num = t + half * g * (t * t + type(g)(3.0)) + g * g * t + half * g * g * g * (t * t - one)
    return wp.min(wp.max(num / (d * d), -one), one)


@wp.func
def sample_hg(d: Any, g: Any, u1: Any, u2: Any):
    """New propagation direction after Henyey-Greenstein scattering of the unit propagation
    direction ``d`` (the deflection cosine is between ``d`` and the result)."""
    zero = type(g)(0.0)
    c = sample_hg_cos(g, u1)
    s = wp.sqrt(wp.max(type(g)(1.0) - c * c, zero))
    phi = type(g)(6.283185307179586) * u2
    t, b = orthonormal_basis(d)
    return wp.normalize(t * (s * wp.cos(phi)) + b * (s * wp.sin(phi)) + d * c)


# ---------------------------------------------------------------------------------------------
# Visible normals
# ---------------------------------------------------------------------------------------------


@wp.func
def sample_vndf_ggx(wi: Any, au: Any, av: Any, u1: Any, u2: Any):
    """GGX visible normal for ``wi`` in the upper hemisphere (Heitz 2018, listing 1)."""
    zero = au * type(au)(0.0)
    one = type(au)(1.0)
    vh = wp.normalize(wp.vector(au * wi[0], av * wi[1], wi[2]))
    lensq = vh[0] * vh[0] + vh[1] * vh[1]
    t1 = wp.vector(one, zero, zero)
    if lensq > zero:
        inv = one / wp.sqrt(lensq)
        t1 = wp.vector(-vh[1] * inv, vh[0] * inv, zero)
    t2 = wp.cross(vh, t1)
    r = wp.sqrt(u1)
    phi = type(au)(6.283185307179586) * u2
    p1 = r * wp.cos(phi)
    p2 = r * wp.sin(phi)
    s = type(au)(0.5) * (one + vh[2])
    p2 = (one - s) * wp.sqrt(wp.max(one - p1 * p1, zero)) + s * p2
    nh = t1 * p1 + t2 * p2 + vh * wp.sqrt(wp.max(one - p1 * p1 - p2 * p2, zero))
    return wp.normalize(wp.vector(au * nh[0], av * nh[1], wp.max(nh[2], zero)))


@wp.func
def beckmann_visible_slope(cot: Any, u: Any):
    """Slope ``x`` along the incident azimuth of a visible normal of the isotropic, unit-roughness
    Beckmann surface seen at ``cot = cot(theta_i) > 0``.

    The density is ``p(x) ~ (cot - x) exp(-x^2)`` on ``x < cot`` (Heitz & d'Eon 2014, sec. 4.2),
    with cumulative ``C(x) = cot sqrt(pi)/2 erfc(-x) + exp(-x^2)/2`` (up to normalisation ``Z =
    C(cot)``). ``C(x) = u Z`` is solved by Halley's method safeguarded by bisection on
    ``[-6, min(cot, 6)]`` (the root lies there for every u >= 2^-33), from the exact inverse of the
    ``cot -> 0`` limit; 3 iterations on average, to float precision.
    """
    zero = cot * type(cot)(0.0)
    one = type(cot)(1.0)
    half = type(cot)(0.5)
    two = type(cot)(2.0)
    hsp = type(cot)(0.88622692545275801) * cot  # cot * sqrt(pi) / 2
    target = u * (hsp * wp.erfc(-cot) + half * wp.exp(-cot * cot))
    lo = type(cot)(-6.0)
    hi = wp.min(cot, type(cot)(6.0))
    c0 = hsp + half  # C(0)
    x = zero
    if target < c0:
        x = -wp.sqrt(-wp.log(target / c0))
    x = wp.min(wp.max(x, lo), hi)
    for _i in range(BECKMANN_MAX_ITER):
        e = wp.exp(-x * x)
        f = hsp * wp.erfc(-x) + half * e - target
        if f > zero:
            hi = x
        else:
            lo = x
        d1 = (cot - x) * e
        d2 = -e * (one + two * x * (cot - x))
        den = two * d1 * d1 - f * d2
        xn = lo
        if den != zero:
            xn = x - two * f * d1 / den
        if xn < lo or xn > hi:
            xn = half * (lo + hi)
        step = wp.abs(xn - x)
        x = xn
        if step <= type(cot)(1e-5) * (one + wp.abs(x)):
            break
    return x


@wp.func
def sample_vndf_beckmann(wi: Any, au: Any, av: Any, u1: Any, u2: Any, u3: Any):
    """Beckmann visible normal for ``wi`` in the upper hemisphere (Heitz & d'Eon 2014):
    stretch to unit roughness, draw the visible slope along the incident azimuth by inversion
    (:func:`beckmann_visible_slope`, uniform ``u1``) and the orthogonal one from the normal
    distribution N(0, 1/2) (Box-Muller, ``u2``, ``u3``), rotate, unstretch."""
    zero = au * type(au)(0.0)
    one = type(au)(1.0)
    ws = wp.normalize(wp.vector(au * wi[0], av * wi[1], wi[2]))
    cos_t = ws[2]
    # from the tangential components, not sqrt(1 - cos^2): near the normal the cancellation
    # leaves float32 with a few correct digits, and cp, sp below would not be a unit pair
    sin_t = wp.sqrt(ws[0] * ws[0] + ws[1] * ws[1])
    r = wp.sqrt(-wp.log(u2))
    phi = type(au)(6.283185307179586) * u3
    sx = r * wp.cos(phi)
    sy = r * wp.sin(phi)
    if sin_t > zero:
        xs = beckmann_visible_slope(cos_t / sin_t, u1)
        cp = ws[0] / sin_t
        sp = ws[1] / sin_t
        sx = cp * xs - sp * sy
        sy = sp * xs + cp * sy
    return wp.normalize(wp.vector(-au * sx, -av * sy, one))


@wp.func
def sample_vndf(wi: Any, au: Any, av: Any, dist: int, u1: Any, u2: Any, u3: Any):
    """Visible normal of the ``dist`` distribution seen from ``wi`` (upper hemisphere)."""
    if dist == physics.GGX:
        return sample_vndf_ggx(wi, au, av, u1, u2)
    return sample_vndf_beckmann(wi, au, av, u1, u2, u3)


@wp.func
def vndf_pdf(wi: Any, m: Any, au: Any, av: Any, dist: int):
    """Density of visible normals ``G1(wi, m) |wi.m| D(m) / |wi.z|`` (1/sr); either side."""
    zero = au * type(au)(0.0)
    if wi[2] == zero:
        return zero
    return (physics.smith_g1(wi, m, au, av, dist) * wp.abs(wp.dot(wi, m))
            * physics.ndf(m, au, av, dist) / wp.abs(wi[2]))


# ---------------------------------------------------------------------------------------------
# Interfaces
# ---------------------------------------------------------------------------------------------


@wp.func
def facet_event(wi: Any, m: Any, eta: Any, k: Any, F: Any, au: Any, av: Any, dist: int,
                u4: Any):
    """:func:`facet_event_shadowed` with the separable Smith term."""
    wo, weight = facet_event_shadowed(wi, m, eta, k, F, au, av, dist, physics.SEPARABLE, u4)
    return wo, weight


@wp.func
def facet_event_shadowed(wi: Any, m: Any, eta: Any, k: Any, F: Any, au: Any, av: Any,
                         dist: int, shadow: int, u4: Any):
    """The event on the sampled microfacet ``m`` of :func:`sample_microfacet`, whose Fresnel
    reflectance at ``wi.m`` is ``F``: reflection weighted by ``F`` (conductor, ``k > 0``), or
    reflection with probability ``F`` and refraction otherwise (dielectric), weighted by
    ``G2(wi, wo) / G1(wi)`` of the shadowing ``shadow`` (:func:`physics.smith_g2_over_g1`).
    Returns ``(wo, weight)``."""
    weight = type(au)(1.0)
    wo = reflect(wi, m)
    if k > au * type(au)(0.0):
        weight = F
    else:
        if u4 >= F:
            wt, ok = refract(wi, m, eta)
            if ok:
                wo = wt
    return wo, weight * physics.smith_g2_over_g1(wi, wo, m, au, av, dist, shadow)


@wp.func
def visible_normal(wi: Any, au: Any, av: Any, dist: int, u1: Any, u2: Any, u3: Any):
    """A visible normal seen from ``wi`` (from ``-wi`` below the interface)."""
    wu = wi
    if wi[2] < au * type(au)(0.0):
        wu = -wi
    return sample_vndf(wu, au, av, dist, u1, u2, u3)


@wp.func
def sample_microfacet(wi: Any, eta: Any, k: Any, au: Any, av: Any, dist: int, u1: Any,
                      u2: Any, u3: Any, u4: Any):
    """Sample ``wo`` for the rough interface of ``physics.microfacet_eval``.

    ``wi`` in the interface's tangent frame; dielectric when ``k == 0`` (either side),
    conductor when ``k > 0`` (from above). ``u1..u3`` draw the visible normal, ``u4`` chooses
    reflection or refraction. Returns ``(wo, weight)`` with ``weight = f |wo.z| / pdf``
    (0 where the single-scattering model loses the particle).
    """
    m = visible_normal(wi, au, av, dist, u1, u2, u3)
    c = wp.dot(wi, m)
    F = au * type(au)(0.0)
    if k > F:
        F = physics.fresnel_conductor(wp.abs(c), eta, k)
    else:
        F = physics.fresnel_dielectric(c, eta)
    wo, weight = facet_event(wi, m, eta, k, F, au, av, dist, u4)
    return wo, weight


@wp.func
def sample_microfacet_film(wi: Any, eta: Any, k: Any, eta_film: Any, phase_scale: Any, au: Any,
                           av: Any, dist: int, u1: Any, u2: Any, u3: Any, u4: Any):
    """:func:`sample_microfacet` for the filmed interface of ``physics.microfacet_eval_film``:
    the same visible normal and event, with the film's Airy reflectance
    (``physics.fresnel_interface``) in place of Fresnel's."""
    m = visible_normal(wi, au, av, dist, u1, u2, u3)
    F = physics.fresnel_interface(wp.dot(wi, m), eta, k, eta_film, phase_scale)
    wo, weight = facet_event(wi, m, eta, k, F, au, av, dist, u4)
    return wo, weight


@wp.func
def sample_microfacet_shadowed(wi: Any, eta: Any, k: Any, eta_film: Any, phase_scale: Any,
                               au: Any, av: Any, dist: int, shadow: int, u1: Any, u2: Any,
                               u3: Any, u4: Any):
    """:func:`sample_microfacet_film` for the shadowing-masking ``shadow``
    (``physics.microfacet_eval_shadowed``): the same visible normal and event, weighted by
    ``G2(wi, wo) / G1(wi)``; ``phase_scale = 0``: no film. The density is
    :func:`microfacet_pdf_film`'s, which has only ``G1(wi)``."""
    m = visible_normal(wi, au, av, dist, u1, u2, u3)
    F = physics.fresnel_interface(wp.dot(wi, m), eta, k, eta_film, phase_scale)
    wo, weight = facet_event_shadowed(wi, m, eta, k, F, au, av, dist, shadow, u4)
    return wo, weight


@wp.func
def microfacet_pdf_film(wi: Any, wo: Any, eta: Any, k: Any, eta_film: Any, phase_scale: Any,
                        au: Any, av: Any, dist: int):
    """Density (1/sr) with which :func:`sample_microfacet_film` (:func:`sample_microfacet`
    where ``phase_scale`` is 0) returns ``wo`` for ``wi``.

    The half vector is that of ``physics.microfacet_smooth_q``; for a conductor the event is not
    chosen (its Fresnel factor sits in the weight), so the density omits F.
    """
    zero = au * type(au)(0.0)
    one = type(au)(1.0)
    h, eta_i, eta_o = physics.half_vector(wi, wo, eta, k)
    if wp.dot(h, h) <= zero or h[2] <= zero:
        return zero
    refl = wi[2] * wo[2] > zero
    conductor = k > zero
    m = wp.normalize(h)
    wu = wi
    if wi[2] < zero:
        wu = -wi
    dv = vndf_pdf(wu, m, au, av, dist)
    ci = wp.dot(wi, m)
    co = wp.dot(wo, m)
    if refl:
        f = one
        if not conductor:
            f = physics.fresnel_interface(ci, eta, k, eta_film, phase_scale)
        return f * dv / (type(au)(4.0) * wp.abs(co))
    denom = eta_i * ci + eta_o * co
    return ((one - physics.fresnel_interface(ci, eta, k, eta_film, phase_scale)) * dv * eta_o
            * eta_o * wp.abs(co) / (denom * denom))


@wp.func
def microfacet_pdf(wi: Any, wo: Any, eta: Any, k: Any, au: Any, av: Any, dist: int):
    """Density (1/sr) with which :func:`sample_microfacet` returns ``wo`` for ``wi``
    (:func:`microfacet_pdf_film` without a film)."""
    zero = au * type(au)(0.0)
    return microfacet_pdf_film(wi, wo, eta, k, zero, zero, au, av, dist)


@wp.func
def smooth_event(wi: Any, eta: Any, k: Any, F: Any, u: Any):
    """The event of :func:`sample_smooth` for the interface's reflectance ``F`` at ``wi.z``."""
    zero = eta * type(eta)(0.0)
    one = type(eta)(1.0)
    wr = wp.vector(-wi[0], -wi[1], wi[2])
    if k > zero:
        return wr, F
    if u < F:
        return wr, one
    wt, ok = refract(wi, wp.vector(zero, zero, one), eta)
    if ok:
        return wt, one
    return wr, one


@wp.func
def sample_smooth(wi: Any, eta: Any, k: Any, u: Any):
    """Specular interface (roughness 0): mirror reflection or Snell refraction, chosen with the
    Fresnel probability for a dielectric (weight 1), or reflection weighted by the conductor's
    Fresnel factor. Returns ``(wo, weight)``."""
    F = eta * type(eta)(0.0)
    if k > F:
        F = physics.fresnel_conductor(wp.abs(wi[2]), eta, k)
    else:
        F = physics.fresnel_dielectric(wi[2], eta)
    wo, weight = smooth_event(wi, eta, k, F, u)
    return wo, weight


@wp.func
def sample_smooth_film(wi: Any, eta: Any, k: Any, eta_film: Any, phase_scale: Any, u: Any):
    """:func:`sample_smooth` of a filmed interface: the film's Airy reflectance
    (``physics.fresnel_interface``) in place of Fresnel's; the refracted direction is Snell's
    between the media on either side (a film with parallel faces does not change it)."""
    F = physics.fresnel_interface(wi[2], eta, k, eta_film, phase_scale)
    wo, weight = smooth_event(wi, eta, k, F, u)
    return wo, weight
