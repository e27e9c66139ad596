"""Energies of a specular path by exact transport along it: a deterministic quadrature of its
events' microfacet BSDFs.

A path's light leaving toward ``p_E`` is the iterated integral over the wave vectors
``p_1 .. p_E`` after its near-specular events,

    E(p_i -> d^2 p_E) = prod_smooth(p) prod_e f_e(p_{e-1}, p_e) / n_{b_e}^2 d^2 p_1 .. d^2 p_E

(``f_e`` the face's microfacet BSDF, Walter et al. 2007, eq. 20-21, between the directions of
``p_{e-1}`` and ``p_e`` in the gaps around it, ``n_{b_e}`` the index of the gap it leaves into:
``f mu dOmega = f / n^2 d^2 p``; the smooth faces' Fresnel energies and the slabs'
attenuation at each intermediate ``p``). It is computed by importance sampling each ``p_e``
from the event's linearised lobe, ``p_e = p_{e-1} + c_e R_e diag(alpha_e) x_e`` with ``x_e``
drawn from the unit slope distribution (Heitz 2014, eq. 9; inverse CDF
:func:`layersim.kernels.pointwise.slope_radius`), with scrambled Sobol points (fixed seed: the
result is deterministic) and weights ``f_e / (n_b^2 q_e)``. This is the walk's model restricted
to the path, without its variance from choosing paths; bin energies and albedos come from it,
while ``eval`` keeps the linearised lobe of :mod:`.lobes` (its measured difference is the
linearisation error, docs/method.md).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import qmc

from ..kernels.lobe import microfacet_reflection
from ..kernels.pointwise import ndf_peak, slope_radius

__all__ = ["trace_path"]


def _local(p_in, p_out, na, nb, down: bool, what: str):
    """Directions (toward the light, toward the viewer) of one event in the face's own frame
    seen from the arriving side (from below: mirrored in ``z``); None where a wave vector is
    beyond its gap's horizon."""
    mu_a = np.sqrt(np.clip(1.0 - np.sum(p_in ** 2, axis=1) / na ** 2, 0.0, 1.0))
    mu_b = np.sqrt(np.clip(1.0 - np.sum(p_out ** 2, axis=1) / nb ** 2, 0.0, 1.0))
    up_after = down if what == "R" else not down
    wi = np.concatenate([-p_in / na, (mu_a if down else -mu_a)[:, None]], axis=1)
    wo = np.concatenate([p_out / nb, (mu_b if up_after else -mu_b)[:, None]], axis=1)
    if not down:
        wi[:, 2], wo[:, 2] = -wi[:, 2], -wo[:, 2]
    return wi, wo, (mu_a > 0) & (mu_b > 0)


def _rough_step(face, step, gaps, n, p, u):
    """One near-specular event: the drawn wave vectors (N, 2) and the weights
    ``f / (n_b^2 q)`` (N, C)."""
    (e, down, what), (a, b) = step, gaps
    na, nb = n[a], n[b]
    mu_a = np.sqrt(np.clip(1.0 - np.sum(p ** 2, axis=1) / na ** 2, 0.0, 1.0))
    mu_b = np.sqrt(np.clip(1.0 - np.sum(p ** 2, axis=1) / nb ** 2, 0.0, 1.0))
    c = 2.0 * na * mu_a if what == "R" else np.abs(na * mu_a - nb * mu_b)
    c = np.maximum(c, 1e-9)
    r = slope_radius(np.minimum(u[:, 0], 1.0 - 1e-12), 1.0, face.distribution)
    phi = 2.0 * np.pi * u[:, 1]
    x = np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)
    cr, sr = math.cos(face.rotation), math.sin(face.rotation)
    s = x * np.array([face.alpha_u, face.alpha_v])[None, :]
    s = np.stack([cr * s[:, 0] - sr * s[:, 1], sr * s[:, 0] + cr * s[:, 1]], axis=1)
    p_new = p + c[:, None] * s
    q = ndf_peak(r * r, face.distribution) / np.pi / (c ** 2 * face.alpha_u * face.alpha_v)
    wi, wo, ok = _local(p, p_new, na, nb, down, what)
    frame = lambda w: np.stack([cr * w[:, 0] + sr * w[:, 1], -sr * w[:, 0] + cr * w[:, 1],
                                w[:, 2]], axis=1)
    f = np.zeros((p.shape[0], len(face.eta)))
    for ch, eta in enumerate(face.eta):
        eta = complex(eta)
        er = eta.real if (down or eta.imag > 0) else 1.0 / eta.real
        if ok.any():
            f[ok, ch] = microfacet_reflection(frame(wi[ok]), frame(wo[ok]), er, face.alpha_u,
                                              face.alpha_v, face.distribution, eta.imag)
    return p_new, f / (nb ** 2 * q[:, None])


def trace_path(model, entry, p_i: np.ndarray, count: int, seed: int = 1):
    """Exit wave vectors (N, 2) and energies (N, C) (each node's share of the incident power)
    of the path ``entry`` of ``model`` (:class:`layersim.specular_paths.model.PathModel`) for
    light entering with wave vector ``p_i`` (2,), on ``count`` Sobol nodes (a power of 2)."""
    chain, path = model.chain, entry.path
    dims = 2 * max(1, len(entry.steps))
    u = qmc.Sobol(dims, scramble=True, seed=seed).random(count)
    p = np.repeat(np.asarray(p_i, float)[None, :], count, axis=0)
    w = np.ones((count, chain.channels))
    k = 0
    for s, step in enumerate(path.steps):
        e, down, what = step
        el = chain.elements[e]
        if what != "S" and not el.smooth:
            p, f = _rough_step(el, step, (path.gaps[s], path.gaps[s + 1]), chain.n, p,
                               u[:, 2 * k:2 * k + 2])
            w = w * f
            k += 1
            continue
        w = w * model.step_energy(step, path.gaps[s], p)
    return p, w
