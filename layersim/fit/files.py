"""Fit targets on disk: a saved BSDF (``.lsim``), a tabulated BSDF (``.bsdf``: the Fourier
format or the RGL tensor format), a MERL binary (``.binary``) (:mod:`.tables` for these
three), or point measurements (``.npz``, ``.csv``).

Point measurements (``docs/conventions.md``, "Fitting"):

- ``.npz``: arrays ``wi`` (N, 3), ``wo`` (N, 3) and ``f`` (N,) or (N, C), f in 1/sr without the
  cosine factor, and optionally ``sigma`` (the shape of f): the standard deviations of f;
- ``.csv``: comma-separated rows ``wi_x, wi_y, wi_z, wo_x, wo_y, wo_z, f[, f_1, ...]`` (one f
  column per channel); lines starting with ``#`` are comments.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import FileFormatError
from ..solved.bsdf import BSDF
from .tables import read_table

__all__ = ["read_target"]


def _npz(path: Path) -> tuple:
    try:
        with np.load(path, allow_pickle=False) as d:
            missing = [k for k in ("wi", "wo", "f") if k not in d.files]
            if missing:
                raise FileFormatError(f"{path}: point measurements need arrays wi, wo and f; "
                                      f"missing {', '.join(missing)}")
            return (d["wi"], d["wo"], d["f"]) + ((d["sigma"],) if "sigma" in d.files else ())
    except (ValueError, OSError) as exc:
        if isinstance(exc, FileFormatError):
            raise
        raise FileFormatError(f"{path}: not an .npz file of point measurements ({exc})") from None


def _csv(path: Path) -> tuple:
    try:
        a = np.loadtxt(path, delimiter=",", comments="#", ndmin=2)
    except ValueError as exc:
        raise FileFormatError(f"{path}: not a CSV file of numbers ({exc})") from None
    if a.shape[1] < 7:
        raise FileFormatError(f"{path}: point measurements need 7 or more columns (wi_x, wi_y, "
                              f"wi_z, wo_x, wo_y, wo_z, f...), got {a.shape[1]}")
    return a[:, 0:3], a[:, 3:6], a[:, 6:]


def read_target(path, wavelengths=None) -> object:
    """What the fit target file at ``path`` holds: a solved BSDF (``.lsim``, or a Fourier
    ``.bsdf`` on nodes layersim knows), a :class:`~.tables.TableTarget` (other ``.bsdf``
    files, MERL ``.binary``), or the tuple ``(wi, wo, f)`` or ``(wi, wo, f, sigma)`` of point
    measurements. ``wavelengths``: see :func:`.tables.read_table`.

    Raises
    ------
    FileFormatError
        An unknown suffix or a file without the layout of its format; the message names the
        file.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".lsim":
        return BSDF.load(path)
    if suffix in (".bsdf", ".binary"):
        return read_table(path, wavelengths)
    if suffix == ".npz":
        return _npz(path)
    if suffix == ".csv":
        return _csv(path)
    raise FileFormatError(f"{path}: a fit target is a saved BSDF (.lsim), a tabulated BSDF "
                          "(.bsdf), a MERL file (.binary) or point measurements (.npz or "
                          f".csv), got {suffix or 'no suffix'}")
