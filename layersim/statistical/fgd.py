"""FGD tables: the directional albedo of a GGX interface's reflection (Belcour 2018, sec. 5;
Bati et al. 2021, sec. 4 and Fig. 6), tabulated once, cached on disk and interpolated.

The values come from :func:`layersim.kernels.fgd.fgd`, which integrates the microfacet BSDF of
:mod:`layersim.kernels.physics` (the solver's and the Monte Carlo walk's) over the outgoing
hemisphere. Dielectric interfaces are tabulated on a regular grid in ``(mu, alpha, log eta)``;
conductors (two index components per channel, few calls) are integrated on demand and memoised.

Resolution (:data:`MU`, :data:`ALPHA`, :data:`LOG_ETA`): 32 incidence cosines ``1/32 .. 1``,
33 roughnesses ``0 .. 1``, 65 relative indices log-spaced over ``[1/4, 4]`` (``eta = 1`` is a
node); trilinear interpolation of ``sqrt(FGD)``. ``mu = 1`` is a node, so the normal-incidence slice used by the
inverse design (:mod:`layersim.statistical.design`) is the forward model's exactly. Queries
outside the grid are refused (``alpha > 1``, ``eta`` outside [1/4, 4]) or clamped (``mu < 1/32``
takes the value at 1/32).
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from .. import tablecache

#: Table axes: incidence cosine, GGX roughness, log of the relative index.
MU = np.linspace(1.0 / 32.0, 1.0, 32)
ALPHA = np.linspace(0.0, 1.0, 33)
ETA_MIN, ETA_MAX = 0.25, 4.0
LOG_ETA = np.linspace(np.log(ETA_MIN), np.log(ETA_MAX), 65)
#: Quadrature of each table entry (Gauss-Legendre nodes per panel in u and phi).
NODES = (64, 32)
_VERSION = 1


class FGDRangeError(ValueError):
    """A roughness or relative index outside the FGD table."""


def _cache_path() -> Path | None:
    return tablecache.path(f"fgd_ggx_v{_VERSION}_{MU.size}x{ALPHA.size}x{LOG_ETA.size}"
                           f"_q{NODES[0]}x{NODES[1]}.npz")


def build_table() -> np.ndarray:
    """Compute the dielectric table, shape ``(MU.size, ALPHA.size, LOG_ETA.size)`` (about 10 s
    on one core)."""
    from ..kernels import fgd as kernel
    mu, alpha, log_eta = np.meshgrid(MU, ALPHA, LOG_ETA, indexing="ij")
    return kernel.fgd(mu, alpha, np.exp(log_eta), 0.0, n_u=NODES[0], n_phi=NODES[1])


@functools.lru_cache(maxsize=None)
def _table_for(cache: str | None) -> np.ndarray:
    path = Path(cache) if cache else None
    stored = tablecache.read(path)
    if stored is not None and "fgd" in stored \
            and stored["fgd"].shape == (MU.size, ALPHA.size, LOG_ETA.size):
        return stored["fgd"]
    table = build_table()
    tablecache.write(path, fgd=table, mu=MU, alpha=ALPHA, log_eta=LOG_ETA)
    return table


def table() -> np.ndarray:
    """The dielectric FGD table (from the cache directory, or computed and stored there)."""
    path = _cache_path()
    return _table_for(str(path) if path else None)


@functools.lru_cache(maxsize=None)
def _interpolator(cache: str | None) -> RegularGridInterpolator:
    # sqrt(FGD) is close to |eta - 1| / (eta + 1), piecewise linear in log(eta) with its kink
    # on the node eta = 1: interpolating it rather than FGD removes most of the error
    return RegularGridInterpolator((MU, ALPHA, LOG_ETA), np.sqrt(np.maximum(
        _table_for(cache), 0.0)), method="linear")


def _check(alpha, eta):
    if np.any(alpha < 0.0) or np.any(alpha > ALPHA[-1] + 1e-12):
        raise FGDRangeError(f"roughness {np.max(alpha):g} outside the FGD table [0, 1]")
    if np.any(eta < ETA_MIN * (1 - 1e-12)) or np.any(eta > ETA_MAX * (1 + 1e-12)):
        bad = eta[(eta < ETA_MIN) | (eta > ETA_MAX)]
        raise FGDRangeError(f"relative index {float(bad.ravel()[0]):g} outside the FGD table "
                            f"[{ETA_MIN:g}, {ETA_MAX:g}]")


def dielectric(mu, alpha, eta) -> np.ndarray:
    """Interpolated FGD of a dielectric interface.

    Parameters
    ----------
    mu : array_like
        Incidence cosine in (0, 1].
    alpha : array_like
        GGX roughness in [0, 1].
    eta : array_like
        Index below the interface relative to the one above, in [1/4, 4].

    Returns
    -------
    ndarray, float64, broadcast shape: reflected energy fraction.

    Raises
    ------
    FGDRangeError
        For a roughness or index outside the table.
    """
    mu, alpha, eta = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64)
                                           for v in (mu, alpha, eta)))
    _check(alpha, eta)
    path = _cache_path()
    pts = np.stack([np.clip(mu, MU[0], 1.0), np.clip(alpha, 0.0, 1.0),
                    np.clip(np.log(eta), LOG_ETA[0], LOG_ETA[-1])], axis=-1)
    root = _interpolator(str(path) if path else None)(pts.reshape(-1, 3)).reshape(mu.shape)
    return root * root


@functools.lru_cache(maxsize=4096)
def _conductor_one(mu: float, alpha: float, eta: float, k: float) -> float:
    from ..kernels import fgd as kernel
    return float(kernel.fgd(mu, alpha, eta, k, n_u=NODES[0], n_phi=NODES[1]))


def conductor(mu: float, alpha: float, eta: float, k: float) -> float:
    """FGD of a conductor interface of relative index ``eta + i k`` (``k > 0``), integrated on
    demand with the table's quadrature (arguments rounded to 1e-9 for the memo)."""
    if not 0.0 <= alpha <= 1.0:
        raise FGDRangeError(f"roughness {alpha:g} outside [0, 1]")
    r = lambda x: round(float(x), 9)
    return _conductor_one(r(max(mu, MU[0])), r(alpha), r(eta), r(k))
