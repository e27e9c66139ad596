"""Kernels that sample interface BSDFs for Fourier projection.

The host solver (``layersim.ingredients``) decides *where* to sample (ordinate pairs and azimuths);
these kernels only evaluate the physics of :mod:`layersim.kernels.physics` there, in float64.

Geometry of a sample: an ordinate pair is given in the solver's convention (``mu > 0`` travels
deeper into the stack): incident ``mu_i``, outgoing ``mu_o`` and the azimuth difference ``phi``
between the *propagation* directions. With the incident light propagating along azimuth 0, the
outward-pointing directions of ``docs/conventions.md`` are::

    wi = (-sqrt(1 - mu_i^2), 0, mu_i)                       (points back toward the source)
    wo = (sqrt(1 - mu_o^2) cos phi, sqrt(1 - mu_o^2) sin phi, -mu_o)

so that ``phi = 0`` is the forward (specular or straight-through) direction.
"""

from __future__ import annotations

import numpy as np
import scipy.fft
import warp as wp

from . import measured, physics, tabulated
from .runtime import device_for, ensure_init, host_array


@wp.func
def _pair_directions(mu_i: wp.float64, mu_o: wp.float64, phi: wp.float64):
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    si = wp.sqrt(wp.max(one - mu_i * mu_i, zero))
    so = wp.sqrt(wp.max(one - mu_o * mu_o, zero))
    wi = wp.vec3d(-si, zero, mu_i)
    wo = wp.vec3d(so * wp.cos(phi), so * wp.sin(phi), -mu_o)
    return wi, wo


@wp.kernel
def _microfacet_split_kernel(mu_i: wp.array(dtype=wp.float64), mu_o: wp.array(dtype=wp.float64),
                             phi: wp.array2d(dtype=wp.float64), eta: wp.float64,
                             k: wp.float64, ef: wp.float64, ps: wp.float64, au: wp.float64,
                             av: wp.float64, dist: int, shadow: int,
                             smooth: wp.array2d(dtype=wp.float64),
                             q: wp.array2d(dtype=wp.float64)):
    p, j = wp.tid()
    wi, wo = _pair_directions(mu_i[p], mu_o[p], phi[p, j])
    s, qq = physics.microfacet_smooth_q_shadowed(wi, wo, eta, k, ef, ps, au, av, dist,
                                                 shadow)
    smooth[p, j] = s
    q[p, j] = qq


@wp.kernel
def _microfacet_eval_kernel(mu_i: wp.array(dtype=wp.float64), mu_o: wp.array(dtype=wp.float64),
                            phi: wp.array2d(dtype=wp.float64), eta: wp.float64,
                            k: wp.float64, ef: wp.float64, ps: wp.float64, au: wp.float64,
                            av: wp.float64, dist: int, shadow: int,
                            f: wp.array2d(dtype=wp.float64)):
    p, j = wp.tid()
    wi, wo = _pair_directions(mu_i[p], mu_o[p], phi[p, j])
    f[p, j] = physics.microfacet_eval_shadowed(wi, wo, eta, k, ef, ps, au, av, dist,
                                                shadow)


def _launch_pairs(kernel, mu_i, mu_o, phi, params, n_out, device=None):
    ensure_init()
    device = device_for(device)
    mu_i = np.ascontiguousarray(mu_i, dtype=np.float64)
    mu_o = np.ascontiguousarray(mu_o, dtype=np.float64)
    phi = np.ascontiguousarray(phi, dtype=np.float64)
    if phi.ndim != 2 or phi.shape[0] != mu_i.shape[0] or mu_o.shape != mu_i.shape:
        raise ValueError("expected mu_i, mu_o of shape (P,) and phi of shape (P, Q)")
    if phi.size == 0:
        return [np.zeros(phi.shape) for _ in range(n_out)]
    a_mi = wp.array(mu_i, dtype=wp.float64, device=device)
    a_mo = wp.array(mu_o, dtype=wp.float64, device=device)
    a_phi = wp.array(phi, dtype=wp.float64, device=device)
    outs = [wp.empty(phi.shape, dtype=wp.float64, device=device) for _ in range(n_out)]
    wp.launch(kernel, dim=phi.shape, inputs=[a_mi, a_mo, a_phi, *params], outputs=outs,
              device=device)
    return [o.numpy() for o in outs]


