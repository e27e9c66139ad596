"""The target of one stage of a refinement: point samples ``(wi, wo, f)`` of the stack above a
lobe and of the lobe the targets ask for, which :func:`layersim.fit` matches by exact transport.

A lobe is Bati et al. 2021's ``R_k = R_{0,n+l} - R_{0,n}`` (sec. 6.1): what the stack cut below
the lobe's interfaces reflects beyond the stack cut above them. Stage ``k`` fits the cut below
lobe ``k`` with the layers above fixed (:mod:`layersim.statistical.refine`), so its target is
the exact BSDF of the cut above (solved) plus lobe ``k`` as wanted, per channel:

- at normal incidence, the target lobe itself, ``E_k D(h) G2(wi, wo) / (4 wi.z wo.z E(wi.z,
  alpha_k))``: Belcour's lobe (Bati et al. 2021 eq. 3), a GGX lobe without Fresnel normalised to
  carry the target energy ``E_k`` (``E``: its own directional albedo), as
  :class:`~layersim.statistical.StatisticalBSDF` evaluates it;
- at the other incidences of :data:`ANGLES`, the lobe that Belcour's statistical model gives the
  statistical design there (its interfaces' lobes of that target lobe): how the model, and with
  it the designer, extends the target away from the normal.

The points: per incidence, :data:`POINTS` outgoing directions that follow the target lobe, from
half vectors on a golden-angle lattice in GGX's own coordinates (``tan^2 theta_h = alpha^2 u /
(1 - u)`` with ``u`` uniform is distributed as ``D cos theta_h``) reflected about them, plus
:data:`FLOOR_POINTS` directions on a Fibonacci lattice over the hemisphere, where the stack must
not put light that the lobes do not.

The residual of a point is ``w (f_model - f) cos theta_o`` (1/sr), passed to the fit as the
standard deviation ``sigma = 1 / (w cos theta_o)`` (:mod:`layersim.fit.target`): the fit's own
``(f_model - f) cos theta_o`` weighted by ``w = 1`` at normal incidence, where the targets are
stated, and by :data:`OFF_NORMAL_WEIGHT` elsewhere. The model's lobes off the normal are no
exact transport of any stack (a GGX lobe without Fresnel carrying the model's energy): on
"coat over rough dielectric", the statistical design's own top interface, whose normal-incidence
lobe is exact to 3e-4 1/sr RMS, misses the model at 60 degrees by 4.6e-2; weighted as much, the
off-normal points drew the fit off the targets at normal incidence. At 0.02 they weigh about
as much as the normal-incidence mismatch and hold what it leaves loose. The points' density
follows the lobe, and so does the weight of its region.
"""

from __future__ import annotations

import math

import numpy as np

from ..verify import direction

__all__ = ["stage_samples", "lobe_directions", "floor_directions", "ANGLES", "POINTS",
           "FLOOR_POINTS", "OFF_NORMAL_WEIGHT"]

#: Incidence angles (degrees from the normal) of the samples.
ANGLES = (0.0, 30.0, 60.0)
#: Weight of the points off the normal (module docstring).
OFF_NORMAL_WEIGHT = 0.02
#: Outgoing directions per incidence that follow the lobe.
POINTS = 128
#: Outgoing directions spread over the hemisphere per incidence.
FLOOR_POINTS = 64
#: Largest ``u`` of the lattice (``tan theta_h = 3 alpha``): farther out a lobe carries
#: little, and the floor lattice sees it.
U_MAX = 0.9
#: Lowest ``wo.z`` kept (about 87 degrees from the normal).
WO_MIN_Z = 0.05
GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


def lobe_directions(wi: np.ndarray, alpha: float, n: int = POINTS) -> np.ndarray:
    """At most ``n`` outgoing directions (shape (m, 3)) that follow a GGX lobe of roughness
    ``alpha`` about the mirror of ``wi`` (module docstring); those below :data:`WO_MIN_Z`
    are dropped."""
    k = np.arange(n) + 0.5
    u = U_MAX * k / n
    tan_t = alpha * np.sqrt(u / (1.0 - u))
    cos_t = 1.0 / np.sqrt(1.0 + tan_t ** 2)
    sin_t = tan_t * cos_t
    phi = 2.0 * np.pi * np.mod(k * GOLDEN, 1.0)
    h = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=-1)
    wo = 2.0 * (h @ wi)[:, None] * h - wi
    return wo[wo[:, 2] > WO_MIN_Z]


