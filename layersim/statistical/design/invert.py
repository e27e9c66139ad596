"""The per-lobe inversions of Bati et al. 2021: base statistics of the stack above a lobe
(Algorithm 3, eq. 18-19) and the parameters of one interface (Algorithm 4; conductors by
sec. 5.1.2 and 5.2.4), at normal incidence, per channel.

All energies use the normal-incidence slice of the FGD table (:mod:`layersim.statistical.fgd`)
that the forward model reads, so a designed stack reproduces its targets in the forward model
to the accuracy of the root finding.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from .. import fgd
from ..forward import add_stack
from ..targets import TargetError
from ..variance import roughness, variance

#: Reflectance below which a conductor cannot go: kappa >= eta needs R > 3 - 2 sqrt(2)
#: (Bati et al. 2021, after eq. 10).
CONDUCTOR_R_MIN = 3.0 - 2.0 * math.sqrt(2.0)
#: Largest extinction coefficient a scene accepts (:mod:`layersim.scene`).
K_MAX = 100.0


def base_stats(stacks, energy: np.ndarray, sigma: float, lobe: int):
    """Algorithm 3: the attenuated energy ``R'`` (eq. 18, per channel) and the reflected
    variance ``sigma^R`` (eq. 19, for the channel of largest ``R'``, Bati et al. 2021 sec.
    5.2.3) that the layer(s) of lobe ``lobe`` must produce below the stacks (one per channel,
    lists of atoms), and ``s_t0n`` and the statistics of each channel.

    Raises
    ------
    TargetError
        If the layers above already spread the light more than ``sigma`` (names the
        smallest reachable variance) or absorb more than the energy allows.
    """
    stats = [add_stack(s, 1.0) for s in stacks]
    r_prime = np.empty(len(stats))
    for c, st in enumerate(stats):
        if st.cos is None or st.T0i * st.Ti0 <= 0.0:
            raise TargetError("no light reaches this lobe through the layers above", lobe)
        r_prime[c] = energy[c] / (st.T0i * st.Ti0 + st.Ri0 * energy[c])
    c = int(np.argmax(r_prime))
    st, rp = stats[c], r_prime[c]
    rr = st.Ri0 * rp
    sigma_min = st.s_ti0 + st.j0i * (st.s_t0i + rr * st.s_ri0 / (1.0 - rr))
    s_r = (1.0 - rr) * ((sigma - st.s_ti0) / st.j0i - st.s_t0i) - rr * st.s_ri0
    if s_r < -1e-12:
        raise TargetError(f"variance {sigma:.4g} (roughness {roughness(sigma):.4g}) is below "
                          f"{sigma_min:.4g} (roughness {roughness(sigma_min):.4g}), the spread "
                          "the layers above already give this lobe (Bati et al. 2021 eq. 19)",
                          lobe, "roughness")
    return r_prime, max(s_r, 0.0), st.s_t0i, stats


def dielectric_root(r: float, alpha: float, eta_above: float, eta_max: float,
                    prefer: str = "above") -> float | None:
    """Absolute index ``eta`` below an interface of roughness ``alpha`` with FGD at normal
    incidence ``r`` (Bati et al. 2021 eq. 7 for smooth interfaces, the FGD inverted
    numerically otherwise), within ``[1, eta_max]``; ``prefer``: the root above ``eta_above``
    or the one below it when both exist. None when neither is in range."""
    f = lambda eta: float(fgd.dielectric(1.0, alpha, eta / eta_above)) - r
    roots = []
    hi = min(eta_max, fgd.ETA_MAX * eta_above)
    if hi > eta_above and f(hi) >= 0.0:
        roots.append(brentq(f, eta_above, hi, xtol=1e-13, rtol=1e-13) if f(eta_above) < 0
                     else eta_above)
    lo = max(1.0, fgd.ETA_MIN * eta_above)
    if lo < eta_above and f(lo) >= 0.0:
        roots.append(brentq(f, lo, eta_above, xtol=1e-13, rtol=1e-13) if f(eta_above) < 0
                     else eta_above)
    if not roots:
        return None
    return roots[0] if prefer == "above" or len(roots) == 1 else roots[1]


def dielectric_limit(alpha: float, eta_above: float, eta_max: float) -> float:
    """Largest FGD at normal incidence of an interface below ``eta_above`` within
    ``[1, eta_max]``."""
    ends = [min(eta_max, fgd.ETA_MAX * eta_above), max(1.0, fgd.ETA_MIN * eta_above)]
    return max(float(fgd.dielectric(1.0, alpha, e / eta_above)) for e in ends)


def conductor_index(r: float, alpha: float, eta_above: float, choice: str, lobe: int):
    """Complex index ``eta + i k`` of a conductor below ``eta_above`` whose FGD at normal
    incidence is ``r``: ``eta`` from the conductor equivalence class of Fresnel reflectance
    ``r`` (Bati et al. 2021 eq. 9-10: ``kappa >= eta`` bounds it by ``eta_max = (1 + r +
    sqrt(6 r - 1 - r^2)) / (2 (1 - r))``; ``choice`` "edge" takes the lower bound ``(1 - r) /
    (1 + r)``, Gulbrandsen's largest edge tint, anything else the middle of the class as the
    paper does), then ``k`` solved so that the rough FGD (not Fresnel) equals ``r``."""
    if not CONDUCTOR_R_MIN < r < 1.0:
        raise TargetError(f"a conductor base needs a reflectance in ({CONDUCTOR_R_MIN:.4f}, 1) "
                          f"at normal incidence under the layers above, this lobe asks for "
                          f"{r:.4g} (kappa >= eta, Bati et al. 2021 eq. 9)", lobe, "energy")
    eta_hi = (1 + r + math.sqrt(max(6 * r - 1 - r * r, 0.0))) / (2 * (1 - r))
    eta_lo = (1 - r) / (1 + r)
    eta = eta_lo if choice == "edge" else 0.5 * (eta_lo + eta_hi)
    f = lambda k: fgd.conductor(1.0, alpha, eta, k) - r
    # start from the smooth interface's k (eq. 8) and widen the bracket geometrically; the
    # rough FGD is not monotonic in k where eta << 1 (total reflection off tilted facets)
    k0 = math.sqrt(max(r * (eta + 1) ** 2 - (eta - 1) ** 2, 1e-12) / (1 - r))
    k_max = K_MAX / eta_above
    if f(k_max) < 0.0:
        raise TargetError(f"a conductor of roughness {alpha:.4g} reflects at most "
                          f"{f(k_max) + r:.4g} (k <= {K_MAX:g}; single-scattering GGX loses the "
                          f"rest to shadowing), this lobe asks for {r:.4g}", lobe, "energy")
    lo, hi = min(k0, k_max), min(k0, k_max)
    for _ in range(40):
        if f(lo) <= 0.0 <= f(hi):
            break
        lo, hi = max(lo / 1.5, 1e-6), min(hi * 1.5, k_max)
    else:
        raise TargetError(f"no conductor index of this class (eta = {eta * eta_above:.4g}) "
                          f"reaches reflectance {r:.4g} at roughness {alpha:.4g}", lobe,
                          "energy")
    k = brentq(f, lo, hi, xtol=1e-12, rtol=1e-12) if lo < hi else k0
    return complex(eta * eta_above, k * eta_above)


def interface_roughness(s_r: float) -> float:
    """Roughness of the interface whose reflected variance is ``s_r``."""
    return roughness(s_r)


def effective_roughness(s_r: float, s_t0n: float) -> float:
    """Roughness at which the FGD of an interface is read below a stack that spreads the
    transmitted light by ``s_t0n`` (Bati et al. 2021, Algorithm 4)."""
    return roughness(s_r + s_t0n)


def optical_depth(r: float, r_prime: np.ndarray) -> np.ndarray:
    """Eq. 13: ``tau = 1/2 log(R / R')`` per channel (>= 0 where ``R >= R'``)."""
    return 0.5 * np.log(r / np.maximum(r_prime, 1e-300))


__all__ = ["base_stats", "dielectric_root", "dielectric_limit", "conductor_index",
           "interface_roughness", "effective_roughness", "optical_depth", "variance",
           "CONDUCTOR_R_MIN"]