def _interface_params(eta: complex, au: float, av: float, distribution: str,
                      film: tuple | None = None, shadowing: str = "separable"):
    """Kernel parameters ``eta, k, eta_film, phase_scale, alpha_u, alpha_v, dist, shadow`` of
    an interface; ``film`` = (index relative to the medium above, phase scale) or None (phase 0:
    the bare interface, :func:`physics.fresnel_interface`); ``shadowing`` the Smith term
    (:data:`physics.SHADOWING_CODES`, :func:`physics.smith_g2`)."""
    ef, ps = film if film is not None else (0.0, 0.0)
    return [wp.float64(complex(eta).real), wp.float64(complex(eta).imag), wp.float64(ef),
            wp.float64(ps), wp.float64(au), wp.float64(av),
            int(physics.DISTRIBUTION_CODES[distribution]),
            int(physics.SHADOWING_CODES[shadowing])]


def microfacet_split(mu_i, mu_o, phi, eta, alpha_u, alpha_v, distribution="beckmann",
                     device=None, film=None, shadowing="separable"):
    """Sample the split microfacet BSDF ``f = smooth * peak(q)`` of an interface.

    Parameters
    ----------
    mu_i, mu_o : ndarray, shape (P,)
        Signed ordinates of each pair (solver convention, see module doc).
    phi : ndarray, shape (P, Q)
        Azimuth differences (radians) at which to sample each pair.
    eta : complex
        Relative index below/above (``eta + i k`` for a conductor).
    alpha_u, alpha_v : float
        Roughness along the tangent axes (the isotropic path passes equal values).
    film : (float, float), optional
        A thin film on the interface: its index relative to the medium above and its phase
        scale ``4 pi n d / lambda`` (:meth:`layersim.layers.Interface.film_params`); every
        function of this module that takes ``film`` evaluates the filmed BSDF
        (:func:`physics.microfacet_eval_film`).
    shadowing : str
        The Smith shadowing-masking term, "separable" or "height-correlated"
        (:func:`physics.smith_g2`); every function of this module that takes ``shadowing``
        evaluates the BSDF with it.

    Returns
    -------
    smooth, q : ndarray, shape (P, Q)
        Smooth factor (1/sr) and slope-space form of :func:`physics.microfacet_smooth_q`.
    """
    return _launch_pairs(_microfacet_split_kernel, mu_i, mu_o, phi,
                         _interface_params(eta, alpha_u, alpha_v, distribution, film,
                                           shadowing), 2, device)


def microfacet_values(mu_i, mu_o, phi, eta, alpha_u, alpha_v, distribution="beckmann",
                      device=None, film=None, shadowing="separable"):
    """Full microfacet BSDF values f (1/sr) at the same sample layout as
    :func:`microfacet_split`."""
    return _launch_pairs(_microfacet_eval_kernel, mu_i, mu_o, phi,
                         _interface_params(eta, alpha_u, alpha_v, distribution, film,
                                           shadowing), 1, device)[0]


# ---------------------------------------------------------------------------------------------
# Numeric projection: the BSDF on a uniform azimuth grid, then a discrete Fourier transform
# ---------------------------------------------------------------------------------------------

@wp.kernel
def _uniform_eval_kernel(mu_i: wp.array(dtype=wp.float64), mu_o: wp.array(dtype=wp.float64),
                         eta: wp.float64, k: wp.float64, ef: wp.float64, ps: wp.float64,
                         au: wp.float64, av: wp.float64, dist: int, shadow: int,
                         f: wp.array2d(dtype=wp.float64)):
    """f[p, j] = BSDF at phi_j = pi j / M, j = 0..M (M + 1 = f.shape[1]): half a period of the
    even azimuthal function."""
    p, j = wp.tid()
    M = f.shape[1] - 1
    phi = wp.float64(wp.pi) * wp.float64(j) / wp.float64(M)
    wi, wo = _pair_directions(mu_i[p], mu_o[p], phi)
    f[p, j] = physics.microfacet_eval_shadowed(wi, wo, eta, k, ef, ps, au, av, dist,
                                                shadow)


