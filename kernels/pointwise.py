"""Host access to the pointwise physics of :mod:`layersim.kernels.physics` on NumPy arrays.

Host code that needs the value of a physics formula at many points (the forward model of
single-view NDF fitting, weights of the projection, quadrature nodes of the near-specular lobe)
calls these wrappers instead of writing the formula again: each copies its arrays to the device,
launches a map kernel (one thread per element, float64) around the Warp function and reads the
result back, so the host sees exactly the values that the projection kernels and the random walk
compute. Arrays are float64 on the CPU device unless ``device`` names another one.

Conventions are those of :mod:`layersim.kernels.physics`: unit vectors of shape ``(..., 3)`` in
the tangent frame of the interface (``z`` the macro-surface normal, the roughness ``alpha_u``
along ``x``), NDF values in 1/sr normalised to unit projected area, BSDF values in 1/sr without
the cosine factor. ``distribution`` is ``"beckmann"`` or ``"ggx"``.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from . import physics
from .runtime import device_for

wp.set_module_options({"enable_backward": False})


@wp.kernel
def _ndf_kernel(m: wp.array(dtype=wp.vec3d), au: wp.float64, av: wp.float64, dist: int,
                out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    out[q] = physics.ndf(m[q], au, av, dist)


@wp.kernel
def _g1_kernel(w: wp.array(dtype=wp.vec3d), au: wp.float64, av: wp.float64, dist: int,
               out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    zero = wp.float64(0.0)
    out[q] = physics.smith_g1(w[q], wp.vec3d(zero, zero, wp.float64(1.0)), au, av, dist)


@wp.kernel
def _peak_kernel(x: wp.array(dtype=wp.float64), dist: int, out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    out[q] = physics.ndf_peak(x[q], dist)


@wp.kernel
def _slope_kernel(u: wp.array(dtype=wp.float64), alpha: wp.float64, dist: int,
                  out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    out[q] = physics.slope_radius(u[q], alpha, dist)


@wp.kernel
def _reflection_kernel(wi: wp.array(dtype=wp.vec3d), wo: wp.array(dtype=wp.vec3d),
                       d: wp.array(dtype=wp.float64), s_i: wp.array(dtype=wp.float64),
                       s_o: wp.array(dtype=wp.float64), eta: wp.float64, fresnel: int,
                       out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    zero = wp.float64(0.0)
    a = wi[q]
    b = wo[q]
    out[q] = zero
    if a[2] <= zero or b[2] <= zero:
        return
    f = wp.float64(1.0)
    if fresnel != 0:
        f = physics.fresnel_dielectric(wp.dot(a, wp.normalize(a + b)), eta)
    out[q] = d[q] * s_i[q] * s_o[q] * physics.microfacet_reflection_factor(f, a, b)


@wp.kernel
def _g2_kernel(wi: wp.array(dtype=wp.vec3d), wo: wp.array(dtype=wp.vec3d),
               m: wp.array(dtype=wp.vec3d), au: wp.float64, av: wp.float64, dist: int,
               shadow: int, out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    out[q] = physics.smith_g2(wi[q], wo[q], m[q], au, av, dist, shadow)


@wp.kernel
def _bsdf_kernel(wi: wp.array(dtype=wp.vec3d), wo: wp.array(dtype=wp.vec3d), eta: wp.float64,
                 k: wp.float64, au: wp.float64, av: wp.float64, dist: int, shadow: int,
                 out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    zero = wp.float64(0.0)
    out[q] = physics.microfacet_eval_shadowed(wi[q], wo[q], eta, k, zero, zero, au, av, dist,
                                              shadow)


def _code(distribution: str) -> int:
    try:
        return int(physics.DISTRIBUTION_CODES[distribution])
    except (KeyError, TypeError):
        raise ValueError(f"distribution must be 'ggx' or 'beckmann', not {distribution!r}") \
            from None


def _shadow_code(shadowing: str) -> int:
    try:
        return int(physics.SHADOWING_CODES[shadowing])
    except (KeyError, TypeError):
        raise ValueError("shadowing must be one of " + ", ".join(physics.SHADOWING_CODES)
                         + f", not {shadowing!r}") from None


def _vectors(v, name: str) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    if v.ndim == 0 or v.shape[-1] != 3:
        raise ValueError(f"{name} must be an array of vectors of shape (..., 3), got shape "
                         f"{v.shape}")
    return v


def _map(kernel, inputs, params, shape, device) -> np.ndarray:
    """Launch ``kernel`` over ``inputs`` (flat host arrays with their Warp dtypes) and the
    scalar ``params``; the result has ``shape``."""
    size = int(np.prod(shape, dtype=np.int64))
    if size == 0:
        return np.zeros(shape)
    dev = device_for(device)
    arrays = [wp.array(np.ascontiguousarray(a), dtype=t, device=dev) for a, t in inputs]
    out = wp.zeros(size, dtype=wp.float64, device=dev)
    wp.launch(kernel, dim=size, inputs=[*arrays, *params], outputs=[out], device=dev)
    return out.numpy().reshape(shape)


def ndf(m, alpha_u: float, alpha_v: float, distribution: str, device: str = "cpu") -> np.ndarray:
    """Microfacet normal distribution ``D(m)`` (:func:`physics.ndf`).

    Parameters
    ----------
    m : array_like, shape (..., 3)
        Unit microfacet normals in the tangent frame.
    alpha_u, alpha_v : float
        Roughness along ``x`` and ``y``.
    distribution : str
        ``"beckmann"`` or ``"ggx"``.
    device : str
        Warp device of the launch.

    Returns
    -------
    ndarray, float64, shape ``m.shape[:-1]``: D in 1/sr, 0 where ``m.z <= 0``.
    """
    m = _vectors(m, "m")
    return _map(_ndf_kernel, [(m.reshape(-1, 3), wp.vec3d)],
                [float(alpha_u), float(alpha_v), _code(distribution)], m.shape[:-1], device)


def smith_g1(w, alpha_u: float, alpha_v: float, distribution: str,
             device: str = "cpu") -> np.ndarray:
    """Smith masking ``G1(w, n) = 1 / (1 + Lambda(w))`` about the macro-surface normal
    ``n = (0, 0, 1)`` (:func:`physics.smith_g1`): the shadowing ``S(k)`` of Wang et al. 2008,
    eq. (4)-(5), of an analytic NDF.

    Parameters
    ----------
    w : array_like, shape (..., 3)
        Unit directions in the tangent frame (``Lambda`` uses ``|w.z|``).
    alpha_u, alpha_v, distribution, device
        As :func:`ndf`.

    Returns
    -------
    ndarray, float64, shape ``w.shape[:-1]``, in [0, 1]; 0 on the horizon (``w.z = 0``).
    """
    w = _vectors(w, "w")
    return _map(_g1_kernel, [(w.reshape(-1, 3), wp.vec3d)],
                [float(alpha_u), float(alpha_v), _code(distribution)], w.shape[:-1], device)


def smith_g2(wi, wo, m, alpha_u: float, alpha_v: float, distribution: str, shadowing: str,
             device: str = "cpu") -> np.ndarray:
    """Smith shadowing-masking ``G2(wi, wo, m)`` of a pair and a microfacet normal
    (:func:`physics.smith_g2`; Heitz 2014, sec. 6).

    Parameters
    ----------
    wi, wo, m : array_like, shape (..., 3)
        Unit directions and microfacet normals in the tangent frame (broadcast together).
    alpha_u, alpha_v, distribution, device
        As :func:`ndf`.
    shadowing : str
        ``"separable"``, ``"height-correlated"`` or ``"height-correlated-beta"``.

    Returns
    -------
    ndarray, float64, the broadcast shape without the last axis, in [0, 1].
    """
    wi, wo, m = np.broadcast_arrays(_vectors(wi, "wi"), _vectors(wo, "wo"), _vectors(m, "m"))
    return _map(_g2_kernel, [(x.reshape(-1, 3), wp.vec3d) for x in (wi, wo, m)],
                [float(alpha_u), float(alpha_v), _code(distribution), _shadow_code(shadowing)],
                wi.shape[:-1], device)


def microfacet_bsdf(wi, wo, eta: complex, alpha: float, distribution: str, shadowing: str,
                    device: str = "cpu") -> np.ndarray:
    """BSDF ``f(wi, wo)`` (1/sr, no cosine) of an isotropic rough interface without a film
    (:func:`physics.microfacet_eval_shadowed`): a dielectric where ``eta`` is real, a conductor
    where ``eta.imag > 0``; the shapes of :func:`smith_g2`."""
    wi, wo = np.broadcast_arrays(_vectors(wi, "wi"), _vectors(wo, "wo"))
    eta = complex(eta)
    return _map(_bsdf_kernel, [(x.reshape(-1, 3), wp.vec3d) for x in (wi, wo)],
                [eta.real, eta.imag, float(alpha), float(alpha), _code(distribution),
                 _shadow_code(shadowing)], wi.shape[:-1], device)


def ndf_peak(q, distribution: str, device: str = "cpu") -> np.ndarray:
    """Peak factor of the NDF at the slope-space form ``q`` (:func:`physics.ndf_peak`):
    ``exp(-q)`` (Beckmann) or ``1 / (1 + q)^2`` (GGX); float64, the shape of ``q``."""
    q = np.asarray(q, dtype=np.float64)
    return _map(_peak_kernel, [(q.reshape(-1), wp.float64)], [_code(distribution)], q.shape,
                device)


def slope_radius(u, alpha: float, distribution: str, device: str = "cpu") -> np.ndarray:
    """Slope radius ``tan(theta_m)`` at cumulative slope probability ``u`` in [0, 1) of the
    isotropic distribution of roughness ``alpha`` (:func:`physics.slope_radius`); float64, the
    shape of ``u``."""
    u = np.asarray(u, dtype=np.float64)
    return _map(_slope_kernel, [(u.reshape(-1), wp.float64)],
                [float(alpha), _code(distribution)], u.shape, device)


def microfacet_brdf(wi, wo, d, s_i, s_o, eta: float | None = None,
                    device: str = "cpu") -> np.ndarray:
    """Microfacet BRDF ``f = D(h) S(wi) S(wo) F / (4 wi.z wo.z)`` from given values of ``D``
    and ``S`` (Wang et al. 2008, eq. 2 and 4; :func:`physics.microfacet_reflection_factor`),
    for an NDF and a shadowing term known only as values (a table, a fit).

    Parameters
    ----------
    wi, wo : array_like, shape (N, 3)
        Unit directions toward the light and the viewer.
    d : array_like, shape (N,)
        ``D`` at the half vectors ``h = (wi + wo) / |wi + wo|`` (1/sr, any scale).
    s_i, s_o : array_like, shape (N,)
        Shadowing ``S(wi)``, ``S(wo)``.
    eta : float or None
        Relative index of the dielectric Fresnel factor ``F(wi . h)``
        (:func:`physics.fresnel_dielectric`); None: ``F = 1``, as the paper's fit assumes.
    device : str
        Warp device of the launch.

    Returns
    -------
    ndarray, float64, shape (N,): f in 1/sr (times the scale of ``d``), 0 where either
    direction is not above the surface; NaN in ``d`` or ``S`` propagates.
    """
    wi, wo = _vectors(wi, "wi").reshape(-1, 3), _vectors(wo, "wo").reshape(-1, 3)
    n = wi.shape[0]
    vals = [np.broadcast_to(np.asarray(v, dtype=np.float64).reshape(-1), (n,))
            for v in (d, s_i, s_o)]
    return _map(_reflection_kernel, [(wi, wp.vec3d), (wo, wp.vec3d)]
                + [(v, wp.float64) for v in vals],
                [1.0 if eta is None else float(eta), int(eta is not None)], (n,), device)
