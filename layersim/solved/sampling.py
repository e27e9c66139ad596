"""Importance sampling of a solved BSDF from its Fourier representation.

``sample(wi, u)`` draws an outgoing direction ``wo`` with a density close to
``f(wi, wo) |wo.z|`` and returns ``(wo, weight, pdf)``, ``weight = f(wi, wo) |wo.z| / pdf``;
``pdf(wi, wo)`` is that density (per steradian). Both are vectorised over any batch shape and run
as Warp kernels (:mod:`layersim.kernels.fourier_sample`) on the CPU or a GPU (``device`` or
``$LAYERSIM_DEVICE``).

Algorithm (Jakob et al. 2014, sec. 7; layerlab / Mitsuba 0.6 ``BSDFStorage::sample``)
--------------------------------------------------------------------------------------
1. Elevation: the marginal density of ``mu_o = |cos theta_o|`` is the azimuthal integral of the
   cosine-weighted BSDF, ``2 pi |mu_o| f_0(mu_o, mu_i)``, with ``f_0`` the zeroth Fourier order
   interpolated exactly as ``eval`` interpolates it (cubic splines in both elevations). It is
   integrated exactly, piece by piece between ordinates, over *both* hemispheres where the
   stack transmits, so that reflection versus transmission is chosen in proportion to their
   energies; a uniform variate is mapped through the piecewise integral by Newton-bisection.
2. Azimuth: given ``mu_o``, the interpolated series ``g(phi) = sum_l g_l cos(l phi)`` is
   inverted by Newton-bisection on its integral ``g_0 phi + sum_l g_l sin(l phi) / l``.

Where nothing is clamped, the density is exactly ``f_Y(wi, wo) |wo.z| / E(wi)`` (``f_Y`` the
luminance of ``eval``, ``E`` its cosine-weighted integral over the sphere): a one-channel BSDF
then has the constant weight ``E(wi)`` (perfect importance sampling of the interpolated BSDF).

Negative values
---------------
The series at the ordinates are non-negative up to small projection errors next to the critical
angle (lobes cut in azimuth are tapered with a non-negative kernel), but cubic interpolation
between ordinates undershoots slightly below zero next to sharp edges of a lobe (``eval`` returns
the positive part of the interpolant; see :mod:`layersim.solved.bsdf`). The *sampling* density is
kept non-negative, and ``pdf`` reports exactly the density that is sampled:

* elevation: in an interval between ordinates where the interpolated ``f_0`` is negative at one
  of the four nodes involved or the cubic dips below zero, the sampler (and ``pdf``) use the
  linear interpolant of its two end values clamped to ``>= 0`` instead, and sample the azimuth
  uniformly there;
* azimuth elsewhere: the density is ``max(g, 0) / (2 pi g_0)``, the shape of ``eval`` (the
  positive part of the same interpolant) for a one-channel BSDF. Where ``g`` is negative
  somewhere, inverting its integral follows ``g`` only up to the negative mass, so ``pdf``
  integrates to ``1 + `` that mass (4.6e-5 for rough glass lit from inside at 140 degrees, 1
  where the interpolant is non-negative: see ``tests/test_bsdf_sampling.py``);
* weights are ``eval(wi, wo) |wo.z| / pdf`` per channel (never negative).

RGB
---
A three-channel BSDF is sampled by luminance (Rec. 709 weights,
:data:`layersim.solved.channels.LUMINANCE`, as layerlab and Mitsuba do with the ``Y`` channel of
``.bsdf`` files); the weights are returned per channel, ``weight[..., c] = f_c |wo.z| / pdf``.

Anisotropic stacks
------------------
The coupled-mode series has no one-dimensional azimuthal inverse, so the sampler draws from the
stack's rotational average (:meth:`layersim.aniso.operator.AnisoOperator.rotational_average`:
the ``s = 0`` coefficients, an isotropic series sampled as above) and weights by the anisotropic
``eval``: ``weight = f(wi, wo) |wo.z| / pdf`` stays unbiased (the average is positive wherever
the BSDF is), with a variance that grows with the anisotropy.

Invalid samples
---------------
``wi`` on the horizon, light from below an opaque stack (``wi.z < 0``: nothing enters it), or an
incident direction from which no energy leaves give an invalid sample, row by row: ``pdf = 0``,
``weight = 0`` and ``wo = (0, 0, 0)`` (not a direction), flagged by :attr:`Sample.valid`. This is
Mitsuba 3's contract (an invalid ``BSDFSample3f`` with zero weight and pdf) rather than an
exception, so that a batch in which some rows hit an opaque surface from behind keeps its other
rows, and a single direction behaves as a batch of one;
:func:`layersim.solved.directions.unit_directions` still raises for ``wi`` that is not a unit
vector. Delta parts (the unscattered transmission of media, the mirror reflection of smooth
interfaces) are not part of ``eval`` and are not sampled: :meth:`layersim.solved.bsdf.BSDF.specular`
gives their directions and energies. A BSDF with a smooth dielectric boundary is sampled inside the
boundary and refracted out (:class:`BoundarySampler`).
"""