def floor_directions(n: int = FLOOR_POINTS) -> np.ndarray:
    """``n`` directions on a Fibonacci lattice over the upper hemisphere above
    :data:`WO_MIN_Z`, shape (n, 3)."""
    k = np.arange(n) + 0.5
    z = WO_MIN_Z + (1.0 - WO_MIN_Z) * (1.0 - k / n)
    r = np.sqrt(1.0 - z * z)
    phi = 2.0 * np.pi * np.mod(k * GOLDEN, 1.0)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def lobe_values(wi: np.ndarray, wo: np.ndarray, energy, alpha) -> np.ndarray:
    """Belcour's lobe (module docstring) of ``energy`` and ``alpha`` (each per channel, shape
    (C,)) at one ``wi`` (3,) and outgoing ``wo`` (m, 3): f in 1/sr, shape (m, C); a smooth
    channel (``alpha = 0``, a delta) is 0."""
    from ...kernels.fgd import ggx_albedo, ggx_lobe
    pairs = np.broadcast_to(wi, wo.shape)
    f = np.zeros((len(wo), len(energy)))
    for c, (e, a) in enumerate(zip(energy, alpha)):
        if a > 0.0 and e > 0.0:
            f[:, c] = e * ggx_lobe(pairs, wo, float(a)) / float(ggx_albedo(float(wi[2]),
                                                                             float(a)))
    return f


def wanted_lobe(targets, model, groups, k: int, theta: float, wo: np.ndarray) -> np.ndarray:
    """Lobe ``k`` as wanted at incidence ``theta`` (degrees; module docstring), shape (m, C):
    the target at normal incidence, else the statistical model ``model`` (the design's
    :class:`~layersim.statistical.StatisticalBSDF`) summed over the interfaces ``groups[k]``."""
    wi, channels = direction(theta), targets.channels
    t = targets.lobes[k]
    if theta == 0.0:
        return lobe_values(wi, wo, np.broadcast_to(t.energy, (channels,)),
                         np.full(channels, t.roughness))
    f = np.zeros((len(wo), channels))
    for lobe in model.lobes(math.radians(theta)):
        if lobe.layer in groups[k]:
            f += lobe_values(wi, wo, np.broadcast_to(lobe.energy, (channels,)),
                           np.broadcast_to(lobe.roughness, (channels,)))
    return f


def stage_samples(targets, model, groups, k: int, above=None, channels: int | None = None,
                  angles=ANGLES) -> tuple:
    """The samples ``(wi, wo, f, sigma)`` of stage ``k`` (module docstring), shapes (N, 3),
    (N, 3), (N, channels), (N, channels); f in 1/sr, sigma (the weights) in 1/sr per unit
    residual.

    Parameters
    ----------
    targets : Targets
        The parsed targets (:func:`~layersim.statistical.parse_targets`); lobe ``k`` is rough.
    model : StatisticalBSDF
        The statistical design's model.
    groups : list
        Per target lobe, the indices of its interfaces in the design.
    k : int
        The lobe (0: top).
    above : BSDF, optional
        The exact solve of the stack above lobe ``k`` (None for the top lobe).
    channels : int, optional
        The channels of the cut fitted (default: the targets'); one channel where the cut is
        achromatic, whose lobes then are too (the mean of the channels, all equal).
    """
    channels = channels or targets.channels
    alpha = targets.lobes[k].roughness
    wis, wos, fs, ss = [], [], [], []
    for theta in angles:
        wi = direction(theta)
        wo = np.concatenate([lobe_directions(wi, alpha), floor_directions()])
        f = wanted_lobe(targets, model, groups, k, theta, wo)
        if channels != f.shape[1]:
            f = f.mean(axis=1, keepdims=True)
        if above is not None:
            f = f + np.asarray(above.eval(np.broadcast_to(wi, wo.shape), wo)).reshape(len(wo), -1)
        wis.append(np.broadcast_to(wi, wo.shape))
        wos.append(wo)
        fs.append(f)
        w = 1.0 if theta == 0.0 else OFF_NORMAL_WEIGHT
        ss.append(np.broadcast_to(1.0 / (w * wo[:, 2:3]), f.shape))
    return np.concatenate(wis), np.concatenate(wos), np.concatenate(fs), np.concatenate(ss)