@wp.func
def _dct1(f: wp.array(dtype=wp.float64), base: wp.int64, M: int, l: int,
          table: wp.array(dtype=wp.float64), stride: int):
    """Trapezoidal cosine coefficient ``l`` of half-period samples ``f[base .. base + M]`` (a
    DCT-I): (2 - delta_l0) / (2M) [f_0 + (-1)^l f_M + 2 sum_{0<j<M} f_j cos(pi l j / M)],
    cosines read from an exact table, ``table[i stride] = cos(pi i / M)``, i < 2M (index l j
    mod 2M). Orders beyond the Nyquist order M carry no information: zero (the CPU path's DCT
    returns M + 1 orders and zero-pads the rest)."""
    if l > M:
        return wp.float64(0.0)
    two_m = 2 * M
    acc = f[base]
    idx = l
    for j in range(1, M):
        if idx >= two_m:
            idx -= two_m
        acc += wp.float64(2.0) * f[base + wp.int64(j)] * table[idx * stride]
        idx += l
    last = f[base + wp.int64(M)]
    if l % 2 == 1:
        last = -last
    acc += last
    scale = wp.float64(1.0) / wp.float64(M)
    if l == 0:
        scale = wp.float64(0.5) / wp.float64(M)
    return acc * scale


@wp.kernel
def _cosine_dct_kernel(f: wp.array(dtype=wp.float64), M: int,
                       table: wp.array(dtype=wp.float64), c: wp.array2d(dtype=wp.float64)):
    """c[p, l] = :func:`_dct1` of row p of the (P, M + 1) samples ``f`` (flattened)."""
    p, l = wp.tid()
    c[p, l] = _dct1(f, wp.int64(p) * wp.int64(M + 1), M, l, table, 1)


def uniform_cosine_series(mu_i, mu_o, eta, alpha_u, alpha_v, distribution, samples: int,
                          orders: int, device=None, dct_kernel: bool | None = None,
                          film=None, shadowing="separable") -> np.ndarray:
    """Cosine coefficients ``f_0 .. f_{orders-1}`` of the BSDF of ordinate pairs from the
    trapezoidal rule with ``samples`` (even) uniform azimuths per period, exact up to aliasing of
    orders beyond ``samples - orders``. The azimuthal function is even, so only the
    ``samples / 2 + 1`` azimuths of [0, pi] are evaluated and a DCT-I gives the coefficients.

    On a CUDA device the samples stay on the device: a table-driven DCT kernel computes the
    requested orders and only those are copied back. On the CPU the kernel samples and scipy's
    DCT transforms. ``dct_kernel`` forces either transform (default: the kernel on CUDA only).
    Orders past ``samples / 2`` are zero.
    """
    ensure_init()
    dev = device_for(device)
    mu_i = np.ascontiguousarray(mu_i, dtype=np.float64)
    mu_o = np.ascontiguousarray(mu_o, dtype=np.float64)
    P = mu_i.size
    if P == 0:
        return np.zeros((0, orders))
    if samples % 2:
        raise ValueError("samples must be even")
    M = samples // 2
    params = _interface_params(eta, alpha_u, alpha_v, distribution, film, shadowing)
    f = wp.empty((P, M + 1), dtype=wp.float64, device=dev)
    wp.launch(_uniform_eval_kernel, dim=(P, M + 1), device=dev,
              inputs=[wp.array(mu_i, dtype=wp.float64, device=dev),
                      wp.array(mu_o, dtype=wp.float64, device=dev), *params], outputs=[f])
    if dev.is_cuda if dct_kernel is None else dct_kernel:
        table = np.cos(np.pi * np.arange(2 * M) / M)
        c = wp.empty((P, orders), dtype=wp.float64, device=dev)
        wp.launch(_cosine_dct_kernel, dim=(P, orders), device=dev,
                  inputs=[f.flatten(), M, wp.array(table, dtype=wp.float64, device=dev)],
                  outputs=[c])
        return c.numpy()
    coef = scipy.fft.dct(f.numpy(), type=1, axis=1)[:, :orders] / M
    coef[:, 0] *= 0.5
    out = np.zeros((P, orders))
    out[:, :coef.shape[1]] = coef
    return out