from __future__ import annotations

import math
import weakref
from typing import NamedTuple

import numpy as np

from .channels import luminance, luminance_series
from .directions import azimuth, direction_pairs, unit_directions
from ..operators.interpolation import spline_weights
from ..kernels import fourier_sample
from ..operators.operator import BLOCKS

_BLOCK_ID = {name: k for k, name in enumerate(BLOCKS)}


class Sample(NamedTuple):
    """What ``sample(wi, u)`` returns; unpacks as ``wo, weight, pdf``.

    Attributes
    ----------
    wo : ndarray, shape (..., 3)
        Sampled unit directions toward the viewer; ``(0, 0, 0)`` where the sample is invalid.
    weight : ndarray, shape (...) or (..., 3)
        ``max(f(wi, wo), 0) |wo.z| / pdf`` per channel; 0 where the sample is invalid.
    pdf : ndarray, shape (...)
        Solid-angle density of ``wo`` (1/sr); 0 where the sample is invalid.
    """

    wo: np.ndarray
    weight: np.ndarray
    pdf: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        """Boolean array, shape ``pdf.shape``: False where no direction was drawn (``wi`` on
        the horizon, below an opaque stack, or with no energy leaving); there ``wo`` is
        ``(0, 0, 0)`` and ``weight`` and ``pdf`` are 0, so a renderer ends the path."""
        return np.asarray(self.pdf) > 0
_SAMPLERS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def sampler_for(bsdf) -> "FourierSampler":
    """The (cached) sampler of a BSDF (anisotropic ones: see the module docstring)."""
    s = _SAMPLERS.get(bsdf)
    if s is None and any(bsdf.lobes):
        s = LobeSampler(bsdf)
        _SAMPLERS[bsdf] = s
    if s is None and bsdf.boundary:
        s = BoundarySampler(bsdf)
        _SAMPLERS[bsdf] = s
    if s is None:
        s = FourierSampler(bsdf.rotational_average(), target=bsdf)
        _SAMPLERS[bsdf] = s
    return s


