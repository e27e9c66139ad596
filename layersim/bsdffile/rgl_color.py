"""RGB channels as spectra for the RGL format's ``spectra`` field.

An RGB BSDF value ``c = (r, g, b)`` is written as the spectrum ``S(lambda) = sum_k a_k B_k
(lambda)``, ``a = M^-1 c``, with three fixed smooth basis spectra ``B_k`` (Gaussians of 40 nm
standard deviation at 610, 550 and 460 nm, sampled at :data:`WAVELENGTHS` and linear between
them, as the renderers interpolate ``spectra``) and ``M[j, k]`` the sRGB channel ``j`` of
``B_k`` as Mitsuba 3 converts a reflectance spectrum to sRGB (``spectrum_list_to_srgb(...,
d65=True)``: the CIE 1931 integral of ``S`` times D65, :mod:`layersim.bsdffile.cie`). So the
spectrum's sRGB value is ``c`` exactly, for every direction: a spectral renderer lighting the
material with D65 white returns the channels. Saturated colours give spectra that are
negative at some wavelengths (``a`` has a negative entry): Mitsuba 3 evaluates them as they
are, pbrt-v4 clamps spectra at zero (``MeasuredBxDF::f``), which shifts such colours.
"""

from __future__ import annotations

import numpy as np

from . import cie

#: Wavelength nodes (nm) of spectra converted from RGB: 13 nodes, 360-830 nm (39 nm apart,
#: fine enough for the 40 nm basis and a twelfth of the size of a 5 nm grid).
WAVELENGTHS = np.linspace(360.0, 830.0, 13)
#: Centres (nm) of the red, green and blue basis spectra, and their common width.
CENTRES = (610.0, 550.0, 460.0)
WIDTH = 40.0
#: XYZ to linear sRGB (Rec. 709, D65 white), as Mitsuba 3's ``xyz_to_srgb``.
XYZ_TO_SRGB = np.array([[3.240479, -1.537150, -0.498535],
                        [-0.969256, 1.875991, 0.041556],
                        [0.055648, -0.204043, 1.057311]])


def basis() -> np.ndarray:
    """The basis spectra (3, len(WAVELENGTHS)) at the nodes (red, green, blue)."""
    return np.exp(-0.5 * ((WAVELENGTHS[None, :] - np.array(CENTRES)[:, None]) / WIDTH) ** 2)


def spectrum_to_srgb(values: np.ndarray, nodes: np.ndarray = WAVELENGTHS) -> np.ndarray:
    """Linear sRGB (..., 3) of reflectance spectra ``values`` (..., len(nodes)) under D65,
    as Mitsuba 3's ``spectrum_list_to_srgb(nodes, values, d65=True)`` computes it (1000
    wavelengths from 360 to 830 nm, the spectrum linear between its nodes), without the
    clamp to [0, 1] that Mitsuba applies there."""
    lam = np.linspace(360.0, 830.0, 1000)
    inside = (lam >= nodes[0]) & (lam <= nodes[-1])
    lam = lam[inside]
    xyz = np.stack([np.interp(lam, cie.NODES, t) for t in (cie.XBAR, cie.YBAR, cie.ZBAR)])
    weight = xyz * np.interp(lam, cie.NODES, cie.D65)[None, :] \
        * (470.0 * cie.Y_NORMALIZATION / 1000)
    hat = np.stack([np.interp(lam, nodes, row) for row in np.eye(len(nodes))])  # node hats
    to_xyz = hat @ weight.T                                   # (nodes, 3)
    return np.asarray(values) @ to_xyz @ XYZ_TO_SRGB.T


#: M[j, k]: sRGB channel j of basis spectrum k.
MATRIX = spectrum_to_srgb(basis()).T


def to_spectra(rgb: np.ndarray) -> np.ndarray:
    """Spectra (..., len(WAVELENGTHS)) whose sRGB values are ``rgb`` (..., 3)."""
    return np.asarray(rgb) @ np.linalg.inv(MATRIX).T @ basis()


def to_rgb(spectra: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_spectra` on its range (sRGB of spectra at the nodes)."""
    return spectrum_to_srgb(spectra)
