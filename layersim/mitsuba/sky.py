"""The procedural environment of ``layersim render`` and of the bench's binned renders.

Nothing is downloaded: a sky whose colour runs linearly in the cosine of the elevation from a
pale horizon to blue at the zenith, a dim warm ground below the horizon, and a small bright
sun-like disc. World space has ``y`` up; a direction of polar angle ``theta`` from ``+y`` and
azimuth ``phi`` is ``(sin theta sin phi, cos theta, -sin theta cos phi)``, the mapping of
Mitsuba 3's ``envmap`` (``u = atan2(x, -z) / 2 pi``, ``v = acos(y) / pi``), so that
:func:`sky_radiance` is the radiance that Mitsuba renders from :func:`sky_bitmap`.
"""

from __future__ import annotations

import numpy as np

#: Sky colours (linear RGB): horizon, zenith, ground.
HORIZON, ZENITH, GROUND = (0.9, 0.9, 0.85), (0.3, 0.5, 0.9), (0.2, 0.18, 0.15)
#: The sun: direction (polar angle from +y, azimuth as in the module docstring; radians),
#: angular radius (radians),
#: radiance (linear, relative to the sky's).
SUN_THETA, SUN_PHI, SUN_RADIUS, SUN_RADIANCE = 0.6, 1.0, 0.06, 40.0


def lat_long(theta, phi) -> np.ndarray:
    """World unit vectors (..., 3) of polar angles ``theta`` from ``+y`` and azimuths ``phi``
    (radians) in Mitsuba's environment-map parameterisation (module docstring)."""
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    return np.stack([np.sin(theta) * np.sin(phi), np.cos(theta),
                     -np.sin(theta) * np.cos(phi)], -1)


def sun_direction() -> np.ndarray:
    """Unit vector toward the sun's centre, world space, shape (3,)."""
    return lat_long(SUN_THETA, SUN_PHI)


def sky_radiance(d, sun: bool = True) -> np.ndarray:
    """Radiance arriving from the world directions ``d`` (..., 3) (unit vectors pointing
    away from the scene, ``y`` up): linear RGB, shape (..., 3), in the units of
    :data:`HORIZON` (1 = a white sky). ``sun=False`` leaves the disc out (a smooth sky)."""
    d = np.asarray(d, dtype=float)
    up = np.clip(d[..., 1], 0.0, 1.0)[..., None]
    sky = (1 - up) * np.array(HORIZON) + up * np.array(ZENITH)
    sky = np.where(d[..., 1:2] < 0, np.array(GROUND), sky)
    if sun:
        disc = d @ sun_direction() > np.cos(SUN_RADIUS)
        sky = sky + SUN_RADIANCE * disc[..., None]
    return sky


def sky_bitmap(width: int = 128, height: int = 64) -> np.ndarray:
    """The environment as an image, ``(height, width, 3)`` float32 linear RGB in Mitsuba's
    latitude-longitude layout (rows from the +y pole down), sampled at pixel centres."""
    theta = (np.arange(height) + 0.5) / height * np.pi
    phi = (np.arange(width) + 0.5) / width * 2 * np.pi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    return sky_radiance(lat_long(T, P)).astype(np.float32)


def sun_samples(count: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """The sun disc of :func:`sky_radiance` as ``count`` point sources: unit world directions
    (count, 3), stratified uniformly over the disc's solid angle (a Fibonacci spiral on the
    cap), and each one's irradiance at normal incidence (count, 3), ``SUN_RADIANCE`` times
    the disc's solid angle ``2 pi (1 - cos SUN_RADIUS)`` over ``count`` (W / m^2 in the sky's
    units). ``sky_radiance(d, sun=False)`` plus these is the environment with the sun."""
    k = np.arange(count) + 0.5
    cos_a = 1.0 - (1.0 - np.cos(SUN_RADIUS)) * k / count
    sin_a = np.sqrt(1.0 - cos_a ** 2)
    psi = np.pi * (3.0 - np.sqrt(5.0)) * k
    c = sun_direction()
    a = np.cross(c, [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(c, a)
    dirs = (cos_a[:, None] * c + sin_a[:, None] * (np.cos(psi)[:, None] * a
                                                   + np.sin(psi)[:, None] * b))
    omega = 2 * np.pi * (1.0 - np.cos(SUN_RADIUS))
    return dirs, np.full((count, 3), SUN_RADIANCE * omega / count)