class BoundarySampler:
    """Sampling of a BSDF with smooth dielectric boundaries (:mod:`layersim.solved.boundary`): the
    inside series is sampled as by :class:`FourierSampler`, in the refracted incident
    direction, and the sampled inside direction is refracted out. The density changes by the
    solid-angle factor ``domega_in / domega_out = x / (eta^2 mu)`` (``x`` and ``mu`` the outside
    and inside cosines); inside directions under total internal reflection leave nowhere and
    give invalid samples (weight 0). The weight is the whole BSDF's ``eval`` over that density,
    so the estimator stays unbiased for the smooth part; deltas are not sampled."""

    def __init__(self, bsdf):
        self.target = bsdf
        self.exits = bsdf.evaluator(0).exits
        self.inner = sampler_for(type(bsdf)(bsdf.operators, info=bsdf.info, lobes=bsdf.lobes))

    def _side(self, w):
        return np.where(w[..., 2] > 0, "top", "bottom")

    def _to_inside(self, w):
        out = w.copy()
        for side, ex in self.exits.items():
            sel = self._side(w) == side
            out[sel] = ex.to_inside(w[sel])
        return out

    def _jacobian(self, wo_out, wo_in):
        """``domega_in / domega_out`` for each outgoing pair (1 off the boundaries)."""
        jac = np.ones(wo_out.shape[0])
        for side, ex in self.exits.items():
            sel = self._side(wo_out) == side
            jac[sel] = np.abs(wo_out[sel, 2]) / (ex.eta**2 * np.abs(wo_in[sel, 2]))
        return jac

    def sample(self, wi, u):
        """As :meth:`FourierSampler.sample`."""
        wi, u, shape = _sample_inputs(wi, u)
        wo_in, _, pdf_in = self.inner.sample(self._to_inside(wi), u)
        wo = wo_in.copy()
        ok = pdf_in > 0
        for side, ex in self.exits.items():
            sel = ok & (self._side(wo_in) == side)
            escapes = np.abs(wo_in[:, 2]) > ex.mu_c
            ok &= ~sel | escapes
            sel &= escapes
            wo[sel] = ex.to_outside(wo_in[sel])
        pdf = np.where(ok, pdf_in, 0.0)
        pdf[ok] *= self._jacobian(wo[ok], wo_in[ok])
        return _sample_result(self.target, wi, wo, pdf, shape)

    def pdf(self, wi, wo) -> np.ndarray:
        """As :meth:`FourierSampler.pdf`."""
        wi, wo, shape = direction_pairs(wi, wo)
        wo_in = self._to_inside(wo)
        pdf = np.asarray(self.inner.pdf(self._to_inside(wi), wo_in), float).reshape(-1)
        return (pdf * self._jacobian(wo, wo_in)).reshape(shape)


