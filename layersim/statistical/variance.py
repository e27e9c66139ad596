"""Belcour's (2018) roughness-variance mapping and the variances of one GGX interface
(Bati et al. 2021, eq. 6 and the text after eq. 3)."""

from __future__ import annotations

import math

#: Exponent of the mapping f(alpha) = alpha^1.1 / (1 - alpha^1.1) (Belcour 2018, sec. 5.2).
EXPONENT = 1.1


def variance(alpha: float) -> float:
    """Lobe variance of a GGX roughness, ``f(alpha) = alpha^1.1 / (1 - alpha^1.1)``.

    Parameters
    ----------
    alpha : float
        GGX roughness in [0, 1).

    Returns
    -------
    float, >= 0 (``inf`` at ``alpha >= 1``).
    """
    a = abs(float(alpha)) ** EXPONENT
    return math.inf if a >= 1.0 else a / (1.0 - a)


def roughness(sigma: float) -> float:
    """Inverse of :func:`variance`: the GGX roughness ``(sigma / (1 + sigma))^(1/1.1)``
    of a lobe of variance ``sigma >= 0``."""
    s = max(float(sigma), 0.0)
    if math.isinf(s):
        return 1.0
    return (s / (1.0 + s)) ** (1.0 / EXPONENT)


def interface(alpha: float, eta: float, cos_i: float, cos_t: float | None):
    """Variances and Jacobians of one rough interface (Belcour 2018, Bati et al. 2021 eq. 6
    generalised to oblique incidence as in Belcour's implementation).

    Parameters
    ----------
    alpha : float
        GGX roughness of the interface.
    eta : float
        Real index below relative to above.
    cos_i, cos_t : float
        Cosines of the mean direction above and below (``cos_t`` None: no transmission, a
        conductor or total internal reflection).

    Returns
    -------
    dict with ``s_r12, s_r21`` (reflection), ``s_t12, s_t21`` (transmission, 0 without it) and
    ``j12, j21`` (the Jacobians of the variance through the interface, ``eta`` at normal
    incidence).
    """
    s_r = variance(alpha)
    if cos_t is None:
        return dict(s_r12=s_r, s_r21=s_r, s_t12=0.0, s_t21=0.0, j12=1.0, j21=1.0)
    s_t12 = variance(alpha * 0.5 * abs(cos_t * eta - cos_i) / (cos_t * eta))
    s_t21 = variance(alpha * 0.5 * abs(cos_i / eta - cos_t) / (cos_i / eta))
    return dict(s_r12=s_r, s_r21=s_r, s_t12=s_t12, s_t21=s_t21,
                j12=cos_t / cos_i * eta, j21=cos_i / cos_t / eta)
