"""Kernels that importance-sample tabulated Fourier BSDFs and evaluate the matching density.

Sampling follows Jakob et al. (2014, sec. 7) and layerlab / Mitsuba 0.6's ``BSDFStorage::sample``:
the outgoing elevation from the marginal density in ``mu_o`` (a spline, inverted by Newton-
bisection on its integral), then the azimuth by inverting the integrated cosine series
(Newton-bisection). It is split in two stages, each with a sampling kernel and a density kernel
that share their arithmetic, so that ``pdf`` always describes what ``sample`` does:

Elevation (one query = one incident direction)
    ``mu`` is ``|cos theta_o|`` on one side (reflection ``side = 0`` or transmission ``side = 1``,
    each a block of the series table). The host passes the incident spline taps; the kernel
    interpolates the zeroth-order coefficient at every outgoing node, ``G_a = sum_b w_b
    f_0(a, b)``, and integrates the marginal ``q(mu) = mu * C(mu)`` exactly, ``C`` being the cubic
    Hermite spline through the ``G_a`` with the derivative estimates of
    :func:`layersim.solved.bsdf.spline_weights` (constant beyond the outermost nodes, as ``eval``).
    In an *exact* interval (the four node values involved are >= 0 and the cubic stays >= 0),
    ``q`` is the cosine-weighted azimuthal integral of ``eval`` (up to the factor ``2 pi``), so
    ``sample`` importance-samples the interpolated BSDF perfectly. Otherwise (undershoot next to a
    sharp edge of a lobe) the interval uses the linear interpolant of its two end values clamped to
    ``>= 0``: the sampling density is never negative, and the density kernel applies the same rule.
    Reflection versus transmission is chosen in proportion to the two sides' integrals.

Azimuth (one query = one interpolated series, 16 pairs with spline weights)
    With ``g(phi) = sum_l g_l cos(l phi)`` the interpolated series of the sampled elevation,
    ``phi`` solves ``int_0^phi g = u pi g_0`` on ``[0, pi]`` (the series is even; the other half
    of ``u`` picks the sign). The density is ``max(g, 0) / (2 pi g_0)``; in a clamped (not exact)
    elevation interval, or if ``g_0 <= 0``, the azimuth is uniform (there the series is dominated
    by undershoot and ``2 pi g_0`` would not normalise it). A series that dips below zero somewhere
    in an exact interval (ringing of a truncated series, cubic undershoot of very narrow lobes)
    makes the integral locally decrease, and the sampled azimuths then follow ``g`` only up to the
    negative mass (documented in :mod:`layersim.solved.sampling`).

All arithmetic is float64. Layout of the series table: see :mod:`.fourier_eval`.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from .fourier_eval import TAPS, tap_series
from .runtime import device_for, host_array

#: (x0, width, c0, c1, c2, c3, exact): an interval of the elevation marginal (see
#: :func:`_interval`).
vec7d = wp.types.vector(length=7, dtype=wp.float64)

_PI = wp.constant(wp.float64(math.pi))
_NEWTON_MAX = wp.constant(100)


@wp.func
def _newton_bisection(t: wp.float64, val: wp.float64, slope: wp.float64, a: wp.float64,
                      b: wp.float64):
    """One step of the safeguarded Newton iteration that inverts the samplers' increasing
    primitives: ``val`` (primitive minus goal) and ``slope`` (the density) at ``t`` in the
    bracket ``[a, b]``. Returns ``(a, b, t)``: the bracket shrunk to the side holding the root,
    and the Newton point, or the bracket's midpoint where the slope vanishes (callers bisect
    when the Newton point leaves the bracket)."""
    if val > wp.float64(0.0):
        b = t
    else:
        a = t
    if slope > wp.float64(0.0):
        t = t - val / slope
    else:
        t = wp.float64(0.5) * (a + b)
    return wp.vec3d(a, b, t)


@wp.func
def _node(c0: wp.array(dtype=wp.float64), h: int, base: wp.int64, a: int,
          taps: wp.array2d(dtype=wp.int64), tw: wp.array2d(dtype=wp.float64), q: int):
    """Zeroth-order coefficient at outgoing node ``a``, interpolated to the query's incident
    elevation (not clamped)."""
    s = wp.float64(0.0)
    row = base + wp.int64(a) * wp.int64(h)
    for k in range(4):
        w = tw[q, k]
        if w != wp.float64(0.0):
            s += w * c0[row + taps[q, k]]
    return s


@wp.func
def _cubic(c: vec7d, t: wp.float64):
    return c[2] + t * (c[3] + t * (c[4] + t * c[5]))


@wp.func
def _nonnegative(c: vec7d):
    """Whether the cubic ``c2 + c3 t + c4 t^2 + c5 t^3`` is >= 0 on [0, 1] (its end values are)."""
    A = wp.float64(3.0) * c[5]
    B = wp.float64(2.0) * c[4]
    C = c[3]
    ok = True
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    if A != zero:
        disc = B * B - wp.float64(4.0) * A * C
        if disc >= zero:
            sq = wp.sqrt(disc)
            qq = wp.float64(-0.5) * (B + wp.sign(B) * sq)     # cancellation-free roots
            if qq != zero:
                r1 = qq / A
                r2 = C / qq
                if r1 > zero and r1 < one:
                    if _cubic(c, r1) < zero:
                        ok = False
                if r2 > zero and r2 < one:
                    if _cubic(c, r2) < zero:
                        ok = False
    elif B != zero:
        r = -C / B
        if r > zero and r < one:
            if _cubic(c, r) < zero:
                ok = False
    return ok


@wp.func
def _interval(mu: wp.array(dtype=wp.float64), c0: wp.array(dtype=wp.float64), h: int,
              base: wp.int64, j: int, taps: wp.array2d(dtype=wp.int64),
              tw: wp.array2d(dtype=wp.float64), q: int):
    """Interval ``j`` of the elevation marginal on one side: ``mu = x0 + width t`` and
    ``C(t) = c0 + c1 t + c2 t^2 + c3 t^3``, returned as ``(x0, width, c0, c1, c2, c3, exact)``.

    ``j = 0`` is ``[0, mu_0]`` and ``j = h`` is ``[mu_{h-1}, 1]`` (both constant, as ``eval`` is
    beyond the outermost nodes); ``j = 1..h-1`` is the Hermite piece ``[mu_{j-1}, mu_j]``.
    ``exact = 1`` when ``C`` is the interpolated zeroth order itself (no node value involved is
    negative and the cubic stays >= 0); otherwise ``exact = 0`` and ``C`` is the linear
    interpolant of the end values clamped to >= 0."""
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    x0 = zero
    width = zero
    f0 = zero
    d0 = zero
    c2 = zero
    c3 = zero
    exact = one
    if j == 0 or j == h:
        a = 0
        if j == h:
            a = h - 1
            x0 = mu[h - 1]
            width = one - x0
        else:
            width = mu[0]
        f0 = _node(c0, h, base, a, taps, tw, q)
        if f0 < zero:
            f0 = zero
            exact = zero
    else:
        k = j - 1
        x0 = mu[k]
        x1 = mu[k + 1]
        width = x1 - x0
        f0 = _node(c0, h, base, k, taps, tw, q)
        f1 = _node(c0, h, base, k + 1, taps, tw, q)
        lowest = wp.min(f0, f1)
        d0 = f1 - f0
        d1 = f1 - f0
        if k > 0:
            fm = _node(c0, h, base, k - 1, taps, tw, q)
            lowest = wp.min(lowest, fm)
            d0 = width * (f1 - fm) / (x1 - mu[k - 1])
        if k + 2 < h:
            fp = _node(c0, h, base, k + 2, taps, tw, q)
            lowest = wp.min(lowest, fp)
            d1 = width * (fp - f0) / (mu[k + 2] - x0)
        c2 = wp.float64(3.0) * (f1 - f0) - wp.float64(2.0) * d0 - d1
        c3 = wp.float64(2.0) * (f0 - f1) + d0 + d1
        if lowest < zero:
            exact = zero
        elif not _nonnegative(vec7d(x0, width, f0, d0, c2, c3, one)):
            exact = zero
        if exact == zero:         # linear interpolant of the clamped end values
            f0 = wp.max(f0, zero)
            d0 = wp.max(f1, zero) - f0
            c2 = zero
            c3 = zero
    return vec7d(x0, width, f0, d0, c2, c3, exact)


@wp.func
def _density(c: vec7d, t: wp.float64):
    """Marginal density (per unit mu, unnormalised) at ``t``: ``(x0 + width t) C(t)``."""
    return (c[0] + c[1] * t) * _cubic(c, t)


@wp.func
def _primitive(c: vec7d, t: wp.float64):
    """``int_0^t (x0 + width s) C(s) ds`` (the interval's mass is ``width * _primitive(c, 1)``)."""
    x0 = c[0]
    w = c[1]
    p0 = x0 * c[2]
    p1 = x0 * c[3] + w * c[2]
    p2 = x0 * c[4] + w * c[3]
    p3 = x0 * c[5] + w * c[4]
    p4 = w * c[5]
    return t * (p0 + t * (p1 / wp.float64(2.0) + t * (p2 / wp.float64(3.0)
                + t * (p3 / wp.float64(4.0) + t * p4 / wp.float64(5.0)))))


@wp.func
def _side_mass(mu: wp.array(dtype=wp.float64), c0: wp.array(dtype=wp.float64), h: int,
               n_int: int, base: wp.int64, taps: wp.array2d(dtype=wp.int64),
               tw: wp.array2d(dtype=wp.float64), q: int):
    m = wp.float64(0.0)
    if base >= wp.int64(0):
        for j in range(n_int):
            c = _interval(mu, c0, h, base, j, taps, tw, q)
            m += wp.max(c[1] * _primitive(c, wp.float64(1.0)), wp.float64(0.0))
    return m


@wp.kernel
def _side_masses(mu: wp.array(dtype=wp.float64), c0: wp.array(dtype=wp.float64), h: int,
                 n_int: int, taps: wp.array2d(dtype=wp.int64),
                 tw: wp.array2d(dtype=wp.float64), base_r: wp.array(dtype=wp.int64),
                 base_t: wp.array(dtype=wp.int64), out: wp.array2d(dtype=wp.float64)):
    q = wp.tid()
    out[q, 0] = _side_mass(mu, c0, h, n_int, base_r[q], taps, tw, q)
    out[q, 1] = _side_mass(mu, c0, h, n_int, base_t[q], taps, tw, q)


@wp.kernel
def _sample_elevation(mu: wp.array(dtype=wp.float64), c0: wp.array(dtype=wp.float64), h: int,
                      n_int: int, taps: wp.array2d(dtype=wp.int64),
                      tw: wp.array2d(dtype=wp.float64), base_r: wp.array(dtype=wp.int64),
                      base_t: wp.array(dtype=wp.int64), masses: wp.array2d(dtype=wp.float64),
                      u: wp.array(dtype=wp.float64),
                      out_mu: wp.array(dtype=wp.float64), out_side: wp.array(dtype=wp.int32),
                      out_pdf: wp.array(dtype=wp.float64), out_exact: wp.array(dtype=wp.int32)):
    q = wp.tid()
    zero = wp.float64(0.0)
    one = wp.float64(1.0)
    mr = masses[q, 0]
    mt = masses[q, 1]
    total = mr + mt
    out_mu[q] = zero
    out_side[q] = -1
    out_pdf[q] = zero
    out_exact[q] = 0
    if total > zero:
        target = u[q] * total
        side = 0
        base = base_r[q]
        if target >= mr and mt > zero:
            side = 1
            base = base_t[q]
            target = target - mr
        # walk the intervals to the one holding the target
        cum = zero
        chosen = int(-1)
        last = int(-1)
        for j in range(n_int):
            if chosen < 0:
                c = _interval(mu, c0, h, base, j, taps, tw, q)
                m = wp.max(c[1] * _primitive(c, one), zero)
                if m > zero:
                    last = j
                    if cum + m > target:
                        chosen = j
                    else:
                        cum += m
        r = one                   # fraction of the chosen interval's mass below the target
        at_end = chosen < 0       # target at the very end (u -> 1, rounding): last interval
        if at_end:
            chosen = last
        c = _interval(mu, c0, h, base, chosen, taps, tw, q)
        mass = wp.max(c[1] * _primitive(c, one), zero)
        if not at_end:
            r = wp.clamp((target - cum) / mass, zero, one)
        goal = r * _primitive(c, one)
        # Newton-bisection on the primitive (monotone: the density is >= 0)
        a = zero
        b = one
        t = r
        tol = wp.float64(1e-14) * _primitive(c, one)
        for it in range(_NEWTON_MAX):
            if not (t >= a and t <= b):
                t = wp.float64(0.5) * (a + b)
            val = _primitive(c, t) - goal
            if wp.abs(val) <= tol or b - a <= wp.float64(1e-15):
                break
            step = _newton_bisection(t, val, _density(c, t), a, b)
            a = step[0]
            b = step[1]
            t = step[2]
        dens = _density(c, t)
        if dens > zero:
            out_mu[q] = c[0] + c[1] * t
            out_side[q] = side
            out_pdf[q] = dens / total
            out_exact[q] = int(c[6])


@wp.kernel
def _pdf_elevation(mu: wp.array(dtype=wp.float64), c0: wp.array(dtype=wp.float64), h: int,
                   n_int: int, taps: wp.array2d(dtype=wp.int64),
                   tw: wp.array2d(dtype=wp.float64), base_r: wp.array(dtype=wp.int64),
                   base_t: wp.array(dtype=wp.int64), masses: wp.array2d(dtype=wp.float64),
                   mu_out: wp.array(dtype=wp.float64), side: wp.array(dtype=wp.int32),
                   out_pdf: wp.array(dtype=wp.float64), out_exact: wp.array(dtype=wp.int32)):
    q = wp.tid()
    zero = wp.float64(0.0)
    out_pdf[q] = zero
    out_exact[q] = 0
    base = base_r[q]
    if side[q] == 1:
        base = base_t[q]
    if side[q] >= 0 and base >= wp.int64(0):
        total = masses[q, 0] + masses[q, 1]
        x = mu_out[q]
        if total > zero and x > zero and x <= wp.float64(1.0):
            # interval holding x: 0 below mu_0, h - 1 + (1 if beyond mu_{h-1})
            j = int(0)
            if x >= mu[0]:
                lo = int(0)
                hi = h - 1
                if x >= mu[h - 1]:
                    lo = h - 1
                while hi - lo > 1:
                    mid = (lo + hi) // 2
                    if mu[mid] <= x:
                        lo = mid
                    else:
                        hi = mid
                j = lo + 1
                if j >= n_int:
                    j = n_int - 1
            c = _interval(mu, c0, h, base, j, taps, tw, q)
            t = wp.clamp((x - c[0]) / c[1], zero, wp.float64(1.0))
            out_pdf[q] = wp.max(_density(c, t), zero) / total
            out_exact[q] = int(c[6])


@wp.func
def _accumulate(offsets: wp.array(dtype=wp.int64), coef: wp.array(dtype=wp.float64),
                pair: wp.array2d(dtype=wp.int64), weight: wp.array2d(dtype=wp.float64),
                scratch: wp.array2d(dtype=wp.float64), q: int, row: int):
    """Interpolated series of query ``q`` into ``scratch[row, :]``; returns its length."""
    n = wp.int64(0)
    for k in range(TAPS):
        if weight[q, k] != wp.float64(0.0):
            p = pair[q, k]
            n = wp.max(n, offsets[p + wp.int64(1)] - offsets[p])
    for l in range(int(n)):
        scratch[row, l] = wp.float64(0.0)
    for k in range(TAPS):
        w = weight[q, k]
        if w != wp.float64(0.0):
            p = pair[q, k]
            start = offsets[p]
            cnt = int(offsets[p + wp.int64(1)] - start)
            for l in range(cnt):
                scratch[row, l] += w * coef[start + wp.int64(l)]
    return int(n)


@wp.kernel
def _sample_azimuth(offsets: wp.array(dtype=wp.int64), coef: wp.array(dtype=wp.float64),
                    pair: wp.array2d(dtype=wp.int64), weight: wp.array2d(dtype=wp.float64),
                    exact: wp.array(dtype=wp.int32), u: wp.array(dtype=wp.float64), first: int,
                    scratch: wp.array2d(dtype=wp.float64),
                    out_phi: wp.array(dtype=wp.float64), out_pdf: wp.array(dtype=wp.float64)):
    row = wp.tid()
    q = first + row
    zero = wp.float64(0.0)
    n = _accumulate(offsets, coef, pair, weight, scratch, q, row)
    g0 = zero
    if n > 0:
        g0 = scratch[row, 0]
    if g0 <= zero or exact[q] == 0:
        out_phi[q] = _PI * (wp.float64(2.0) * u[q] - wp.float64(1.0))
        out_pdf[q] = wp.float64(0.5) / _PI
    else:
        uu = wp.float64(2.0) * u[q]
        sgn = wp.float64(1.0)
        if uu > wp.float64(1.0):
            uu = wp.float64(2.0) - uu
            sgn = wp.float64(-1.0)
        goal = uu * _PI * g0
        tol = wp.float64(1e-13) * _PI * g0
        a = zero
        b = _PI
        phi = uu * _PI
        g = g0
        for it in range(_NEWTON_MAX):
            if not (phi >= a and phi <= b):
                phi = wp.float64(0.5) * (a + b)
            # F(phi) = g0 phi + sum_l g_l sin(l phi) / l and g(phi), by Chebyshev recurrences
            cs = wp.cos(phi)
            sn = wp.sin(phi)
            two_c = wp.float64(2.0) * cs
            c_prev = wp.float64(1.0)
            c_cur = cs
            s_prev = zero
            s_cur = sn
            F = g0 * phi
            g = g0
            for l in range(1, n):
                gl = scratch[row, l]
                F += gl * s_cur / wp.float64(l)
                g += gl * c_cur
                c_next = two_c * c_cur - c_prev
                s_next = two_c * s_cur - s_prev
                c_prev = c_cur
                c_cur = c_next
                s_prev = s_cur
                s_cur = s_next
            val = F - goal
            if wp.abs(val) <= tol or b - a <= wp.float64(1e-15):
                break
            step = _newton_bisection(phi, val, g, a, b)
            a = step[0]
            b = step[1]
            phi = step[2]
        out_phi[q] = sgn * phi
        out_pdf[q] = wp.max(g, zero) / (wp.float64(2.0) * _PI * g0)


@wp.kernel
def _pdf_azimuth(offsets: wp.array(dtype=wp.int64), coef: wp.array(dtype=wp.float64),
                 pair: wp.array2d(dtype=wp.int64), weight: wp.array2d(dtype=wp.float64),
                 exact: wp.array(dtype=wp.int32), phi: wp.array(dtype=wp.float64),
                 out_pdf: wp.array(dtype=wp.float64)):
    q = wp.tid()
    zero = wp.float64(0.0)
    series = tap_series(offsets, coef, pair, weight, q, wp.cos(phi[q]))
    g0 = series[0]
    if g0 > zero and exact[q] != 0:
        out_pdf[q] = wp.max(series[1], zero) / (wp.float64(2.0) * _PI * g0)
    else:
        out_pdf[q] = wp.float64(0.5) / _PI


# ---------------------------------------------------------------------------------------------
# Host wrappers
# ---------------------------------------------------------------------------------------------

#: Bytes of per-query scratch (interpolated series) the azimuth sampler may hold at once.
SCRATCH_BYTES = 64 << 20


def _elevation_inputs(mu, c0, taps, tw, base_r, base_t, device):
    h = int(mu.size)
    n_int = h + (1 if mu[-1] < 1.0 else 0)
    return [host_array(mu, wp.float64, device), host_array(c0, wp.float64, device), h, n_int,
            host_array(taps, wp.int64, device), host_array(tw, wp.float64, device),
            host_array(base_r, wp.int64, device), host_array(base_t, wp.int64, device)]


def side_masses(mu, c0, taps, tw, base_r, base_t, device=None):
    """Integrals of the (clamped) elevation marginal over the reflection and transmission side.

    Parameters
    ----------
    mu : float64 (h,)
        Positive ordinates (increasing).
    c0 : float64 (P,)
        Zeroth-order coefficient of every pair of the series table (0 for empty pairs).
    taps, tw : (Q, 4) int64 / float64
        Incident spline taps and weights (:func:`layersim.solved.bsdf.spline_weights` of
        ``|mu_i|``).
    base_r, base_t : int64 (Q,)
        First pair of the reflection / transmission block for the query (``-1``: left out).

    Returns
    -------
    float64 (Q, 2)
        ``int q(mu) dmu`` on each side (``2 pi`` times it is the cosine-weighted integral of the
        sampled density's unnormalised BSDF over the hemisphere).
    """
    device = device_for(device)
    Q = taps.shape[0]
    if Q == 0:
        return np.zeros((0, 2))
    out = wp.empty((Q, 2), dtype=wp.float64, device=device)
    wp.launch(_side_masses, dim=Q, device=device,
              inputs=_elevation_inputs(mu, c0, taps, tw, base_r, base_t, device), outputs=[out])
    return out.numpy()


def sample_elevation(mu, c0, taps, tw, base_r, base_t, masses, u, device=None):
    """Sample ``|cos theta_o|`` and the side for each query.

    Parameters
    ----------
    mu, c0, taps, tw, base_r, base_t : see :func:`side_masses`
    masses : float64 (Q, 2)
        :func:`side_masses` of the same queries.
    u : float64 (Q,)
        Uniform variate in [0, 1].

    Returns
    -------
    mu_o : float64 (Q,) in (0, 1]
    side : int32 (Q,)
        0 reflection, 1 transmission, -1 no sample (nothing leaves).
    pdf : float64 (Q,)
        Density of ``mu_o`` per unit ``|cos theta_o|`` (both sides together integrate to 1).
    exact : int32 (Q,)
        1 where the marginal is the interpolated zeroth order itself, 0 in a clamped interval
        (the azimuth is then sampled uniformly).
    """
    device = device_for(device)
    Q = u.shape[0]
    if Q == 0:
        return np.zeros(0), np.zeros(0, np.int32), np.zeros(0), np.zeros(0, np.int32)
    out_mu = wp.empty(Q, dtype=wp.float64, device=device)
    out_side = wp.empty(Q, dtype=wp.int32, device=device)
    out_pdf = wp.empty(Q, dtype=wp.float64, device=device)
    out_exact = wp.empty(Q, dtype=wp.int32, device=device)
    wp.launch(_sample_elevation, dim=Q, device=device,
              inputs=_elevation_inputs(mu, c0, taps, tw, base_r, base_t, device)
              + [host_array(masses, wp.float64, device), host_array(u, wp.float64, device)],
              outputs=[out_mu, out_side, out_pdf, out_exact])
    return out_mu.numpy(), out_side.numpy(), out_pdf.numpy(), out_exact.numpy()


def pdf_elevation(mu, c0, taps, tw, base_r, base_t, masses, mu_o, side, device=None):
    """Density of :func:`sample_elevation` at ``mu_o`` (float64 (Q,)) on ``side`` (int32 (Q,);
    -1 gives 0), and the ``exact`` flag of the interval holding ``mu_o``."""
    device = device_for(device)
    Q = mu_o.shape[0]
    if Q == 0:
        return np.zeros(0), np.zeros(0, np.int32)
    out = wp.empty(Q, dtype=wp.float64, device=device)
    out_exact = wp.empty(Q, dtype=wp.int32, device=device)
    wp.launch(_pdf_elevation, dim=Q, device=device,
              inputs=_elevation_inputs(mu, c0, taps, tw, base_r, base_t, device)
              + [host_array(masses, wp.float64, device), host_array(mu_o, wp.float64, device),
                 host_array(side, wp.int32, device)], outputs=[out, out_exact])
    return out.numpy(), out_exact.numpy()


def sample_azimuth(offsets, coef, pair, weight, exact, u, device=None):
    """Sample the azimuth difference of the interpolated series of each query.

    Parameters
    ----------
    offsets, coef : series table (see :mod:`.fourier_eval`)
    pair, weight : (Q, 16) int64 / float64
        Neighbouring pairs and their spline weights (weight 0 skips a tap).
    exact : int32 (Q,)
        The elevation stage's flag; 0 samples the azimuth uniformly.
    u : float64 (Q,) uniform in [0, 1]

    Returns
    -------
    phi : float64 (Q,) in [-pi, pi]
        Azimuth difference of the propagation directions (0 = specular / straight through).
    pdf : float64 (Q,)
        Density per radian.
    """
    device = device_for(device)
    Q = u.shape[0]
    if Q == 0:
        return np.zeros(0), np.zeros(0)
    lengths = np.diff(offsets)
    width = max(1, int(lengths.max()) if lengths.size else 1)
    chunk = max(1, min(Q, SCRATCH_BYTES // (8 * width)))
    args = [host_array(offsets, wp.int64, device), host_array(coef, wp.float64, device),
            host_array(pair, wp.int64, device), host_array(weight, wp.float64, device),
            host_array(exact, wp.int32, device), host_array(u, wp.float64, device)]
    out_phi = wp.empty(Q, dtype=wp.float64, device=device)
    out_pdf = wp.empty(Q, dtype=wp.float64, device=device)
    scratch = wp.empty((chunk, width), dtype=wp.float64, device=device)
    for first in range(0, Q, chunk):
        wp.launch(_sample_azimuth, dim=min(chunk, Q - first), device=device,
                  inputs=args + [first, scratch], outputs=[out_phi, out_pdf])
    return out_phi.numpy(), out_pdf.numpy()


def pdf_azimuth(offsets, coef, pair, weight, exact, phi, device=None):
    """Density of :func:`sample_azimuth` at ``phi`` (float64 (Q,), radians)."""
    device = device_for(device)
    Q = phi.shape[0]
    if Q == 0:
        return np.zeros(0)
    out = wp.empty(Q, dtype=wp.float64, device=device)
    wp.launch(_pdf_azimuth, dim=Q, device=device, inputs=[
        host_array(offsets, wp.int64, device), host_array(coef, wp.float64, device),
        host_array(pair, wp.int64, device), host_array(weight, wp.float64, device),
        host_array(exact, wp.int32, device), host_array(phi, wp.float64, device)], outputs=[out])
    return out.numpy()