# Whole blocks on the device: coarse energy bound, ragged sampling, DCT, truncation
# ---------------------------------------------------------------------------------------------
#
# The numeric path on a GPU keeps a block's samples and series on the device
# (``layersim.ingredients.numeric``): each pair ``p`` has its own half period ``M_p`` (a power of
# two, so one cosine table of the largest ``M`` serves all pairs) and its samples live in one flat
# array at ``start[p]``.


@wp.kernel
def _coarse_bound_kernel(mu_i: wp.array(dtype=wp.float64), mu_o: wp.array(dtype=wp.float64),
                         n_phi: int, eta: wp.float64, k: wp.float64, ef: wp.float64,
                         ps: wp.float64, au: wp.float64, av: wp.float64, dist: int, shadow: int,
                         smax: wp.array(dtype=wp.float64),
                         q0: wp.array(dtype=wp.float64), qpi: wp.array(dtype=wp.float64)):
    """Largest |smooth factor| over ``n_phi`` azimuths pi j / (n_phi - 1), and the slope-space
    form q at phi = 0 and pi, of each pair."""
    p = wp.tid()
    big = wp.float64(0.0)
    for j in range(n_phi):
        phi = wp.float64(wp.pi) * wp.float64(j) / wp.float64(n_phi - 1)
        wi, wo = _pair_directions(mu_i[p], mu_o[p], phi)
        s, q = physics.microfacet_smooth_q_shadowed(wi, wo, eta, k, ef, ps, au, av, dist,
                                                    shadow)
        big = wp.max(big, wp.abs(s))
        if j == 0:
            q0[p] = q
        if j == n_phi - 1:
            qpi[p] = q
    smax[p] = big


def coarse_bound(mu_i, mu_o, eta, alpha_u, alpha_v, distribution, n_phi: int, device=None,
                 film=None, shadowing="separable"):
    """Per pair: ``max |S(phi)|`` over ``n_phi`` uniform azimuths of [0, pi], ``q(0)`` and
    ``q(pi)`` (see :func:`microfacet_split`); arrays of shape (P,). Only these three numbers per
    pair leave the device."""
    ensure_init()
    dev = device_for(device)
    mu_i = np.ascontiguousarray(mu_i, dtype=np.float64)
    P = mu_i.size
    outs = [wp.zeros(P, dtype=wp.float64, device=dev) for _ in range(3)]
    if P:
        wp.launch(_coarse_bound_kernel, dim=P, device=dev,
                  inputs=[wp.array(mu_i, dtype=wp.float64, device=dev),
                          host_array(mu_o, wp.float64, dev), int(n_phi),
                          *_interface_params(eta, alpha_u, alpha_v, distribution, film, shadowing)],
                  outputs=outs)
    return tuple(o.numpy() for o in outs)


@wp.kernel
def _ragged_eval_kernel(mu_i: wp.array(dtype=wp.float64), mu_o: wp.array(dtype=wp.float64),
                        half: wp.array(dtype=wp.int32), start: wp.array(dtype=wp.int64),
                        first: int, eta: wp.float64, k: wp.float64, ef: wp.float64,
                        ps: wp.float64, au: wp.float64, av: wp.float64, dist: int, shadow: int,
                        f: wp.array(dtype=wp.float64)):
    """f[start[p] + j] = BSDF of pair p = first + row at phi_j = pi j / M_p, j = 0..M_p."""
    row, j = wp.tid()
    p = first + row
    M = half[p]
    phi = wp.float64(wp.pi) * wp.float64(j) / wp.float64(M)
    wi, wo = _pair_directions(mu_i[p], mu_o[p], phi)
    f[start[p] + wp.int64(j)] = physics.microfacet_eval_shadowed(wi, wo, eta, k, ef, ps, au,
                                                                 av, dist, shadow)


