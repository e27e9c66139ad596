"""Atomic operators of Belcour's statistical model (Belcour 2018, sec. 5; Bati et al. 2021,
sec. 4): the energies and variances of one interface or one absorbing medium, per channel.

An atom maps the mean direction above it (cosine ``cos_i``) to the one below (``cos_t``) and
carries reflectances ``R12, R21``, transmittances ``T12, T21``, their variances and the
Jacobians ``j12, j21`` of the variance through it. The stack is written top to bottom as
interfaces (:class:`Interface`: absolute index below, GGX roughness) and absorbing media
(:class:`Absorber`: optical depth along the normal, Beer-Lambert).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from . import fgd
from .variance import interface as interface_variances, roughness, variance


@dataclass(frozen=True)
class Interface:
    """A GGX interface into the medium of absolute index ``ior`` (complex: a conductor)."""

    ior: complex
    alpha: float


@dataclass(frozen=True)
class Absorber:
    """A non-scattering medium of optical depth ``tau`` at normal incidence."""

    tau: float


@dataclass(frozen=True)
class Atom:
    """Energies, variances and Jacobians of one layer for one channel."""

    R12: float
    T12: float
    R21: float
    T21: float
    s_r12: float
    s_r21: float
    s_t12: float
    s_t21: float
    j12: float
    j21: float
    cos_t: float | None
    lobe: bool


def absorber(layer: Absorber, cos_i: float) -> Atom:
    """Beer-Lambert transmittance ``exp(-tau / cos)`` each way; no reflection, no spread."""
    t = math.exp(-layer.tau / cos_i)
    return Atom(0.0, t, 0.0, t, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, cos_i, False)


def interface(layer: Interface, eta_above: float, cos_i: float, s_t0i: float) -> Atom:
    """One GGX interface lit at mean cosine ``cos_i`` from the medium of index ``eta_above``.

    ``R12`` is the FGD of the interface at the effective roughness ``f^-1(f(alpha) + s_t0i)``
    (Bati et al. 2021, Algorithms 1 and 4: the spread of the light transmitted down to the
    interface widens the microfacet lobe it meets); the transmitted energy is ``1 - R12`` both
    ways and ``R21 = R12`` (no total-internal-reflection term, as in Bati et al. 2021 sec. 5.2).
    Snell's law moves the mean direction; under total internal reflection or at a conductor
    ``cos_t`` is None and nothing is transmitted.
    """
    eta = layer.ior.real / eta_above
    k = layer.ior.imag / eta_above
    alpha_eff = roughness(variance(layer.alpha) + s_t0i)
    cos_t = None
    if k == 0.0:
        sin_t = math.sqrt(max(0.0, 1.0 - cos_i * cos_i)) / eta
        if sin_t < 1.0:
            cos_t = math.sqrt(1.0 - sin_t * sin_t)
    if k > 0.0:
        r12 = fgd.conductor(cos_i, alpha_eff, eta, k)
    else:
        r12 = float(fgd.dielectric(cos_i, alpha_eff, eta))
    v = interface_variances(layer.alpha, eta, cos_i, cos_t)
    if cos_t is None:
        return Atom(r12, 0.0, 0.0, 0.0, cos_t=None, lobe=True, **v)
    return Atom(r12, 1.0 - r12, r12, 1.0 - r12, cos_t=cos_t, lobe=True, **v)
