"""Counter-based random numbers for the random walk: Philox-4x32-10, as Warp functions.

Why not Warp's built-in RNG: its state is 32 bits and ``wp.randf`` returns floats with 24 random
bits, so long walks see correlations and the exponential free path ``-log(u)`` is cut off at
``log(2^24) ~ 16.6``. Philox (Salmon, Moraes, Dror, Shaw 2011, "Parallel random numbers: as easy as
1, 2, 3", SC'11) is a keyed bijection of a 128-bit counter: there is no state to carry, any
``(key, counter)`` can be evaluated in any order, and the stream of a particle does not depend on
how particles are split into launches or threads.

Stream layout used by the walk
------------------------------
* key   = the 64-bit ``seed`` as two 32-bit words ``(seed_lo, seed_hi)``;
* counter = ``(draw, 0, particle_lo, particle_hi)``: ``particle`` is the global 64-bit index of the
  particle in the run, ``draw`` counts the Philox blocks that particle has used so far.

Each block gives four 32-bit words, turned into four uniforms by :func:`u01`.

These functions are translated to OpenCL C by :mod:`layersim.kernels.opencl_codegen`, so they only
use the subset it understands (typed arguments, integer arithmetic, shifts and xors).
"""

from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})

# Philox-4x32 multipliers and Weyl key increments (Random123, philox.h).
PHILOX_M0 = wp.constant(wp.uint32(0xD2511F53))
PHILOX_M1 = wp.constant(wp.uint32(0xCD9E8D57))
PHILOX_W0 = wp.constant(wp.uint32(0x9E3779B9))
PHILOX_W1 = wp.constant(wp.uint32(0xBB67AE85))
SHIFT32 = wp.constant(wp.uint64(32))
#: 2^-32: one unit of a 32-bit word as a fraction of [0, 1).
TWO_M32 = wp.constant(wp.float32(2.3283064365386963e-10))
#: Largest float32 below one (1 - 2^-24).
ONE_MINUS_ULP = wp.constant(wp.float32(0.99999994))


@wp.func
def mulhilo32(a: wp.uint32, b: wp.uint32):
    """High and low 32-bit words of the 64-bit product ``a * b``."""
    p = wp.uint64(a) * wp.uint64(b)
    return wp.uint32(p >> SHIFT32), wp.uint32(p)


@wp.func
def philox4x32_10(c0: wp.uint32, c1: wp.uint32, c2: wp.uint32, c3: wp.uint32,
                  k0: wp.uint32, k1: wp.uint32):
    """Philox-4x32 with 10 rounds: four 32-bit words for counter ``(c0..c3)`` and key ``(k0, k1)``.

    Bit-identical to Random123's ``philox4x32_R(10, ctr, key)`` (known-answer vectors in
    ``tests/test_rng.py``).
    """
    x0 = c0
    x1 = c1
    x2 = c2
    x3 = c3
    key0 = k0
    key1 = k1
    for _r in range(10):
        hi0, lo0 = mulhilo32(PHILOX_M0, x0)
        hi1, lo1 = mulhilo32(PHILOX_M1, x2)
        x0 = hi1 ^ x1 ^ key0
        x1 = lo1
        x2 = hi0 ^ x3 ^ key1
        x3 = lo0
        key0 = key0 + PHILOX_W0
        key1 = key1 + PHILOX_W1
    return x0, x1, x2, x3


@wp.func
def u01(x: wp.uint32):
    """Uniform float32 in the open interval (0, 1) from a 32-bit word.

    ``(x + 1/2) * 2^-32``: the resolution near 0 is 2^-32 (so ``-log(u)`` reaches 22.5 and small
    probabilities are resolved to 32 bits); near 1 float32 itself limits it to 2^-24, and the
    few words that would round to 1.0 (probability 3e-8) are clamped to ``1 - 2^-24``. The result
    is never 0 and never 1.
    """
    u = (wp.float32(x) + wp.float32(0.5)) * TWO_M32
    return wp.min(u, ONE_MINUS_ULP)


@wp.func
def uniform4(seed_lo: wp.uint32, seed_hi: wp.uint32, particle_lo: wp.uint32,
             particle_hi: wp.uint32, draw: wp.uint32):
    """Four independent uniforms in (0, 1): block ``draw`` of particle ``particle``'s stream."""
    x0, x1, x2, x3 = philox4x32_10(draw, wp.uint32(0), particle_lo, particle_hi, seed_lo,
                                   seed_hi)
    return u01(x0), u01(x1), u01(x2), u01(x3)