@wp.kernel
def _ragged_dct_kernel(f: wp.array(dtype=wp.float64), half: wp.array(dtype=wp.int32),
                       start: wp.array(dtype=wp.int64), table: wp.array(dtype=wp.float64),
                       c: wp.array2d(dtype=wp.float64)):
    """:func:`_dct1` of ragged rows: ``table[i] = cos(pi i / M_max)``, read with stride
    ``M_max / M_p`` (both powers of two)."""
    p, l = wp.tid()
    M = half[p]
    c[p, l] = _dct1(f, start[p], M, l, table, (table.shape[0] // 2) // M)


@wp.kernel
def _truncate_kernel(c: wp.array2d(dtype=wp.float64), m: int, relerr: wp.float64,
                     taper: wp.array(dtype=wp.int32), factors: wp.array(dtype=wp.float64),
                     cut: wp.array(dtype=wp.int32)):
    """Per pair: series computed to ``c.shape[1] >= m`` orders are cut to ``m``. A coefficient at
    or past ``m`` above ``relerr |c_0|`` marks the pair truncated (``cut``); otherwise orders past
    the last one above ``relerr |c_0|`` are zeroed. Rows with ``taper`` are multiplied by
    ``factors`` (m,) (the host passes the Jackson kernel's). Same rule as
    ``layersim.ingredients.numeric`` on the host."""
    p = wp.tid()
    extra = c.shape[1]
    thr = relerr * wp.max(wp.abs(c[p, 0]), wp.float64(1e-300))
    last = int(-1)
    for l in range(extra):
        if wp.abs(c[p, l]) >= thr:
            last = l
    length = extra
    if last >= 0:
        length = last + 1
    cut[p] = 0
    if last >= m:
        cut[p] = 1
        length = m
    for l in range(m):
        if l >= length:
            c[p, l] = wp.float64(0.0)
        elif taper[p] != 0:
            c[p, l] = c[p, l] * factors[l]


def ragged_cosine_series(mu_i, mu_o, eta, alpha_u, alpha_v, distribution, half: np.ndarray,
                         orders: int, m: int, relerr: float, taper: np.ndarray,
                         factors: np.ndarray, device=None, film=None, shadowing="separable"):
    """Trapezoidal cosine series of each pair with its own ``2 half[p]`` samples per period
    (``half`` powers of two), ``orders`` coefficients, then cut to ``m`` orders as described in
    :func:`_truncate_kernel` (rows with ``taper`` multiplied by ``factors``, shape (m,)). Pairs
    should be sorted by ``half`` (one launch per distinct value; unsorted input works but
    launches more often).

    Returns
    -------
    coef : wp.array2d of float64, shape (P, orders)
        The series (orders ``>= m`` left as computed), on ``device``.
    cut : wp.array of int32, shape (P,)
        1 where the pair had significant orders at or past ``m``.
    """
    ensure_init()
    dev = device_for(device)
    half = np.ascontiguousarray(half, dtype=np.int32)
    P = half.size
    if np.any(half < 1) or np.any(half & (half - 1)):
        raise ValueError("half sample counts must be powers of two")
    start = np.zeros(P, np.int64)
    np.cumsum(half[:-1].astype(np.int64) + 1, out=start[1:])
    total = int(start[-1] + half[-1] + 1) if P else 0
    params = _interface_params(eta, alpha_u, alpha_v, distribution, film, shadowing)
    a_mi = host_array(mu_i, wp.float64, dev)
    a_mo = host_array(mu_o, wp.float64, dev)
    a_half = wp.array(half, dtype=wp.int32, device=dev)
    a_start = wp.array(start, dtype=wp.int64, device=dev)
    f = wp.empty(max(total, 1), dtype=wp.float64, device=dev)
    edges = np.flatnonzero(np.diff(half)) + 1
    for a, b in zip(np.r_[0, edges], np.r_[edges, P]):
        if b > a:
            wp.launch(_ragged_eval_kernel, dim=(int(b - a), int(half[a]) + 1), device=dev,
                      inputs=[a_mi, a_mo, a_half, a_start, int(a), *params], outputs=[f])
    m_max = int(half.max(initial=1))
    table = np.cos(np.pi * np.arange(2 * m_max) / m_max)
    coef = wp.empty((P, orders), dtype=wp.float64, device=dev)
    cut = wp.zeros(P, dtype=wp.int32, device=dev)
    if P:
        wp.launch(_ragged_dct_kernel, dim=(P, orders), device=dev,
                  inputs=[f, a_half, a_start, wp.array(table, dtype=wp.float64, device=dev)],
                  outputs=[coef])
        wp.launch(_truncate_kernel, dim=P, device=dev,
                  inputs=[coef, int(m), wp.float64(relerr),
                          host_array(taper, wp.int32, dev),
                          host_array(np.asarray(factors, float)[:m], wp.float64, dev)],
                  outputs=[cut])
    return coef, cut


# Anisotropic layers: samples in (phi_d, phi_s)
# ---------------------------------------------------------------------------------------------
#
# For anisotropic layers the BSDF depends on both propagation azimuths, expressed (Zeltner & Jakob
# 2018 eq. (6)) by the difference ``phi_d = phi_o - phi_i`` and the sum ``phi_s = phi_o + phi_i``,
# in the interface's own tangent frame. With ``phi_i = (phi_s - phi_d) / 2`` and
# ``phi_o = (phi_s + phi_d) / 2``::
#
#     wi = (-sqrt(1 - mu_i^2) cos phi_i, -sqrt(1 - mu_i^2) sin phi_i, mu_i)
#     wo = ( sqrt(1 - mu_o^2) cos phi_o,  sqrt(1 - mu_o^2) sin phi_o, -mu_o)
#
# which reduces to the isotropic geometry above for ``phi_i = 0``. Microfacet BSDFs are invariant
# under a rotation of both directions by pi, so the half angles are unambiguous.


@wp.func
def _pair_directions_ds(mu_i: wp.float64, mu_o: wp.float64, phi_d: wp.float64,
                        phi_s: wp.float64):
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    half = wp.float64(0.5)
    si = wp.sqrt(wp.max(one - mu_i * mu_i, zero))
    so = wp.sqrt(wp.max(one - mu_o * mu_o, zero))
    phi_i = half * (phi_s - phi_d)
    phi_o = half * (phi_s + phi_d)
    wi = wp.vec3d(-si * wp.cos(phi_i), -si * wp.sin(phi_i), mu_i)
    wo = wp.vec3d(so * wp.cos(phi_o), so * wp.sin(phi_o), -mu_o)
    return wi, wo


@wp.kernel
def _microfacet_split_ds_kernel(mu_i: wp.array(dtype=wp.float64),
                                mu_o: wp.array(dtype=wp.float64),
                                phi_d: wp.array2d(dtype=wp.float64),
                                phi_s: wp.array2d(dtype=wp.float64), eta: wp.float64,
                                k: wp.float64, ef: wp.float64, ps: wp.float64,
                                au: wp.float64, av: wp.float64, dist: int, shadow: int,
                                smooth: wp.array2d(dtype=wp.float64),
                                q: wp.array2d(dtype=wp.float64)):
    p, j = wp.tid()
    wi, wo = _pair_directions_ds(mu_i[p], mu_o[p], phi_d[p, j], phi_s[p, j])
    s, qq = physics.microfacet_smooth_q_shadowed(wi, wo, eta, k, ef, ps, au, av, dist,
                                                 shadow)
    smooth[p, j] = s
    q[p, j] = qq


@wp.kernel
def _microfacet_eval_ds_kernel(mu_i: wp.array(dtype=wp.float64),
                               mu_o: wp.array(dtype=wp.float64),
                               phi_d: wp.array2d(dtype=wp.float64),
                               phi_s: wp.array2d(dtype=wp.float64), eta: wp.float64,
                               k: wp.float64, ef: wp.float64, ps: wp.float64, au: wp.float64,
                               av: wp.float64, dist: int, shadow: int,
                               f: wp.array2d(dtype=wp.float64)):
    p, j = wp.tid()
    wi, wo = _pair_directions_ds(mu_i[p], mu_o[p], phi_d[p, j], phi_s[p, j])
    f[p, j] = physics.microfacet_eval_shadowed(wi, wo, eta, k, ef, ps, au, av, dist,
                                                shadow)


def _launch_pairs_ds(kernel, mu_i, mu_o, phi_d, phi_s, params, n_out, device=None):
    ensure_init()
    device = device_for(device)
    mu_i = np.ascontiguousarray(mu_i, dtype=np.float64)
    mu_o = np.ascontiguousarray(mu_o, dtype=np.float64)
    phi_d, phi_s = np.broadcast_arrays(np.asarray(phi_d, np.float64),
                                       np.asarray(phi_s, np.float64))
    phi_d = np.ascontiguousarray(phi_d)
    phi_s = np.ascontiguousarray(phi_s)
    if phi_d.ndim != 2 or phi_d.shape[0] != mu_i.shape[0] or mu_o.shape != mu_i.shape:
        raise ValueError("expected mu_i, mu_o of shape (P,) and phi_d, phi_s of shape (P, Q)")
    if phi_d.size == 0:
        return [np.zeros(phi_d.shape) for _ in range(n_out)]
    arrays = [wp.array(a, dtype=wp.float64, device=device) for a in (mu_i, mu_o, phi_d, phi_s)]
    outs = [wp.empty(phi_d.shape, dtype=wp.float64, device=device) for _ in range(n_out)]
    wp.launch(kernel, dim=phi_d.shape, inputs=[*arrays, *params], outputs=outs, device=device)
    return [o.numpy() for o in outs]


def microfacet_split_ds(mu_i, mu_o, phi_d, phi_s, eta, alpha_u, alpha_v,
                        distribution="beckmann", device=None, film=None, shadowing="separable"):
    """Split microfacet BSDF ``f = smooth * peak(q)`` of an anisotropic interface, sampled at
    azimuth differences ``phi_d`` and sums ``phi_s`` (radians) in the interface's tangent frame.

    Parameters
    ----------
    mu_i, mu_o : ndarray, shape (P,)
        Signed ordinates of each pair (solver convention, see module doc).
    phi_d, phi_s : ndarray, shape (P, Q) (broadcast against each other)
        Difference and sum of the propagation azimuths.
    eta : complex
        Relative index below/above (``eta + i k`` for a conductor).
    alpha_u, alpha_v : float
        Roughness along the tangent axes x and y.

    Returns
    -------
    smooth, q : ndarray, shape (P, Q)
        Smooth factor (1/sr) and slope-space form of :func:`physics.microfacet_smooth_q`.
        With ``alpha_u = alpha_v = 1``, ``q`` is the squared tangent of the half vector,
        ``|h_t|^2 / h_z^2`` (pure geometry).
    """
    return _launch_pairs_ds(_microfacet_split_ds_kernel, mu_i, mu_o, phi_d, phi_s,
                            _interface_params(eta, alpha_u, alpha_v, distribution, film,
                                              shadowing), 2,
                            device)


def microfacet_values_ds(mu_i, mu_o, phi_d, phi_s, eta, alpha_u, alpha_v,
                         distribution="beckmann", device=None, film=None, shadowing="separable"):
    """Full microfacet BSDF values f (1/sr) at the sample layout of
    :func:`microfacet_split_ds` (used as the reference of the projection tests)."""
    return _launch_pairs_ds(_microfacet_eval_ds_kernel, mu_i, mu_o, phi_d, phi_s,
                            _interface_params(eta, alpha_u, alpha_v, distribution, film,
                                              shadowing), 1,
                            device)[0]


# ---------------------------------------------------------------------------------------------
# Tabulated NDFs (layersim.kernels.tabulated): the BSDF on a uniform (phi_d, phi_s) grid
# ---------------------------------------------------------------------------------------------

@wp.kernel
def _tabulated_ds_kernel(mu_i: wp.array(dtype=wp.float64), mu_o: wp.array(dtype=wp.float64),
                         eta: wp.float64, k: wp.float64, tab: wp.array(dtype=wp.float64),
                         shadow: int, f: wp.array3d(dtype=wp.float64)):
    """f[p, a, b] = BSDF at phi_d = 2 pi a / Nd, phi_s = 2 pi b / Ns."""
    p, a, b = wp.tid()
    two_pi = wp.float64(6.283185307179586)
    phi_d = two_pi * wp.float64(a) / wp.float64(f.shape[1])
    phi_s = two_pi * wp.float64(b) / wp.float64(f.shape[2])
    wi, wo = _pair_directions_ds(mu_i[p], mu_o[p], phi_d, phi_s)
    f[p, a, b] = tabulated.microfacet_eval_tabulated_shadowed(wi, wo, eta, k, tab, 0, shadow)


def tabulated_ds_samples(mu_i, mu_o, eta, table: np.ndarray, n_d: int, n_s: int,
                         device=None, shadowing: str = "separable") -> np.ndarray:
    """BSDF of a tabulated-NDF interface (:func:`tabulated.microfacet_eval_tabulated`) for
    ordinate pairs on the uniform azimuth grid ``phi_d = 2 pi a / n_d``, ``phi_s = 2 pi b / n_s``
    (interface frame, geometry of :func:`microfacet_split_ds`).

    Parameters
    ----------
    mu_i, mu_o : ndarray, shape (P,)
        Signed ordinates (solver convention, see module doc).
    eta : complex
        Relative index below/above (``eta + i k`` for a conductor).
    table : ndarray of float64
        Packed table (:meth:`layersim.ndf.table.NDFTable.packed`).
    shadowing : str
        The Smith term (:func:`physics.g2_from_masking`).

    Returns
    -------
    ndarray, shape (P, n_d, n_s)
        BSDF values (1/sr).
    """
    ensure_init()
    dev = device_for(device)
    mu_i = np.ascontiguousarray(mu_i, dtype=np.float64)
    if mu_i.size == 0:
        return np.zeros((0, n_d, n_s))
    f = wp.empty((mu_i.size, n_d, n_s), dtype=wp.float64, device=dev)
    wp.launch(_tabulated_ds_kernel, dim=f.shape, device=dev,
              inputs=[wp.array(mu_i, dtype=wp.float64, device=dev),
                      wp.array(np.ascontiguousarray(mu_o, dtype=np.float64), dtype=wp.float64,
                               device=dev),
                      wp.float64(complex(eta).real), wp.float64(complex(eta).imag),
                      wp.array(np.ascontiguousarray(table, dtype=np.float64),
                               dtype=wp.float64, device=dev),
                      int(physics.SHADOWING_CODES[shadowing])],
              outputs=[f])
    return f.numpy()


# ---------------------------------------------------------------------------------------------
# Measured BRDFs (layersim.kernels.measured): cosine series of an isotropic table
# ---------------------------------------------------------------------------------------------

@wp.kernel
def _measured_uniform_kernel(mu_i: wp.array(dtype=wp.float64), mu_o: wp.array(dtype=wp.float64),
                             tab: wp.array(dtype=wp.float64), f: wp.array2d(dtype=wp.float64)):
    """f[p, j] = BRDF at phi_j = pi j / M (M + 1 = f.shape[1])."""
    p, j = wp.tid()
    phi = wp.float64(wp.pi) * wp.float64(j) / wp.float64(f.shape[1] - 1)
    wi, wo = _pair_directions(mu_i[p], mu_o[p], phi)
    f[p, j] = measured.measured_eval(wi, wo, tab, 0)


def measured_cosine_series(mu_i, mu_o, table: np.ndarray, half: int, orders: int,
                           device=None) -> np.ndarray:
    """Cosine coefficients ``f_0 .. f_{orders-1}`` (1/sr) of a measured BRDF
    (:func:`measured.measured_eval`, one channel's flat ``table``) for ordinate pairs (solver
    convention, reflection: ``mu_i > 0 > mu_o``), from ``half + 1`` uniform azimuths on
    [0, pi] (trapezoidal rule, a DCT-I); orders past ``half`` are zero. Shape (P, orders)."""
    ensure_init()
    dev = device_for(device)
    mu_i = np.ascontiguousarray(mu_i, dtype=np.float64)
    if mu_i.size == 0:
        return np.zeros((0, orders))
    f = wp.empty((mu_i.size, half + 1), dtype=wp.float64, device=dev)
    wp.launch(_measured_uniform_kernel, dim=f.shape, device=dev,
              inputs=[wp.array(mu_i, dtype=wp.float64, device=dev),
                      wp.array(np.ascontiguousarray(mu_o, dtype=np.float64), dtype=wp.float64,
                               device=dev),
                      wp.array(np.ascontiguousarray(table, dtype=np.float64), dtype=wp.float64,
                               device=dev)], outputs=[f])
    y = scipy.fft.dct(f.numpy(), type=1, axis=1) / half
    y[:, 0] *= 0.5
    out = np.zeros((mu_i.size, orders))
    n = min(orders, half + 1)
    out[:, :n] = y[:, :n]
    return out
