"""Synthetic single-view measurements of an analytic microfacet surface, for tests and benchmarks.

The data a gonioreflectometer with one camera and a moving light would record from a surface of
known GGX or Beckmann NDF (Wang et al. 2008 eq. 2-4, with the exact Smith shadowing of that NDF;
both from :mod:`layersim.kernels.physics`), with optional multiplicative Gaussian noise.
"""

from __future__ import annotations

import numpy as np

from ..kernels import pointwise
from . import microfacet as mf
from .measurements import Measurements


def direction(theta_deg: float, phi_deg: float) -> np.ndarray:
    """Unit vector (3,) at polar angle theta and azimuth phi, both in degrees."""
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def fibonacci_lights(n: int, max_theta_deg: float = 85.0) -> np.ndarray:
    """n nearly uniform unit vectors (n, 3) over the cap theta <= max_theta (Fibonacci lattice
    in cos theta), as a dense light sweep."""
    k = np.arange(n) + 0.5
    z = 1.0 - k / n * (1.0 - np.cos(np.radians(max_theta_deg)))
    r = np.sqrt(1.0 - z * z)
    p = np.pi * (3.0 - np.sqrt(5.0)) * k
    return np.stack([r * np.cos(p), r * np.sin(p), z], axis=1)


def analytic_ndf(distribution: str, alpha_u: float, alpha_v: float, rotation_deg: float = 0.0):
    """(ndf, shadow) callables of unit vectors (..., 3) for a GGX or Beckmann surface whose
    alpha_u axis lies at azimuth rotation_deg."""
    if distribution not in ("ggx", "beckmann"):
        raise ValueError(f"distribution must be 'ggx' or 'beckmann', not {distribution!r}")
    c, s = np.cos(np.radians(rotation_deg)), np.sin(np.radians(rotation_deg))

    def to_local(v):
        v = np.asarray(v, float)
        return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1],
                         v[..., 2]], axis=-1)

    return (lambda h: pointwise.ndf(to_local(h), alpha_u, alpha_v, distribution),
            lambda k: pointwise.smith_g1(to_local(k), alpha_u, alpha_v, distribution))


def measure(view, lights, distribution="ggx", alpha_u=0.3, alpha_v=0.6, rotation_deg=0.0,
            noise=0.0, eta=None, channel_scale=(1.0,), seed=0) -> Measurements:
    """Single-view measurements of an analytic surface.

    Parameters
    ----------
    view : (3,) unit vector toward the viewer
    lights : (N, 3) unit vectors toward the lights
    distribution : "ggx" or "beckmann"; alpha_u, alpha_v its roughness
    rotation_deg : azimuth of the alpha_u axis in degrees
    noise : relative standard deviation of multiplicative Gaussian noise
    eta : Fresnel index of eq. (3), None for F = 1
    channel_scale : specular coefficient per channel (one value per channel)
    seed : noise generator seed
    """
    ndf, shadow = analytic_ndf(distribution, alpha_u, alpha_v, rotation_deg)
    view = np.asarray(view, float)
    wo = np.broadcast_to(view, np.shape(lights))
    f = mf.specular_brdf(lights, wo, ndf, shadow, eta)
    rng = np.random.default_rng(seed)
    scale = np.asarray(channel_scale, float)
    vals = f[:, None] * scale[None, :] * (1.0 + noise * rng.standard_normal((len(f), len(scale))))
    return Measurements.from_arrays(view, lights, vals, source="synthetic")
