"""The particle random walk through a layer stack, as Warp functions (float32 hot loop).

One source for every backend: :func:`walk_thread` is called by the Warp kernel :data:`walk_kernel`
(``warp-cpu``, ``warp-cuda``) and, translated by :mod:`layersim.kernels.opencl_codegen`, by the
generated OpenCL kernel. The physics comes from :mod:`.physics` and :mod:`.sampling`, the random
numbers from :mod:`.rng`. The host (:mod:`layersim.montecarlo`) only flattens the scene into the
arrays described below, launches, and reduces the integer tallies.

Stack model
-----------
The stack is a column of ``S`` slabs between ``S + 1`` boundaries, top to bottom: boundary ``b`` is
the top of slab ``b``, boundary ``S`` the bottom of the stack. Boundary records (``bnd_i``: 2 ints,
``bnd_f``: :data:`BND_F` floats each) hold the kind (:data:`NULL` index-matched pass-through,
:data:`DIELECTRIC`, :data:`CONDUCTOR`, :data:`DIFFUSE`, :data:`MEASURED`), the distribution code,
the relative index ``eta`` and ``k``, ``alpha_u``, ``alpha_v``, ``cos``/``sin`` of the
tangent-frame rotation and the Lambertian albedo; a tabulated NDF (:mod:`.tabulated`) and a
measured base (:mod:`.measured`) keep their tables after the records. Slab records (``slab_f``:
:data:`SLAB_F` floats each) hold the optical thickness
``tau`` along the normal, the single-scattering albedo and the HG ``g`` (``tau = 0``: clear).

Walk
----
A particle enters along ``-wi`` at boundary 0 (``wi.z > 0``) or ``S`` (``wi.z < 0``) with weight
1 and alternates boundary interactions and flights. In slab ``s`` at optical depth ``t`` (0 at
its top) it flies an exponential optical path ``l = -log(u)``, i.e. ``l |d.z|`` in depth along the
normal; if that crosses a boundary it interacts there, otherwise it scatters (weight times the
albedo, HG direction). Interfaces sample their BSDF (``sampling.sample_microfacet`` /
``sample_smooth``, Lambertian cosine sampling) and multiply the weight by ``f |cos| / pdf``.
Russian roulette is unbiased: below :data:`RR_WEIGHT` a particle survives with probability
``w / RR_WEIGHT`` and continues with weight ``RR_WEIGHT``; so weights stay in [0, 1]. A particle
leaves at the top or bottom, is absorbed (weight 0), or is stopped after ``max_steps`` loop steps
(counted as *truncated*, its energy lost; the host reports the count).

Random numbers: one Philox block (4 uniforms) per interaction, one more for a roulette decision at
a boundary; block ``draw`` of particle ``p`` is ``rng.uniform4(seed, p, draw)``, so a particle's
path depends only on ``(seed, p)``.

Tallies (deterministic)
-----------------------
Weights are accumulated as 64-bit fixed point with 32 fractional bits (``round(w * 2^32)``, and
``round(w^2 * 2^32)`` for second moments) by integer atomics. Integer addition is associative, so
the totals do not depend on thread scheduling, launch size or batching: the same seed gives
bit-identical tallies on a backend. Quantisation error: at most 2^-33 per particle, far below any
attainable standard error. ``tally`` holds ``n_copies`` replicas (thread ``tid`` adds to replica
``tid % n_copies``, to spread atomic traffic on GPUs) of a ``[side 2][moment 2][bin nb]`` block,
``nb = n_mu * n_phi + 1``, the last bin being the side's total; ``counters`` holds per replica
``[events, truncated]``.
"""

from __future__ import annotations

import warp as wp

from . import compensation, measured, rng, sampling, tabulated

wp.set_module_options({"enable_backward": False})

# Boundary kinds (host: layersim.montecarlo.stack).
NULL = wp.constant(0)
DIELECTRIC = wp.constant(1)
CONDUCTOR = wp.constant(2)
DIFFUSE = wp.constant(3)
MEASURED = wp.constant(4)
#: ints per boundary record: kind, distribution
BND_I = wp.constant(2)
#: floats per boundary record: eta, k, alpha_u, alpha_v, cos(rot), sin(rot), albedo, offset of
#: the boundary's energy-compensation tables in ``bnd_f`` (0: none; :mod:`.compensation`)
BND_F = wp.constant(8)
#: floats per slab record: tau, albedo, g
SLAB_F = wp.constant(3)

#: Russian roulette threshold and survivor weight.
RR_WEIGHT = wp.constant(wp.float32(0.25))
#: Fixed-point scale of the tallies (2^32).
FIXED_SCALE = wp.constant(wp.float32(4294967296.0))
TWO_PI = wp.constant(wp.float32(6.283185307179586))

#: Outcomes of :func:`walk_particle`.
EXIT_TOP = wp.constant(0)
EXIT_BOTTOM = wp.constant(1)
ABSORBED = wp.constant(-1)
TRUNCATED = wp.constant(-2)


