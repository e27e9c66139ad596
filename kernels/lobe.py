"""Host access to the rough-interface physics of :mod:`layersim.kernels.physics` at given
directions and microfacet normals, for the near-specular interfaces of :mod:`layersim.solved.lobe`
(the direct reflection lobe, its energy and the transmitted energy come from the same functions
as the Monte Carlo walk's microfacet events). ``k > 0`` selects a conductor (complex relative
index ``eta + i k``), which reflects with the conductor Fresnel term and transmits nothing."""

from __future__ import annotations

import numpy as np
import warp as wp

from . import physics, sampling
from .runtime import device_for, ensure_init


@wp.kernel
def _eval_kernel(wi: wp.array(dtype=wp.vec3d), wo: wp.array(dtype=wp.vec3d), eta: wp.float64,
                 k: wp.float64, au: wp.float64, av: wp.float64, dist: int,
                 out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    out[q] = physics.microfacet_eval(wi[q], wo[q], eta, k, au, av, dist)


@wp.kernel
def _facet_kernel(wi: wp.array(dtype=wp.vec3d), m: wp.array(dtype=wp.vec3d), eta: wp.float64,
                  k: wp.float64, au: wp.float64, av: wp.float64, dist: int,
                  vis: wp.array2d(dtype=wp.float64), refl: wp.array2d(dtype=wp.float64),
                  trans: wp.array2d(dtype=wp.float64), wo: wp.array2d(dtype=wp.vec3d)):
    q, j = wp.tid()
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    w = wi[q]
    n = m[j]
    c = wp.dot(w, n)
    vis[q, j] = zero
    refl[q, j] = zero
    trans[q, j] = zero
    wo[q, j] = wp.vec3d(zero, zero, one)
    if c <= zero or w[2] <= zero:
        return
    # visible-normal density relative to D(m) cos(theta_m): G1(wi, m) (wi.m) / (wi.z m.z)
    vis[q, j] = physics.smith_g1(w, n, au, av, dist) * c / (w[2] * n[2])
    r = n * (wp.float64(2.0) * c) - w
    wo[q, j] = r
    if k > zero:
        refl[q, j] = physics.fresnel_conductor(c, eta, k) * physics.smith_g1(r, n, au, av, dist)
        return
    f = physics.fresnel_dielectric(c, eta)
    refl[q, j] = f * physics.smith_g1(r, n, au, av, dist)
    # refraction into the denser side (eta > 1: no total internal reflection from above)
    s = one - (one - c * c) / (eta * eta)
    t = -w / eta + n * (c / eta - wp.sqrt(wp.max(s, zero)))
    trans[q, j] = (one - f) * physics.smith_g1(t, n, au, av, dist)


@wp.kernel
def _sample_kernel(wi: wp.array(dtype=wp.vec3d), u: wp.array2d(dtype=wp.float64),
                   au: wp.float64, av: wp.float64, dist: int, wo: wp.array(dtype=wp.vec3d)):
    q = wp.tid()
    m = sampling.sample_vndf(wi[q], au, av, dist, u[q, 0], u[q, 1], u[q, 2])
    wo[q] = sampling.reflect(wi[q], m)


@wp.kernel
def _pdf_kernel(wi: wp.array(dtype=wp.vec3d), wo: wp.array(dtype=wp.vec3d), au: wp.float64,
                av: wp.float64, dist: int, out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    zero = wp.float64(0.0)
    out[q] = zero
    h = wi[q] + wo[q]
    if wi[q][2] <= zero or wo[q][2] <= zero or wp.dot(h, h) <= zero:
        return
    m = wp.normalize(h)
    # reflection maps the visible-normal density to directions with 1 / (4 |wo.m|)
    out[q] = sampling.vndf_pdf(wi[q], m, au, av, dist) / (wp.float64(4.0) * wp.dot(wo[q], m))


@wp.kernel
def _refract_kernel(wi: wp.array(dtype=wp.vec3d), m: wp.array(dtype=wp.vec3d), eta: wp.float64,
                    wt: wp.array(dtype=wp.vec3d)):
    q = wp.tid()
    t, ok = sampling.refract(wi[q], m[q], eta)
    zero = wp.float64(0.0)
    wt[q] = wp.vec3d(zero, zero, zero)
    if ok:
        wt[q] = t


def _vec(a) -> wp.array:
    return wp.array(np.ascontiguousarray(a, dtype=np.float64).reshape(-1, 3), dtype=wp.vec3d,
                    device=device_for("cpu"))


def microfacet_reflection(wi, wo, eta: float, alpha_u: float, alpha_v: float,
                          distribution: str, k: float = 0.0) -> np.ndarray:
    """Microfacet BSDF ``f(wi, wo)`` (1/sr, no cosine; :func:`physics.microfacet_eval`) of a
    rough interface of relative index ``eta + i k``, directions ``(Q, 3)`` in its tangent
    frame."""
    ensure_init()
    wi = np.asarray(wi, float).reshape(-1, 3)
    if wi.shape[0] == 0:
        return np.zeros(0)
    out = wp.zeros(wi.shape[0], dtype=wp.float64, device=device_for("cpu"))
    wp.launch(_eval_kernel, dim=wi.shape[0],
              inputs=[_vec(wi), _vec(wo), float(eta), float(k), float(alpha_u), float(alpha_v),
                      int(physics.DISTRIBUTION_CODES[distribution])],
              outputs=[out], device=device_for("cpu"))
    return out.numpy()


def facet_events(wi, m, eta: float, alpha_u: float, alpha_v: float, distribution: str,
                 k: float = 0.0):
    """Per incident direction ``wi`` (Q, 3) and microfacet normal ``m`` (K, 3), both in the
    tangent frame: the visible-normal factor ``G1(wi, m) (wi.m) / (wi.z m.z)``, the reflected
    and refracted weights ``F G1(wo, m)`` and ``(1 - F) G1(wt, m)`` (0 where the event leaves
    on the wrong side: the single-scattering loss), and the reflected direction; arrays
    (Q, K) and (Q, K, 3)."""
    ensure_init()
    wi = np.asarray(wi, float).reshape(-1, 3)
    m = np.asarray(m, float).reshape(-1, 3)
    dev = device_for("cpu")
    shape = (wi.shape[0], m.shape[0])
    outs = [wp.zeros(shape, dtype=wp.float64, device=dev) for _ in range(3)]
    wo = wp.zeros(shape, dtype=wp.vec3d, device=dev)
    wp.launch(_facet_kernel, dim=shape,
              inputs=[_vec(wi), _vec(m), float(eta), float(k), float(alpha_u), float(alpha_v),
                      int(physics.DISTRIBUTION_CODES[distribution])],
              outputs=[*outs, wo], device=dev)
    return (*(o.numpy() for o in outs), wo.numpy())


def sample_reflection(wi, u, alpha_u: float, alpha_v: float, distribution: str) -> np.ndarray:
    """Directions ``wo`` (Q, 3) reflected about visible microfacet normals drawn for ``wi``
    (Q, 3, upper hemisphere, tangent frame) with uniforms ``u`` (Q, 3)
    (:func:`sampling.sample_vndf`); ``wo`` may point below the surface (no sample)."""
    ensure_init()
    wi = np.asarray(wi, float).reshape(-1, 3)
    dev = device_for("cpu")
    wo = wp.zeros(wi.shape[0], dtype=wp.vec3d, device=dev)
    if wi.shape[0]:
        wp.launch(_sample_kernel, dim=wi.shape[0],
                  inputs=[_vec(wi), wp.array(np.ascontiguousarray(u, dtype=np.float64),
                                             dtype=wp.float64, device=dev),
                          float(alpha_u), float(alpha_v),
                          int(physics.DISTRIBUTION_CODES[distribution])],
                  outputs=[wo], device=dev)
    return wo.numpy()


def reflection_pdf(wi, wo, alpha_u: float, alpha_v: float, distribution: str) -> np.ndarray:
    """Solid-angle density (1/sr) of :func:`sample_reflection` at ``wo`` (Q, 3) for ``wi``
    (Q, 3): ``D_wi(m) / (4 |wo.m|)`` at the half vector; 0 unless both lie above."""
    ensure_init()
    wi = np.asarray(wi, float).reshape(-1, 3)
    dev = device_for("cpu")
    out = wp.zeros(wi.shape[0], dtype=wp.float64, device=dev)
    if wi.shape[0]:
        wp.launch(_pdf_kernel, dim=wi.shape[0],
                  inputs=[_vec(wi), _vec(wo), float(alpha_u), float(alpha_v),
                          int(physics.DISTRIBUTION_CODES[distribution])],
                  outputs=[out], device=dev)
    return out.numpy()


def refraction(wi, m, eta: float) -> np.ndarray:
    """Directions (Q, 3) refracted from ``wi`` (Q, 3, pointing away from the boundary)
    through microfacet normals ``m`` (Q, 3) of relative index ``eta``
    (:func:`sampling.refract`, the walk's own); (0, 0, 0) under total internal reflection."""
    ensure_init()
    wi = np.asarray(wi, float).reshape(-1, 3)
    dev = device_for("cpu")
    wt = wp.zeros(wi.shape[0], dtype=wp.vec3d, device=dev)
    if wi.shape[0]:
        wp.launch(_refract_kernel, dim=wi.shape[0], inputs=[_vec(wi), _vec(m), float(eta)],
                  outputs=[wt], device=dev)
    return wt.numpy()
