"""Tabulated BSDF files as fit targets: the two ``.bsdf`` formats layersim reads and MERL
binaries, each as a :class:`TableTarget` that evaluates the file and says where it has data.

- **Fourier ``.bsdf``** (``SCATFUN``: layerlab, Mitsuba 0.6, pbrt-v3, the Layer Laboratory;
  :mod:`layersim.bsdffile`): a table on the nodes of a quadrature rule layersim knows
  (layersim's and layerlab's files) becomes the solved BSDF it holds
  (:meth:`~layersim.bsdffile.FourierTable.to_bsdf`, exact up to the file's float32 storage);
  any other table is evaluated as the renderers evaluate it
  (:meth:`~layersim.bsdffile.FourierTable.eval`, Catmull-Rom on the file's nodes). Every
  reflected pair above the surface has data.
- **RGL tensor ``.bsdf``** (``tensor_file``: Mitsuba 3's and pbrt-v4's ``measured``, the RGL
  database; :mod:`layersim.bsdffile.rgl`): evaluated as the renderers reconstruct it
  (:meth:`~layersim.bsdffile.rgl.RGLTable.eval`). The file holds the top-side reflection for
  incident elevations up to its last ``theta_i`` slice, above which renderers clamp: pairs with
  either direction beyond it are left out. Channels: the ``rgb`` flavour gives three; a
  spectrum equal at every wavelength (layersim's one-channel export) gives one; other spectra
  are evaluated at the template's ``[stack] wavelengths`` (linear in wavelength, as the
  renderers interpolate), which a fit to them needs.
- **MERL binary** (``.binary``; Matusik et al. 2003; :mod:`layersim.layers.merl`): isotropic,
  three channels (RGB). Pairs whose interpolation touches an unmeasured sample (stored
  negative) are left out, and so are pairs with either elevation above :data:`MERL_THETA_MAX`
  (80 degrees), where the gantry measures few, noisy samples and the sample grid is clamped;
  Ngan et al. 2005 ("Experimental analysis of BRDF models", EGSR) leave them out of their fits
  for the same reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..bsdffile.rawfile import read_bytes
from ..errors import FileFormatError, InfeasibleError, SceneError

__all__ = ["TableTarget", "MERL_THETA_MAX", "read_table"]

#: Largest elevation (degrees) of either direction of a pair taken from a MERL file.
MERL_THETA_MAX = 80.0


@dataclass(frozen=True)
class TableTarget:
    """A tabulated BSDF file as a fit target.

    Attributes
    ----------
    f : callable
        ``f(wi, wo)`` of unit directions (N, 3) (toward the light and the viewer) -> the BSDF
        (1/sr, no cosine factor), shape (N, channels).
    valid : callable
        ``valid(wi, wo)`` -> bool (N,): the pairs where the file has reliable data.
    channels : int
    source : str
        What the file is, for messages (``"MERL file x.binary (RGB)"``).
    """

    f: Callable
    valid: Callable
    channels: int
    source: str

    def eval(self, wi, wo) -> np.ndarray:
        """The file's BSDF (1/sr) at pairs ``(..., 3)``, shape (N, channels); NaN where it has
        no data (:attr:`valid`), so that plots leave those out."""
        wi = np.asarray(wi, float).reshape(-1, 3)
        wo = np.asarray(wo, float).reshape(-1, 3)
        return np.where(self.valid(wi, wo)[:, None], self.f(wi, wo), np.nan)


def _everywhere(wi, wo) -> np.ndarray:
    return np.ones(len(wi), bool)


def _fourier(path: Path) -> object:
    """A Fourier ``.bsdf`` file: its solved BSDF where layersim can rebuild the operators,
    else a :class:`TableTarget` evaluating the table as renderers do."""
    from ..bsdffile import read
    table = read(path)
    try:
        return table.to_bsdf()
    except (FileFormatError, InfeasibleError):
        channels = table.channels
        return TableTarget(lambda wi, wo: np.asarray(table.eval(wi, wo)).reshape(len(wi), -1),
                           _everywhere, channels,
                           f"Fourier .bsdf file {path} ({channels} channel(s), renderer "
                           "evaluation)")


def _rgl_lambdas(table, path: Path, wavelengths) -> np.ndarray:
    """The channel coordinates at which an RGL table is evaluated (module docstring)."""
    if table.wavelengths is None:
        return np.arange(3.0)
    spectra = np.asarray(table.spectra)
    if np.all(spectra == spectra[:, :, :1]):
        return table.wavelengths[:1].astype(float)
    if wavelengths is None:
        raise FileFormatError(
            f"{path}: an RGL file of {len(table.wavelengths)} wavelengths "
            f"({table.wavelengths[0]:g}-{table.wavelengths[-1]:g} nm); give the template "
            "[stack] wavelengths (nm), one per channel, to fit it at those")
    return np.asarray(wavelengths, float)


def _rgl(path: Path, wavelengths) -> TableTarget:
    from ..bsdffile import rgl_table
    table = rgl_table.read(path)
    lam = _rgl_lambdas(table, path, wavelengths)
    cos_max = np.cos(float(np.max(table.theta_i))) - 1e-9

    def f(wi, wo):
        # the renderers' wi is the camera direction (our wo) and their value holds the cosine
        # of the light direction (our wi)
        return table.eval(wo, wi, lam) / wi[:, 2:3]

    def valid(wi, wo):
        return (wi[:, 2] >= cos_max) & (wo[:, 2] >= cos_max)

    return TableTarget(f, valid, len(lam), f"RGL file {path} ({len(lam)} channel(s))")


def _merl(path: Path) -> TableTarget:
    from ..layers.merl import read_merl
    try:
        table = read_merl(path)
    except SceneError as exc:
        raise FileFormatError(str(exc)) from None
    cos_max = np.cos(np.radians(MERL_THETA_MAX)) - 1e-9

    def valid(wi, wo):
        return ((wi[:, 2] >= cos_max) & (wo[:, 2] >= cos_max)
                & table.measured_at(wi, wo))

    return TableTarget(lambda wi, wo: table.eval(wi, wo).T, valid, 3,
                       f"MERL file {path} (RGB)")


def read_table(path, wavelengths=None) -> object:
    """The tabulated BSDF in the file at ``path`` (module docstring): a solved
    :class:`~layersim.solved.bsdf.BSDF` for a Fourier ``.bsdf`` file on known nodes, else a
    :class:`TableTarget`.

    Parameters
    ----------
    path : str or path
        A ``.bsdf`` file (either format, told apart by its first bytes) or a MERL ``.binary``.
    wavelengths : sequence of float, optional
        The template's channel wavelengths (nm), at which a spectral RGL file is evaluated.

    Raises
    ------
    FileFormatError
        The file cannot be read, is of neither format, or is a spectral RGL file and no
        wavelengths are given; the message names the file.
    """
    path = Path(path)
    if path.suffix.lower() == ".binary":
        return _merl(path)
    head = read_bytes(path, 12)
    if head.startswith(b"SCATFUN"):
        return _fourier(path)
    if head.startswith(b"tensor_file"):
        return _rgl(path, wavelengths)
    raise FileFormatError(f"{path}: neither a Fourier .bsdf file (SCATFUN) nor an RGL "
                          "material (tensor_file)")