class LobeSampler:
    """Sampling of a BSDF with a near-specular lobe (:mod:`layersim.solved.lobe`): a mixture of the
    lobe's own sampling (visible normals, reflected: :meth:`layersim.solved.lobe.NearSpecularLobe.
    sample`), chosen with probability ``P(wi)``, the lobe's share of the (luminance) energy
    leaving from ``wi`` outside the deltas, and the sampler of the rest of the BSDF (the same
    operators without the lobe). The density is ``P pdf_lobe + (1 - P) pdf_rest`` and the weight
    the whole ``eval`` over it, so the estimator is unbiased, and exact in the lobe's share
    where the rest carries no energy (a bare conductor).

    ``u[..., 0]`` chooses the component and is reused, rescaled, as the lobe's first variate;
    the lobe's Box-Muller angle (Beckmann) takes the low-order digits of ``u[..., 1]``."""

    def __init__(self, bsdf):
        self.target = bsdf
        self.lobes = [bsdf.evaluator(c).lobes["top"] for c in range(bsdf.channels)]
        self.rest_bsdf = type(bsdf)(bsdf.operators, info=bsdf.info, boundary=bsdf.boundary)
        self._rest = None

    @property
    def rest(self):
        if self._rest is None:
            self._rest = sampler_for(self.rest_bsdf)
        return self._rest

    def _share(self, wi: np.ndarray) -> np.ndarray:
        """``P(wi)`` (Q,): the lobe's energy (azimuth average) over all the energy leaving
        outside the deltas; any ``P`` keeps the estimator unbiased, this one makes the weights
        nearly constant."""
        lobe = np.zeros((wi.shape[0], len(self.lobes)))
        total = np.zeros_like(lobe)
        top = wi[:, 2] > 0
        for c, lb in enumerate(self.lobes):
            ev = self.target.evaluator(c)
            R, T = ev.albedo(wi)
            deltas = sum(e for e, _ in ev.specular(wi).values())
            total[:, c] = R + T - deltas
            if top.any():
                lobe[top, c] = lb.reflected(wi[top, 2])
        if len(self.lobes) == 3:
            lobe, total = luminance(lobe), luminance(total)
        else:
            lobe, total = lobe[:, 0], total[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            share = np.where(total > 0, lobe / np.where(total > 0, total, 1.0), 0.0)
        return np.clip(share, 0.0, 1.0)

    def sample(self, wi, u):
        """As :meth:`FourierSampler.sample`."""
        wi, u, shape = _sample_inputs(wi, u)
        P = self._share(wi)
        pick = u[:, 0] < P
        wo = np.zeros_like(wi)
        if pick.any():
            u0 = u[pick, 0] / P[pick]
            u1 = u[pick, 1]
            u2 = np.modf(u1 * 4096.0)[0]
            wo[pick] = self.lobes[0].sample(wi[pick], np.stack([u0, u1, u2], axis=1))
        rest = ~pick & (P < 1)
        if rest.any():
            v = np.stack([(u[rest, 0] - P[rest]) / (1.0 - P[rest]), u[rest, 1]], axis=1)
            wo[rest] = self.rest.sample(wi[rest], v)[0]
        valid = np.linalg.norm(wo, axis=1) > 0
        pdf = np.zeros(wi.shape[0])
        pdf[valid] = self._pdf(wi[valid], wo[valid], P[valid])
        return _sample_result(self.target, wi, wo, pdf, shape)

    def _pdf(self, wi: np.ndarray, wo: np.ndarray, P: np.ndarray) -> np.ndarray:
        out = P * self.lobes[0].pdf(wi, wo)
        rest = P < 1
        if rest.any():
            out[rest] += (1.0 - P[rest]) * np.asarray(
                self.rest.pdf(wi[rest], wo[rest]), float).reshape(-1)
        return out

    def pdf(self, wi, wo) -> np.ndarray:
        """As :meth:`FourierSampler.pdf`."""
        wi, wo, shape = direction_pairs(wi, wo)
        return self._pdf(wi, wo, self._share(wi)).reshape(shape)


def _uniforms(u) -> np.ndarray:
    u = np.asarray(u, dtype=float)
    if u.ndim == 0 or u.shape[-1] != 2:
        raise ValueError(f"u must have shape (..., 2) (two uniform variates per sample), got "
                         f"shape {u.shape}")
    if not np.all(np.isfinite(u)) or np.any(u < 0.0) or np.any(u > 1.0):
        raise ValueError("u must hold uniform variates within [0, 1]")
    return u


class FourierSampler:
    """Importance sampling and its density for one :class:`layersim.BSDF` (see module docs).

    Parameters
    ----------
    bsdf : layersim.BSDF
        Isotropic BSDF whose Fourier series is sampled.
    device : str, optional
        Warp device for the kernels (default: ``$LAYERSIM_DEVICE`` or the CPU).
    target : layersim.BSDF, optional
        BSDF whose ``eval`` gives the weights (default ``bsdf``); anisotropic stacks pass
        themselves with their rotational average as ``bsdf``.
    """

    def __init__(self, bsdf, device=None, target=None):
        self.bsdf = bsdf
        self.target = bsdf if target is None else target
        self.device = device
        self.mu = np.asarray(bsdf.grid.mu, float)
        self.h = self.mu.size
        self.offsets, self.coef = luminance_series(bsdf)
        counts = np.diff(self.offsets)
        self.c0 = np.where(counts > 0, self.coef[np.minimum(self.offsets[:-1],
                                                            max(self.coef.size - 1, 0))], 0.0)
        op = bsdf.operators[0]
        self.present = {name: op.blocks[name] is not None for name in BLOCKS}

    # ---- helpers -----------------------------------------------------------------------

    def _base(self, name: str) -> int:
        return _BLOCK_ID[name] * self.h * self.h if self.present[name] else -1

    def _bases(self, mu_in: np.ndarray):
        """First pair of the reflection and transmission block for each incident elevation
        (``-1`` where the block is left out or no light enters)."""
        top = mu_in > 0
        base_r = np.where(top, self._base("Rt"), self._base("Rb"))
        base_t = np.where(top, self._base("Ttb"), self._base("Tbt"))
        dead = mu_in == 0
        base_r[dead] = -1
        base_t[dead] = -1
        return base_r.astype(np.int64), base_t.astype(np.int64)

    def _incident(self, mu_in: np.ndarray):
        """Spline taps, block bases and side masses for each incident elevation. The masses
        depend on ``mu_in`` only (not on the azimuth), so they are computed once per distinct
        value (a batch sharing one ``wi`` costs one integration)."""
        in_taps, in_w = spline_weights(self.mu, np.abs(mu_in))
        base_r, base_t = self._bases(mu_in)
        keys, first, inverse = np.unique(mu_in, return_index=True, return_inverse=True)
        masses = fourier_sample.side_masses(self.mu, self.c0, in_taps[first], in_w[first],
                                            base_r[first], base_t[first], self.device)
        return in_taps, in_w, base_r, base_t, masses[inverse.ravel()]

    def _pairs(self, base, mu_out, in_taps, in_w):
        """16 neighbouring pairs and weights (the same spline weights as ``eval``)."""
        io, wo_ = spline_weights(self.mu, mu_out)
        h = self.h
        pair = base[:, None] + (io[:, :, None] * h + in_taps[:, None, :]).reshape(-1, 16)
        weight = (wo_[:, :, None] * in_w[:, None, :]).reshape(-1, 16)
        return pair, weight

    # ---- public ------------------------------------------------------------------------

    def sample(self, wi, u):
        """Draw outgoing directions.

        Parameters
        ----------
        wi : array_like, shape (..., 3)
            Unit directions toward the light (local frame).
        u : array_like, shape (..., 2)
            Uniform variates in [0, 1]; ``u[..., 1]`` picks the elevation (and side),
            ``u[..., 0]`` the azimuth. Broadcast against ``wi``.

        Returns
        -------
        wo : ndarray, shape (..., 3)
            Sampled unit directions toward the viewer (``(0, 0, 0)`` for invalid samples).
        weight : ndarray, shape (...) or (..., 3)
            ``max(f(wi, wo), 0) |wo.z| / pdf`` per channel (0 where ``pdf == 0``).
        pdf : ndarray, shape (...)
            Solid-angle density of ``wo`` (1/sr), equal to :meth:`pdf` at ``wo``.
        """
        wi, u, shape = _sample_inputs(wi, u)
        Q = wi.shape[0]
        mu_in = wi[:, 2]
        in_taps, in_w, base_r, base_t, masses = self._incident(mu_in)
        mu_o, side, pdf_mu, exact = fourier_sample.sample_elevation(
            self.mu, self.c0, in_taps, in_w, base_r, base_t, masses, u[:, 1], self.device)
        ok = side >= 0
        wo = np.zeros((Q, 3))
        pdf = np.zeros(Q)
        if ok.any():
            sel = np.flatnonzero(ok)
            base = np.where(side[sel] == 0, base_r[sel], base_t[sel])
            pair, weight = self._pairs(base, mu_o[sel], in_taps[sel], in_w[sel])
            dphi, pdf_phi = fourier_sample.sample_azimuth(self.offsets, self.coef, pair, weight,
                                                          exact[sel], u[sel, 0], self.device)
            phi_o = azimuth(wi[sel]) + math.pi + dphi
            sin_t = np.sqrt(np.maximum(0.0, 1.0 - mu_o[sel] ** 2))
            sgn = np.sign(mu_in[sel]) * np.where(side[sel] == 0, 1.0, -1.0)
            wo[sel] = np.stack([sin_t * np.cos(phi_o), sin_t * np.sin(phi_o),
                                sgn * mu_o[sel]], axis=-1)
            pdf[sel] = pdf_mu[sel] * pdf_phi
        return _sample_result(self.target, wi, wo, pdf, shape)

    def pdf(self, wi, wo) -> np.ndarray:
        """Solid-angle density (1/sr) with which :meth:`sample` draws ``wo`` given ``wi``.

        Parameters
        ----------
        wi, wo : array_like, shape (..., 3)
            Unit directions (broadcast against each other).

        Returns
        -------
        ndarray, shape (...)
            0 on the horizon, for left-out blocks and for invalid ``wi``.
        """
        wi, wo, shape = direction_pairs(wi, wo)
        mu_in = wi[:, 2]
        in_taps, in_w, base_r, base_t, masses = self._incident(mu_in)
        same = np.sign(wo[:, 2]) == np.sign(mu_in)
        side = np.where(same, 0, 1).astype(np.int32)
        side[(wo[:, 2] == 0) | (mu_in == 0)] = -1
        mu_o = np.abs(wo[:, 2])
        pdf, exact = fourier_sample.pdf_elevation(self.mu, self.c0, in_taps, in_w, base_r,
                                                  base_t, masses, mu_o, side, self.device)
        ok = np.flatnonzero(pdf > 0)
        if ok.size:
            base = np.where(side[ok] == 0, base_r[ok], base_t[ok])
            pair, weight = self._pairs(base, mu_o[ok], in_taps[ok], in_w[ok])
            dphi = azimuth(wo[ok]) - azimuth(wi[ok]) - math.pi
            pdf[ok] *= fourier_sample.pdf_azimuth(self.offsets, self.coef, pair, weight,
                                                  exact[ok], dphi, self.device)
        return pdf.reshape(shape)


def _sample_result(target, wi: np.ndarray, wo: np.ndarray, pdf: np.ndarray, shape: tuple):
    """``(wo, weight, pdf)`` of a batch of samples in the caller's ``shape``: ``weight`` is
    ``f |wo.z| / pdf`` per channel (never negative: ``f`` is ``target.eval``, the positive part
    of the interpolant), and samples with ``pdf = 0`` (none drawn) return ``wo = 0`` and
    weight 0 (:class:`Sample`). ``wi``, ``wo`` (Q, 3) and ``pdf`` (Q,) are flat; ``wo`` is
    modified."""
    good = pdf > 0
    wo[~good] = 0.0
    nch = target.channels
    weight = np.zeros((wi.shape[0], nch))
    g = np.flatnonzero(good)
    if g.size:
        f = target.eval(wi[g], wo[g]).reshape(g.size, nch)
        weight[g] = f * (np.abs(wo[g, 2]) / pdf[g])[:, None]
    weight = weight[:, 0] if nch == 1 else weight
    return Sample(wo.reshape(shape + (3,)), weight.reshape(shape + weight.shape[1:]),
                  pdf.reshape(shape))


def _sample_inputs(wi, u) -> tuple[np.ndarray, np.ndarray, tuple]:
    """``wi`` (validated directions) and ``u`` (uniforms in [0, 1)^2) broadcast together and
    flattened to ``(Q, 3)`` and ``(Q, 2)``, with the broadcast shape ``(...)``."""
    wi = unit_directions("wi", wi)
    u = _uniforms(u)
    shape = np.broadcast_shapes(wi.shape[:-1], u.shape[:-1])
    return (np.broadcast_to(wi, shape + (3,)).reshape(-1, 3),
            np.broadcast_to(u, shape + (2,)).reshape(-1, 2), shape)
