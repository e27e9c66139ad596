"""Smooth (roughness 0) interfaces: deltas in direction, exact in the ordinates.

A smooth interface reflects into the mirror direction and refracts by Snell's law. Mirror
reflection keeps ``|mu|`` and the azimuth of propagation (``phi = 0``), so it is a diagonal entry
with the same value in every Fourier order, on any grid: the Fresnel reflectance of
:mod:`layersim.kernels.physics` (the function the Monte Carlo walk uses) at each node.

* A smooth **conductor** is the opaque operator ``Rt = diag(F)`` in every order
  (:func:`smooth_conductor_operator`).
* A smooth **dielectric boundary** (the top interface of a stack, or the bottom one of a
  transmissive stack) refracts ``mu`` to its Snell image, which is diagonal only on a grid whose
  nodes are matched across the interface. The solver keeps the refraction out of the blocks: on
  the Snell-matched grid of :func:`layersim.operators.quadrature.snell_matched` the stack is solved
  in the directions just inside the boundary, with the boundary's internal reflection
  (:func:`boundary_reflector`: diagonal ``F``, 1 under total internal reflection, and unit
  transmission that hands the radiance arriving at the boundary on); the BSDF then applies the
  Fresnel transmission and the change of solid angle (:mod:`layersim.solved.boundary`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from ..kernels.fresnel import fresnel
from ..operators.operator import Grid, IsoOperator


def smooth_conductor_operator(grid: Grid, m: int, eta: complex, eta_above: float,
                              reflectance: np.ndarray | None = None,
                              film: tuple | None = None) -> IsoOperator:
    """Opaque operator of a smooth conductor of relative index ``eta`` (complex: ``eta.real +
    i eta.imag``): ``Rt = diag(F(mu))`` in each of the ``m`` orders, all of it a delta.
    ``reflectance`` (h,) replaces ``F``: a near-specular conductor's rough reflected energy
    (:meth:`layersim.solved.lobe.NearSpecularLobe.reflectance`); ``film`` (relative index, phase
    scale) makes ``F`` the Airy reflectance of a filmed conductor
    (:func:`layersim.kernels.fresnel.fresnel`)."""
    F = (fresnel(grid.mu, eta.real, eta.imag, film) if reflectance is None
         else np.asarray(reflectance, float))
    diag = sps.diags(F, format="csr")
    return IsoOperator(grid, {"Rt": [diag] * m}, eta_above, None, delta={"Rt": F})


def boundary_reflector(grid: Grid, m: int, side: str, eta_rel: float,
                       eta_inside: float, reflectance: np.ndarray | None = None) -> IsoOperator:
    """The internal reflection of a smooth dielectric boundary, seen from inside the stack.

    Parameters
    ----------
    grid : Grid
        The stack's (Snell-matched) grid.
    m : int
        Fourier orders.
    side : {"top", "bottom"}
        Which boundary of the stack.
    eta_rel : float
        Index inside relative to outside (> 1).
    eta_inside : float
        Absolute index of the medium inside the boundary.
    reflectance : ndarray (h,), optional
        Internal reflectance per node in place of Fresnel's: a near-specular boundary's rough
        one (:meth:`layersim.solved.lobe.NearSpecularLobe.internal_reflectance`).

    Returns
    -------
    IsoOperator
        For ``side="top"``: ``Rb = diag(F_in)`` (light inside the stack going up is reflected
        down with the Fresnel reflectance from the dense side, 1 beyond the critical angle),
        ``Ttb = Tbt = I`` (radiance arriving at the boundary is handed on: the BSDF applies the
        transmission) and ``Rt = 0``; mirrored for ``"bottom"``. All of it is a delta.
    """
    F = fresnel(-grid.mu, eta_rel) if reflectance is None else np.asarray(reflectance, float)
    h = grid.h
    diag, eye, zero = sps.diags(F, format="csr"), sps.identity(h, format="csr"), \
        sps.csr_matrix((h, h))
    ones = np.ones(h)
    inner = "Rb" if side == "top" else "Rt"
    outer = "Rt" if side == "top" else "Rb"
    blocks = {inner: [diag] * m, outer: [zero] * m, "Ttb": [eye] * m, "Tbt": [eye] * m}
    return IsoOperator(grid, blocks, eta_inside, eta_inside,
                       delta={inner: F, "Ttb": ones, "Tbt": ones})