@wp.func
def boundary_scatter(d: wp.vec3, b: int, bnd_i: wp.array(dtype=wp.int32),
                     bnd_f: wp.array(dtype=wp.float32), u0: wp.float32, u1: wp.float32,
                     u2: wp.float32, u3: wp.float32):
    """Interaction of a particle propagating along ``d`` with (non-null) boundary ``b``.

    Returns the new propagation direction and the weight factor ``f |cos| / pdf``.
    """
    kind = bnd_i[BND_I * b]
    dist = bnd_i[BND_I * b + 1]
    o = BND_F * b
    eta = bnd_f[o]
    k = bnd_f[o + 1]
    au = bnd_f[o + 2]
    av = bnd_f[o + 3]
    wi = -d
    if kind == DIFFUSE:
        if wi[2] <= wp.float32(0.0):
            return d, wp.float32(0.0)
        return sampling.sample_cosine_hemisphere(u0, u1), bnd_f[o + 6]
    if kind == MEASURED:                # alpha_u's slot holds the table's offset in bnd_f
        wm, wm_weight = measured.sample_measured(wi, bnd_f, int(au), u0, u1)
        return wm, wm_weight
    if au == wp.float32(0.0):
        ws, fs = sampling.sample_smooth(wi, eta, k, u0)
        return ws, fs
    # the compensation lobe (isotropic, azimuth independent) or the single-scattering one
    v0 = u0
    scale = wp.float32(1.0)
    comp = int(bnd_f[o + 7])
    if comp > 0:
        taken, wc, fc, v0, scale = compensation.choose_lobe(wi, bnd_f, comp, u0, u1, u2)
        if taken:
            return wc, fc
    cr = bnd_f[o + 4]
    sr = bnd_f[o + 5]
    wl = sampling.to_tangent_frame(wi, cr, sr)
    if dist == tabulated.TABULATED:     # alpha_u's slot holds the table's offset in bnd_f
        wt, wt_weight = tabulated.sample_microfacet_tabulated(wl, eta, k, bnd_f, int(au), v0,
                                                              u1, u3)
        return sampling.from_tangent_frame(wt, cr, sr), wt_weight * scale
    wo, weight = sampling.sample_microfacet(wl, eta, k, au, av, dist, v0, u1, u2, u3)
    return sampling.from_tangent_frame(wo, cr, sr), weight * scale


@wp.func
def walk_particle(seed_lo: wp.uint32, seed_hi: wp.uint32, p_lo: wp.uint32, p_hi: wp.uint32,
                  wi: wp.vec3, bnd_i: wp.array(dtype=wp.int32),
                  bnd_f: wp.array(dtype=wp.float32), slab_f: wp.array(dtype=wp.float32),
                  n_slabs: int, max_steps: int):
    """Follow particle ``p = p_hi * 2^32 + p_lo`` from incidence to its fate.

    Returns ``(outcome, d, w, events)``: :data:`EXIT_TOP` / :data:`EXIT_BOTTOM` /
    :data:`ABSORBED` / :data:`TRUNCATED`, the final propagation direction (= the outgoing
    direction ``wo`` for exits), the final weight, and the number of scattering events
    (medium scatterings and interface interactions).
    """
    zero = wp.float32(0.0)
    d = -wi
    w = wp.float32(1.0)
    draw = wp.uint32(0)
    events = int(0)
    b = int(0)
    if wi[2] < zero:
        b = n_slabs
    s = int(0)
    t = zero
    at_boundary = bool(True)
    for _step in range(max_steps):
        if at_boundary:
            if bnd_i[BND_I * b] != NULL:
                u0, u1, u2, u3 = rng.uniform4(seed_lo, seed_hi, p_lo, p_hi, draw)
                draw = draw + wp.uint32(1)
                d, f = boundary_scatter(d, b, bnd_i, bnd_f, u0, u1, u2, u3)
                events = events + 1
                w = w * f
                if w <= zero:
                    return ABSORBED, d, zero, events
                if w < RR_WEIGHT:
                    r0, r1, r2, r3 = rng.uniform4(seed_lo, seed_hi, p_lo, p_hi, draw)
                    draw = draw + wp.uint32(1)
                    if r0 * RR_WEIGHT >= w:
                        return ABSORBED, d, zero, events
                    w = RR_WEIGHT
            if d[2] < zero:
                if b == n_slabs:
                    return EXIT_BOTTOM, d, w, events
                s = b
                t = zero
            elif d[2] > zero:
                if b == 0:
                    return EXIT_TOP, d, w, events
                s = b - 1
                t = slab_f[SLAB_F * s]
            else:
                return ABSORBED, d, zero, events  # grazing exactly: never leaves the plane
            at_boundary = False
        else:
            tau = slab_f[SLAB_F * s]
            if tau <= zero:
                # clear slab: straight to the next boundary
                b = s
                if d[2] < zero:
                    b = s + 1
                at_boundary = True
            else:
                u0, u1, u2, u3 = rng.uniform4(seed_lo, seed_hi, p_lo, p_hi, draw)
                draw = draw + wp.uint32(1)
                tn = t + wp.log(u0) * d[2]  # depth grows downwards: l |d.z| with l = -log(u0)
                if d[2] < zero and tn >= tau:
                    b = s + 1
                    at_boundary = True
                elif d[2] > zero and tn <= zero:
                    b = s
                    at_boundary = True
                else:
                    t = tn
                    w = w * slab_f[SLAB_F * s + 1]
                    d = sampling.sample_hg(d, slab_f[SLAB_F * s + 2], u1, u2)
                    events = events + 1
                    if w < RR_WEIGHT:
                        if u3 * RR_WEIGHT >= w:
                            return ABSORBED, d, zero, events
                        w = RR_WEIGHT
    return TRUNCATED, d, zero, events


