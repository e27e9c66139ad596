"""Host access to the Fresnel reflectances of :mod:`layersim.kernels.physics`: the smooth
(roughness 0) interfaces of the solver are diagonal in the ordinates with these values, so they
come from the same functions as the Monte Carlo walk's specular events
(:func:`layersim.kernels.sampling.sample_smooth`, ``sample_smooth_film``), bare or with a thin
film (:func:`layersim.kernels.physics.fresnel_interface`)."""

from __future__ import annotations

import numpy as np
import warp as wp

from . import physics
from .runtime import device_for


@wp.kernel
def _fresnel(cos_i: wp.array(dtype=wp.float64), eta: wp.float64, k: wp.float64,
             eta_film: wp.float64, phase_scale: wp.float64, out: wp.array(dtype=wp.float64)):
    q = wp.tid()
    out[q] = physics.fresnel_interface(cos_i[q], eta, k, eta_film, phase_scale)


def fresnel(cos_i, eta: float, k: float = 0.0, film: tuple | None = None) -> np.ndarray:
    """Unpolarised Fresnel reflectance for incidence cosines ``cos_i``.

    Parameters
    ----------
    cos_i : array_like
        Cosine between the incident direction (pointing away from the boundary) and the normal
        of the boundary pointing into the medium above; negative: the light arrives from below.
    eta : float
        Index below the boundary relative to the one above.
    k : float
        Extinction coefficient of a conductor below (0: dielectric; a conductor is lit from
        above only).
    film : (float, float), optional
        A thin film on the boundary: its index relative to the medium above and its phase
        scale ``4 pi n d / lambda`` (:meth:`layersim.layers.Interface.film_params`); its Airy
        reflectance replaces Fresnel's.

    Returns
    -------
    ndarray, float64, shape of ``cos_i``; 1 under total internal reflection.
    """
    cos_i = np.asarray(cos_i, dtype=np.float64)
    flat = np.ascontiguousarray(cos_i.reshape(-1))
    if flat.size == 0:
        return np.zeros(cos_i.shape)
    device = device_for("cpu")
    a = wp.array(flat, dtype=wp.float64, device=device)
    out = wp.zeros(flat.size, dtype=wp.float64, device=device)
    eta_film, phase_scale = film if film is not None else (0.0, 0.0)
    wp.launch(_fresnel, dim=flat.size, device=device,
              inputs=[a, float(eta), float(k), float(eta_film), float(phase_scale), out])
    return out.numpy().reshape(cos_i.shape)
