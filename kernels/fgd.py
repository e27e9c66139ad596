"""Directional albedo of a GGX interface's reflection (the FGD term of Belcour 2018), integrated
from the per-interface physics of :mod:`layersim.kernels.physics`.

``FGD(mu, alpha, eta, k) = int f_r(wi, wo) |wo.z| dwo`` over the upper hemisphere, where ``f_r``
is :func:`~layersim.kernels.physics.microfacet_eval` (GGX, Smith shadowing-masking, Fresnel of a
dielectric when ``k == 0`` or of a conductor) and ``wi`` has cosine ``mu``. The integral is taken
over the half vector ``h`` in the coordinates ``(u, phi)`` in which GGX's ``D(h) cos(theta_h)
dw_h = du dphi / (2 pi)`` (``tan^2 theta_h = alpha^2 u / (1 - u)``), so the quadrature needs no
more nodes for a sharp lobe than for a wide one; with ``dwo = 4 |wo.h| dw_h`` the integrand is
``f_r |wo.z| 4 |wo.h| / (D(h) cos(theta_h))`` (per ``du dphi / 2 pi``), a smooth function.
``alpha == 0`` gives the Fresnel reflectance itself.

:func:`ggx_albedo` integrates the same lobe without Fresnel (``F = 1``): the energy of a GGX lobe,
by which the lobes of :mod:`layersim.statistical.lobes` are normalised.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from . import physics
from .runtime import device_for, host_array

#: Gauss-Legendre nodes of :func:`fgd` per panel in ``u`` and in ``phi`` (over [0, pi]: the
#: integrand is even in phi); total internal reflection adds panels (see ``_fgd_kernel``).
U_NODES = 64
PHI_NODES = 32


@wp.func
def _half_vector_node(wi: wp.vec3d, alpha: wp.float64, u: wp.float64, phi: wp.float64):
    """Half vector at quadrature node ``(u, phi)`` and the mirrored direction ``wo``."""
    one = wp.float64(1.0)
    r = physics.slope_radius(u, alpha, physics.GGX)
    t2 = r * r
    cos_h = one / wp.sqrt(one + t2)
    sin_h = wp.sqrt(wp.max(one - cos_h * cos_h, wp.float64(0.0)))
    h = wp.vec3d(sin_h * wp.cos(phi), sin_h * wp.sin(phi), cos_h)
    wo = h * (wp.float64(2.0) * wp.dot(wi, h)) - wi
    return h, wo


@wp.func
def _integrand(wi: wp.vec3d, a: wp.float64, u: wp.float64, phi: wp.float64, eta: wp.float64,
               k: wp.float64, fresnel: int):
    """``f_r |wo.z| dwo / (du dphi / 2 pi)`` at node ``(u, phi)``."""
    zero = wp.float64(0.0)
    h, wo = _half_vector_node(wi, a, u, phi)
    if wo[2] <= zero or wp.dot(wi, h) <= zero:
        return zero
    d = physics.ndf(h, a, a, physics.GGX)
    if d <= zero:
        return zero
    jac = wp.float64(4.0) * wp.abs(wp.dot(wo, h)) / (d * h[2])
    if fresnel == 0:
        g = physics.smith_g1(wi, h, a, a, physics.GGX) * physics.smith_g1(
            wo, h, a, a, physics.GGX)
        return g * d * physics.microfacet_reflection_factor(wp.float64(1.0), wi, wo) * wo[2] * jac
    return physics.microfacet_eval(wi, wo, eta, k, a, a, physics.GGX) * wo[2] * jac


@wp.func
def _u_of_theta(theta: wp.float64, a: wp.float64):
    """GGX coordinate ``u`` of the half-vector elevation ``theta`` (clamped to [0, 1])."""
    if theta <= wp.float64(0.0):
        return wp.float64(0.0)
    if theta >= wp.float64(0.5) * wp.float64(wp.pi):
        return wp.float64(1.0)
    t = wp.tan(theta)
    return t * t / (a * a + t * t)


@wp.func
def _tir_breaks(wi: wp.vec3d, a: wp.float64, phi: wp.float64, cos_c: wp.float64):
    """The ``u`` (ascending, in [0, 1]) where ``wi.h = cos_c`` along azimuth ``phi``:
    ``wi.h = A cos(theta) + B sin(theta) = R cos(theta - delta)``."""
    one = wp.float64(1.0)
    if cos_c < wp.float64(0.0):
        return one, one
    big_a = wi[2]
    big_b = wi[0] * wp.cos(phi)
    r = wp.sqrt(big_a * big_a + big_b * big_b)
    if cos_c >= r:
        return one, one
    delta = wp.atan2(big_b, big_a)
    w = wp.acos(cos_c / r)
    b0 = _u_of_theta(delta - w, a)
    b1 = _u_of_theta(delta + w, a)
    return wp.min(b0, b1), wp.max(b0, b1)


@wp.func
def _phi_breaks(wi: wp.vec3d, cos_c: wp.float64):
    """Azimuths in [0, pi] where the total-internal-reflection region of the half vectors
    appears (``max over theta of wi.h = cos_c``), ascending; ``pi`` when there are none."""
    one = wp.float64(1.0)
    pi = wp.float64(wp.pi)
    s2 = wi[0] * wi[0]
    if cos_c < wp.float64(0.0) or s2 <= wp.float64(0.0):
        return pi, pi
    c2 = (cos_c * cos_c - wi[2] * wi[2]) / s2
    if c2 <= wp.float64(0.0) or c2 >= one:
        return pi, pi
    b = wp.acos(wp.sqrt(c2))
    return b, pi - b


@wp.func
def _panel_end(panel: int, b0: wp.float64, b1: wp.float64, last: wp.float64):
    """Upper end of panel 0, 1 or 2 of an interval split at ``b0 <= b1`` and ending at
    ``last`` (a panel may be empty)."""
    if panel == 0:
        return b0
    if panel == 1:
        return b1
    return last


@wp.kernel
def _fgd_kernel(mu: wp.array(dtype=wp.float64), alpha: wp.array(dtype=wp.float64),
                eta: wp.array(dtype=wp.float64), k: wp.array(dtype=wp.float64),
                fresnel: int,
                u_x: wp.array(dtype=wp.float64), u_w: wp.array(dtype=wp.float64),
                p_x: wp.array(dtype=wp.float64), p_w: wp.array(dtype=wp.float64),
                out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    c = wp.min(wp.max(mu[q], wp.float64(1e-6)), one)
    wi = wp.vec3d(wp.sqrt(one - c * c), zero, c)
    a = alpha[q]
    if a <= zero:
        if fresnel == 0:
            out[q] = one
        elif k[q] > zero:
            out[q] = physics.fresnel_conductor(c, eta[q], k[q])
        else:
            out[q] = physics.fresnel_dielectric(c, eta[q])
        return
    # Total internal reflection (eta < 1) switches Fresnel to 1 where wi.h < cos_c: the u range
    # of each phi is split there so that every Gauss-Legendre panel sees a smooth integrand.
    cos_c = wp.float64(-1.0)
    if fresnel != 0 and k[q] <= zero and eta[q] < one:
        cos_c = wp.sqrt(one - eta[q] * eta[q])
    total = zero
    p0, p1 = _phi_breaks(wi, cos_c)
    plo = zero
    for ppanel in range(3):
        phi_hi = _panel_end(ppanel, p0, p1, wp.float64(wp.pi))
        if phi_hi > plo:
            for j in range(p_x.shape[0]):
                phi = plo + (phi_hi - plo) * p_x[j]
                pw = (phi_hi - plo) * p_w[j]
                u0, u1 = _tir_breaks(wi, a, phi, cos_c)
                lo = zero
                for panel in range(3):
                    hi = _panel_end(panel, u0, u1, one)
                    if hi > lo:
                        for i in range(u_x.shape[0]):
                            u = lo + (hi - lo) * u_x[i]
                            value = _integrand(wi, a, u, phi, eta[q], k[q], fresnel)
                            total += (hi - lo) * u_w[i] * pw * value
                        lo = hi
            plo = phi_hi
    # phi over [0, pi] counts half the circle; the measure is du dphi / (2 pi)
    out[q] = total / wp.float64(wp.pi)


def _nodes(n_u: int, n_phi: int):
    x, w = np.polynomial.legendre.leggauss(n_u)
    u_x, u_w = 0.5 * (x + 1.0), 0.5 * w
    x, w = np.polynomial.legendre.leggauss(n_phi)
    p_x, p_w = 0.5 * (x + 1.0), 0.5 * w
    return u_x, u_w, p_x, p_w


def _launch(mu, alpha, eta, k, fresnel: bool, n_u: int, n_phi: int) -> np.ndarray:
    mu, alpha, eta, k = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64)
                                               for v in (mu, alpha, eta, k)))
    shape = mu.shape
    if mu.size == 0:
        return np.zeros(shape)
    device = device_for("cpu")
    arrays = [host_array(v.reshape(-1), wp.float64, device) for v in (mu, alpha, eta, k)]
    nodes = [host_array(v, wp.float64, device) for v in _nodes(n_u, n_phi)]
    out = wp.zeros(mu.size, dtype=wp.float64, device=device)
    wp.launch(_fgd_kernel, dim=mu.size, inputs=[*arrays, int(fresnel), *nodes, out],
              device=device)
    return out.numpy().reshape(shape)


def fgd(mu, alpha, eta, k=0.0, n_u: int = U_NODES, n_phi: int = PHI_NODES) -> np.ndarray:
    """Directional albedo of a GGX interface's reflection, with Fresnel.

    Parameters
    ----------
    mu : array_like
        Cosine of the incident direction (0, 1] (values below 1e-6 are taken as 1e-6).
    alpha : array_like
        GGX roughness (>= 0; 0: the Fresnel reflectance).
    eta, k : array_like
        Index below the interface relative to the one above (``eta < 1``: light in the denser
        medium, with total internal reflection); ``k > 0``: a conductor.
    n_u, n_phi : int
        Gauss-Legendre nodes in ``u`` and in ``phi`` (over [0, pi]).

    Returns
    -------
    ndarray, float64, the broadcast shape of the inputs: the reflected energy fraction.
    """
    return _launch(mu, alpha, eta, k, True, n_u, n_phi)


def ggx_albedo(mu, alpha, n_u: int = U_NODES, n_phi: int = PHI_NODES) -> np.ndarray:
    """Directional albedo of the GGX reflection lobe without Fresnel, ``int D G2 / (4 mu_i)
    dw_h``-style (Smith's shadowing-masking loses 0-20 % of the energy at large roughness and
    grazing incidence). Same parameters and quadrature as :func:`fgd`."""
    return _launch(mu, alpha, 1.0, 0.0, False, n_u, n_phi)


@wp.kernel
def _lobe_kernel(wi: wp.array(dtype=wp.vec3d), wo: wp.array(dtype=wp.vec3d),
                 alpha: wp.float64, out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    zero = wp.float64(0.0)
    a, b = wi[q], wo[q]
    out[q] = zero
    if a[2] <= zero or b[2] <= zero:
        return
    h = wp.normalize(a + b)
    g = physics.smith_g1(a, h, alpha, alpha, physics.GGX) * physics.smith_g1(
        b, h, alpha, alpha, physics.GGX)
    out[q] = physics.ndf(h, alpha, alpha, physics.GGX) * g * physics.microfacet_reflection_factor(
        wp.float64(1.0), a, b)


@wp.kernel
def _masking_kernel(wo: wp.array(dtype=wp.vec3d), m: wp.array(dtype=wp.vec3d),
                    alpha: wp.float64, out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    out[q] = wp.float64(0.0)
    if wo[q][2] > wp.float64(0.0):
        out[q] = physics.smith_g1(wo[q], m[q], alpha, alpha, physics.GGX)


def _vec_launch(kernel, a, b, alpha: float) -> np.ndarray:
    a = np.ascontiguousarray(np.asarray(a, dtype=np.float64).reshape(-1, 3))
    b = np.ascontiguousarray(np.asarray(b, dtype=np.float64).reshape(-1, 3))
    if a.shape[0] == 0:
        return np.zeros(0)
    device = device_for("cpu")
    wa = wp.array(a, dtype=wp.vec3d, device=device)
    wb = wp.array(b, dtype=wp.vec3d, device=device)
    out = wp.zeros(a.shape[0], dtype=wp.float64, device=device)
    wp.launch(kernel, dim=a.shape[0], inputs=[wa, wb, float(alpha), out], device=device)
    return out.numpy()


def ggx_lobe(wi, wo, alpha: float) -> np.ndarray:
    """GGX reflection lobe without Fresnel, ``D(h) G2(wi, wo) / (4 wi.z wo.z)`` (1/sr) for
    direction pairs of shape (n, 3) (0 unless both lie above the surface)."""
    return _vec_launch(_lobe_kernel, wi, wo, alpha)


def smith_masking(wo, m, alpha: float) -> np.ndarray:
    """Smith masking ``G1(wo, m)`` of GGX (0 below the horizon), pairs of shape (n, 3)."""
    return _vec_launch(_masking_kernel, wo, m, alpha)