@wp.func
def find_bin(x: wp.float32, edges: wp.array(dtype=wp.float32), n_edges: int):
    """Index of the bin ``[edges[i], edges[i+1])`` holding ``x`` (the last bin is closed), or -1
    outside ``[edges[0], edges[-1]]``."""
    if x < edges[0] or x > edges[n_edges - 1]:
        return -1
    i = int(0)
    while i < n_edges - 2 and x >= edges[i + 1]:
        i = i + 1
    return i


@wp.func
def tally_exit(side: int, d: wp.vec3, w: wp.float32, copy: int,
               mu_edges: wp.array(dtype=wp.float32), n_mu_edges: int,
               phi_edges: wp.array(dtype=wp.float32), n_phi_edges: int,
               tally: wp.array(dtype=wp.int64)):
    """Add an exiting particle's weight (and squared weight) to its side's total and bin."""
    n_phi = n_phi_edges - 1
    nb = (n_mu_edges - 1) * n_phi + 1
    base = (copy * 2 + side) * 2 * nb
    wq = wp.int64(wp.round(w * FIXED_SCALE))
    w2q = wp.int64(wp.round(w * w * FIXED_SCALE))
    wp.atomic_add(tally, base + nb - 1, wq)
    wp.atomic_add(tally, base + nb + nb - 1, w2q)
    phi = wp.atan2(d[1], d[0])
    if phi < wp.float32(0.0):
        phi = phi + TWO_PI
    i = find_bin(wp.abs(d[2]), mu_edges, n_mu_edges)
    j = find_bin(phi, phi_edges, n_phi_edges)
    if i >= 0 and j >= 0:
        wp.atomic_add(tally, base + i * n_phi + j, wq)
        wp.atomic_add(tally, base + nb + i * n_phi + j, w2q)


@wp.func
def walk_thread(tid: int, n_threads: int, per_thread: int, first: wp.int64, count: int,
                seed_lo: wp.uint32, seed_hi: wp.uint32, wi: wp.vec3,
                bnd_i: wp.array(dtype=wp.int32), bnd_f: wp.array(dtype=wp.float32),
                slab_f: wp.array(dtype=wp.float32), n_slabs: int, max_steps: int,
                mu_edges: wp.array(dtype=wp.float32), n_mu_edges: int,
                phi_edges: wp.array(dtype=wp.float32), n_phi_edges: int, n_copies: int,
                tally: wp.array(dtype=wp.int64), counters: wp.array(dtype=wp.int64)):
    """Work of thread ``tid`` of ``n_threads``: particles ``first + tid + j n_threads`` for
    ``j < per_thread`` that fall below ``first + count``."""
    copy = tid % n_copies
    events = wp.int64(0)
    truncated = wp.int64(0)
    for j in range(per_thread):
        i = tid + j * n_threads
        if i < count:
            p = first + wp.int64(i)
            side, d, w, ev = walk_particle(seed_lo, seed_hi, wp.uint32(p),
                                           wp.uint32(p >> wp.int64(32)), wi, bnd_i, bnd_f,
                                           slab_f, n_slabs, max_steps)
            events = events + wp.int64(ev)
            if side >= 0:
                tally_exit(side, d, w, copy, mu_edges, n_mu_edges, phi_edges, n_phi_edges,
                           tally)
            elif side == TRUNCATED:
                truncated = truncated + wp.int64(1)
    wp.atomic_add(counters, 2 * copy, events)
    wp.atomic_add(counters, 2 * copy + 1, truncated)


@wp.kernel
def walk_kernel(n_threads: int, per_thread: int, first: wp.int64, count: int,
                seed_lo: wp.uint32, seed_hi: wp.uint32, wi: wp.vec3,
                bnd_i: wp.array(dtype=wp.int32), bnd_f: wp.array(dtype=wp.float32),
                slab_f: wp.array(dtype=wp.float32), n_slabs: int, max_steps: int,
                mu_edges: wp.array(dtype=wp.float32), n_mu_edges: int,
                phi_edges: wp.array(dtype=wp.float32), n_phi_edges: int, n_copies: int,
                tally: wp.array(dtype=wp.int64), counters: wp.array(dtype=wp.int64)):
    walk_thread(wp.tid(), n_threads, per_thread, first, count, seed_lo, seed_hi, wi, bnd_i,
                bnd_f, slab_f, n_slabs, max_steps, mu_edges, n_mu_edges, phi_edges, n_phi_edges,
                n_copies, tally, counters)
