"""The particle random walk through a layer stack, as Warp functions (float32 hot loop).

One source for every backend: :func:`walk_thread` is called by the Warp kernel :data:`walk_kernel`
(``warp-cpu``, ``warp-cuda``) and, translated by :mod:`layersim.kernels.opencl_codegen`, by the
generated OpenCL kernel. The physics comes from :mod:`.physics` and :mod:`.sampling`, the random
numbers from :mod:`.rng`. The host (:mod:`layersim.montecarlo`) only flattens the scene into the
arrays described below, launches, and reduces the integer tallies.

Stack model
-----------
The stack is a column of ``S`` slabs between ``S + 1`` boundaries, top to bottom: boundary ``b`` is
the top of slab ``b``, boundary ``S`` the bottom of the stack. Boundary records (``bnd_i``: 3 ints,
``bnd_f``: :data:`BND_F` floats each) hold the kind (:data:`NULL` index-matched pass-through,
:data:`DIELECTRIC`, :data:`CONDUCTOR`, :data:`DIFFUSE`, :data:`MEASURED`), the distribution code,
the shadowing code (:data:`.physics.SHADOWING_CODES`),
the relative index ``eta`` and ``k``, ``alpha_u``, ``alpha_v``, ``cos``/``sin`` of the
tangent-frame rotation, the Lambertian albedo, the offset of the energy-compensation tables, and
the thin film of a filmed interface (its index relative to the medium above and its phase scale
``4 pi n d / lambda``, :func:`.physics.fresnel_interface`; 0: no film); a tabulated NDF
(:mod:`.tabulated`) and a measured base (:mod:`.measured`) keep their tables after the records.
Slab records (``slab_f``: :data:`SLAB_F` floats each) hold the optical thickness ``tau`` along
the normal, the single-scattering albedo and the HG ``g`` (``tau = 0``: clear).

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

from dataclasses import dataclass, fields
from functools import lru_cache

import numpy as np
import warp as wp

from . import compensation, measured, physics, rng, sampling, tabulated

wp.set_module_options({"enable_backward": False})

# Boundary kinds (host: layersim.montecarlo.stack).
NULL = wp.constant(0)
DIELECTRIC = wp.constant(1)
CONDUCTOR = wp.constant(2)
DIFFUSE = wp.constant(3)
MEASURED = wp.constant(4)
#: ints per boundary record: kind, distribution, shadowing (:func:`.physics.smith_g2`)
BND_I = wp.constant(3)
#: floats per boundary record: eta, k, alpha_u, alpha_v, cos(rot), sin(rot), albedo, offset of
#: the boundary's energy-compensation tables in ``bnd_f`` (0: none; :mod:`.compensation`), the
#: film's relative index and phase scale (0: no film; :func:`.physics.fresnel_interface`)
BND_F = wp.constant(10)
#: Slots of the film in a boundary record.
FILM_ETA = wp.constant(8)
FILM_PHASE = wp.constant(9)
#: floats per slab record: tau, albedo, g
SLAB_F = wp.constant(3)

#: Russian roulette threshold and survivor weight.
RR_WEIGHT = wp.constant(wp.float32(0.25))
#: Fixed-point scale of the tallies (2^32).
FIXED_SCALE = wp.constant(wp.float32(4294967296.0))
TWO_PI = wp.constant(wp.float32(6.283185307179586))

#: Outcomes of a particle's walk.
EXIT_TOP = wp.constant(0)
EXIT_BOTTOM = wp.constant(1)
ABSORBED = wp.constant(-1)
TRUNCATED = wp.constant(-2)




# ------------------------------------------------------------------------------------------------
# What a stack's walk needs
# ------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Features:
    """The code paths of the walk that a stack uses; a kernel built for these leaves every other
    path out (:func:`program`), so that a coated conductor runs no tabulated-NDF, measured-base,
    compensation or medium code, and the compiler allocates registers for what runs.

    Attributes
    ----------
    smooth : bool
        Smooth (alpha 0) interfaces: specular sampling.
    beckmann, ggx : bool
        Rough interfaces with that analytic distribution.
    tabulated : bool
        Rough interfaces with a tabulated NDF (:mod:`.tabulated`).
    compensation : bool
        Energy-compensation lobes (:mod:`.compensation`).
    diffuse, measured : bool
        A Lambertian or a measured (:mod:`.measured`) base.
    media : bool
        Slabs with ``tau > 0`` (flights and Henyey-Greenstein scattering).
    film : bool
        Interfaces carrying a thin film (Airy reflectance in place of Fresnel's).
    height_correlated : bool
        Rough interfaces with a height-correlated Smith term (:func:`.physics.smith_g2`,
        :func:`.physics.g2_from_masking`).
    """

    smooth: bool = True
    beckmann: bool = True
    ggx: bool = True
    tabulated: bool = True
    compensation: bool = True
    diffuse: bool = True
    measured: bool = True
    media: bool = True
    film: bool = True
    height_correlated: bool = True

    @classmethod
    def every(cls) -> "Features":
        """Every path: the kernel that runs any stack."""
        return cls()

    @property
    def interfaces(self) -> bool:
        """Any boundary that is not an index-matched pass-through."""
        return self.smooth or self.rough or self.diffuse or self.measured

    @property
    def rough(self) -> bool:
        return self.beckmann or self.ggx or self.tabulated

    def left_out(self) -> list:
        """Names of the paths a kernel for these features leaves out."""
        return [f.name for f in fields(self) if not getattr(self, f.name)]

    def __or__(self, other: "Features") -> "Features":
        return Features(**{f.name: getattr(self, f.name) or getattr(other, f.name)
                           for f in fields(self)})


def features_of(bnd_i: np.ndarray, bnd_f: np.ndarray, slab_f: np.ndarray,
                n_slabs: int) -> Features:
    """The :class:`Features` the records of a flattened stack use (host side)."""
    records = np.asarray(bnd_i).reshape(-1, int(BND_I))
    kinds, dists, shadows = records[:, 0], records[:, 1], records[:, 2]
    rec = np.asarray(bnd_f)[:(n_slabs + 1) * int(BND_F)].reshape(-1, int(BND_F))
    microfacet = ((kinds == DIELECTRIC) | (kinds == CONDUCTOR))
    smooth = microfacet & (rec[:, 2] == 0.0) & (dists != tabulated.TABULATED)
    rough = microfacet & ~smooth
    slabs = np.asarray(slab_f).reshape(-1, int(SLAB_F))[:max(n_slabs, 1)]
    return Features(
        smooth=bool(smooth.any()),
        beckmann=bool((rough & (dists == physics.BECKMANN)).any()),
        ggx=bool((rough & (dists == physics.GGX)).any()),
        tabulated=bool((rough & (dists == tabulated.TABULATED)).any()),
        compensation=bool((rough & (rec[:, 7] > 0)).any()),
        diffuse=bool((kinds == DIFFUSE).any()),
        measured=bool((kinds == MEASURED).any()),
        media=bool(n_slabs > 0 and (slabs[:, 0] > 0).any()),
        film=bool((microfacet & (rec[:, FILM_PHASE] > 0)).any()),
        height_correlated=bool((rough & (shadows != physics.SEPARABLE)).any()))

@wp.func
def find_bin(x: wp.float32, edges: wp.array(dtype=wp.float32), n_edges: int):
    """Index of the bin ``[edges[i], edges[i+1])`` holding ``x`` (the last bin is closed), or -1
    outside ``[edges[0], edges[-1]]``. Bisection: the same few steps in every thread of a warp,
    where a scan would take as many steps as the bin's index."""
    if x < edges[0] or x > edges[n_edges - 1]:
        return -1
    lo = int(0)
    hi = n_edges - 1            # edges[lo] <= x, and x < edges[hi] or hi is the last edge
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if x >= edges[mid]:
            lo = mid
        else:
            hi = mid
    return lo


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


# ------------------------------------------------------------------------------------------------
# The walk, built for a set of features
# ------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class WalkProgram:
    """The walk built for :attr:`features`: :attr:`thread` (the Warp function the OpenCL kernel
    translates) and :attr:`kernel` (the Warp kernel calling it), in a module of their own."""

    features: Features
    thread: object
    kernel: object


@lru_cache(maxsize=None)
def program(features: Features, max_registers: int | None = None) -> WalkProgram:
    """The walk with only the paths of ``features`` compiled in (``wp.static`` branches of
    closures; Warp builds each feature set once and caches it on disk). ``max_registers`` caps
    the registers per thread of the CUDA kernel (more threads resident per multiprocessor, at
    the risk of spills)."""
    scatter = _boundary_scatter(features)
    thread = _walk_thread(_walk_particle(features, scatter))
    return WalkProgram(features, thread, _walk_kernel(thread, max_registers))


def _boundary_scatter(f: Features):
    """The boundary interaction of a walk built for ``f``."""
    # with one analytic distribution its code is a constant, and the other's branches in
    # sampling.sample_vndf and physics.smith_g1 fold away
    one_dist = (physics.BECKMANN if not f.ggx else physics.GGX) \
        if (f.beckmann != f.ggx and not f.tabulated) else -1

    @wp.func
    def boundary_scatter(d: wp.vec3, b: int, bnd_i: wp.array(dtype=wp.int32),
                         bnd_f: wp.array(dtype=wp.float32), u0: wp.float32, u1: wp.float32,
                         u2: wp.float32, u3: wp.float32):
        """Interaction of a particle propagating along ``d`` with (non-null) boundary ``b``.

        Returns the new propagation direction and the weight factor ``f |cos| / pdf``.
        """
        kind = bnd_i[BND_I * b]
        dist = bnd_i[BND_I * b + 1]
        if wp.static(one_dist >= 0):
            dist = wp.static(one_dist)
        o = BND_F * b
        eta = bnd_f[o]
        k = bnd_f[o + 1]
        au = bnd_f[o + 2]
        av = bnd_f[o + 3]
        wi = -d
        if wp.static(f.diffuse):
            if kind == DIFFUSE:
                if wi[2] <= wp.float32(0.0):
                    return d, wp.float32(0.0)
                return sampling.sample_cosine_hemisphere(u0, u1), bnd_f[o + 6]
        if wp.static(f.measured):
            if kind == MEASURED:        # alpha_u's slot holds the table's offset in bnd_f
                wm, wm_weight = measured.sample_measured(wi, bnd_f, int(au), u0, u1)
                return wm, wm_weight
        if wp.static(f.smooth):
            if au == wp.float32(0.0):
                if wp.static(f.film):       # a film: its relative index and phase scale
                    if bnd_f[o + FILM_PHASE] > wp.float32(0.0):
                        wf, ff = sampling.sample_smooth_film(wi, eta, k, bnd_f[o + FILM_ETA],
                                                             bnd_f[o + FILM_PHASE], u0)
                        return wf, ff
                ws, fs = sampling.sample_smooth(wi, eta, k, u0)
                return ws, fs
        if wp.static(f.rough):
            # the compensation lobe (isotropic, azimuth independent) or the single-scattering one
            v0 = u0
            scale = wp.float32(1.0)
            if wp.static(f.compensation):
                comp = int(bnd_f[o + 7])
                if comp > 0:
                    taken, wc, fc, v0, scale = compensation.choose_lobe(wi, bnd_f, comp, u0, u1,
                                                                        u2)
                    if taken:
                        return wc, fc
            cr = bnd_f[o + 4]
            sr = bnd_f[o + 5]
            wl = sampling.to_tangent_frame(wi, cr, sr)
            shadow = int(0)                     # physics.SEPARABLE
            if wp.static(f.height_correlated):
                shadow = bnd_i[BND_I * b + 2]
            if wp.static(f.tabulated):
                if dist == tabulated.TABULATED:     # alpha_u's slot: the table's offset
                    wt, wt_weight = tabulated.sample_microfacet_tabulated_shadowed(
                        wl, eta, k, bnd_f, int(au), shadow, v0, u1, u3)
                    return sampling.from_tangent_frame(wt, cr, sr), wt_weight * scale
            if wp.static(f.height_correlated):  # any film rides along (phase 0: none)
                if shadow != physics.SEPARABLE:
                    wh, wh_weight = sampling.sample_microfacet_shadowed(
                        wl, eta, k, bnd_f[o + FILM_ETA], bnd_f[o + FILM_PHASE], au, av, dist,
                        shadow, v0, u1, u2, u3)
                    return sampling.from_tangent_frame(wh, cr, sr), wh_weight * scale
            if wp.static(f.film):
                if bnd_f[o + FILM_PHASE] > wp.float32(0.0):
                    wg, wg_weight = sampling.sample_microfacet_film(
                        wl, eta, k, bnd_f[o + FILM_ETA], bnd_f[o + FILM_PHASE], au, av, dist,
                        v0, u1, u2, u3)
                    return sampling.from_tangent_frame(wg, cr, sr), wg_weight * scale
            wo, weight = sampling.sample_microfacet(wl, eta, k, au, av, dist, v0, u1, u2, u3)
            return sampling.from_tangent_frame(wo, cr, sr), weight * scale
        return d, wp.float32(0.0)       # a kind these features leave out: absorbed

    return boundary_scatter


def _walk_particle(f: Features, boundary_scatter):
    """The walk of one particle, for ``f``, with ``boundary_scatter`` at its boundaries."""

    @wp.func
    def walk_particle(seed_lo: wp.uint32, seed_hi: wp.uint32, p_lo: wp.uint32,
                      p_hi: wp.uint32, wi: wp.vec3, bnd_i: wp.array(dtype=wp.int32),
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
                if wp.static(f.interfaces):
                    if bnd_i[BND_I * b] != NULL:
                        u0, u1, u2, u3 = rng.uniform4(seed_lo, seed_hi, p_lo, p_hi, draw)
                        draw = draw + wp.uint32(1)
                        d, fw = boundary_scatter(d, b, bnd_i, bnd_f, u0, u1, u2, u3)
                        events = events + 1
                        w = w * fw
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
                # a clear slab (tau 0, and every slab of a stack without media): straight to
                # the next boundary
                clear = True
                tau = zero
                if wp.static(f.media):
                    tau = slab_f[SLAB_F * s]
                    clear = tau <= zero
                if clear:
                    b = s
                    if d[2] < zero:
                        b = s + 1
                    at_boundary = True
                else:
                    u0, u1, u2, u3 = rng.uniform4(seed_lo, seed_hi, p_lo, p_hi, draw)
                    draw = draw + wp.uint32(1)
                    tn = t + wp.log(u0) * d[2]  # depth grows downwards: l |d.z|, l = -log(u0)
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

    return walk_particle


def _walk_thread(walk_particle):
    """The work of one thread: its particles, walked with ``walk_particle``, tallied."""

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
                    tally_exit(side, d, w, copy, mu_edges, n_mu_edges, phi_edges,
                               n_phi_edges, tally)
                elif side == TRUNCATED:
                    truncated = truncated + wp.int64(1)
        wp.atomic_add(counters, 2 * copy, events)
        wp.atomic_add(counters, 2 * copy + 1, truncated)

    return walk_thread


def _walk_kernel(walk_thread, max_registers: int | None):
    """The Warp kernel running ``walk_thread``, in a module of its own."""

    @wp.kernel(enable_backward=False, module="unique", cuda_max_registers=max_registers)
    def walk_kernel(n_threads: int, per_thread: int, first: wp.int64, count: int,
                    seed_lo: wp.uint32, seed_hi: wp.uint32, wi: wp.vec3,
                    bnd_i: wp.array(dtype=wp.int32), bnd_f: wp.array(dtype=wp.float32),
                    slab_f: wp.array(dtype=wp.float32), n_slabs: int, max_steps: int,
                    mu_edges: wp.array(dtype=wp.float32), n_mu_edges: int,
                    phi_edges: wp.array(dtype=wp.float32), n_phi_edges: int, n_copies: int,
                    tally: wp.array(dtype=wp.int64), counters: wp.array(dtype=wp.int64)):
        walk_thread(wp.tid(), n_threads, per_thread, first, count, seed_lo, seed_hi, wi,
                    bnd_i, bnd_f, slab_f, n_slabs, max_steps, mu_edges, n_mu_edges, phi_edges,
                    n_phi_edges, n_copies, tally, counters)

    return walk_kernel


#: The walk with every path: runs any stack (tests, and the OpenCL translator's checks).
EVERY = program(Features.every())
walk_thread = EVERY.thread
walk_kernel = EVERY.kernel
