"""Single-view reflectance measurements: the input of ``layersim fit-ndf``.

One view direction, many light directions, the specular BRDF per channel (Wang et al. 2008
sec. 4: a fixed camera and a moving light). The layout is written in ``docs/conventions.md``
("Single-view measurements"):

- ``.npz``: ``view`` (3,) toward the viewer; ``lights`` (N, 3) toward the lights; ``values`` (N,)
  or (N, C) in 1/sr; optional ``channels`` (C,) names.
- ``.csv``: a header ``light_x,light_y,light_z,view_x,view_y,view_z,NAME...`` (one column per
  channel), one row per light, the same view in every row; lines starting with ``#`` are comments.

Directions are in the local frame (z the normal) and normalised on reading; ``values`` are the
specular part of the BRDF (the diffuse part removed, as in Wang et al. 2008 sec. 3), without the
cosine factor.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FileFormatError

_DIRS = ["light_x", "light_y", "light_z", "view_x", "view_y", "view_z"]


@dataclass(frozen=True)
class Measurements:
    """Single-view BRDF samples.

    Attributes
    ----------
    view : array (3,), unit vector toward the viewer, view.z > 0
    lights : array (N, 3), unit vectors toward the lights
    values : array (N, C), specular BRDF in 1/sr per channel
    channels : tuple of C names
    source : where the data came from (for messages)
    """

    view: np.ndarray
    lights: np.ndarray
    values: np.ndarray
    channels: tuple = ("value",)
    source: str = "<memory>"

    @classmethod
    def from_arrays(cls, view, lights, values, channels=None, source="<memory>"):
        """Validate and normalise; errors name ``source`` and the field."""
        def bad(field, msg):
            return FileFormatError(f"{source}: field '{field}': {msg}")
        view = np.asarray(view, float).reshape(-1)
        lights = np.asarray(lights, float)
        values = np.asarray(values, float)
        if view.shape != (3,) or not np.all(np.isfinite(view)) or view[2] <= 0:
            raise bad("view", "must be 3 finite numbers with z > 0 (above the surface)")
        if lights.ndim != 2 or lights.shape[1] != 3 or not np.all(np.isfinite(lights)):
            raise bad("lights", f"must be finite numbers of shape (N, 3), got {lights.shape}")
        values = values[:, None] if values.ndim == 1 else values
        if values.ndim != 2 or values.shape[0] != len(lights):
            raise bad("values", f"shape {values.shape} does not match {len(lights)} lights")
        if not np.all(np.isfinite(values)):
            raise bad("values", "holds NaN or infinite numbers")
        if len(lights) < 16:
            raise bad("lights", f"{len(lights)} light directions; fitting needs at least 16")
        norms = np.linalg.norm(lights, axis=1)
        if np.any(norms == 0):
            raise bad("lights", "holds a zero vector")
        names = tuple(str(c) for c in channels) if channels is not None else tuple(
            f"c{k}" for k in range(values.shape[1])) if values.shape[1] > 1 else ("value",)
        if len(names) != values.shape[1]:
            raise bad("channels", f"{len(names)} names for {values.shape[1]} value columns")
        return cls(view / np.linalg.norm(view), lights / norms[:, None], values, names,
                   str(source))

    @classmethod
    def load(cls, path) -> "Measurements":
        """Read a ``.npz`` or ``.csv`` file in the layout of the module docstring."""
        path = Path(path)
        if path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as z:
                missing = [k for k in ("view", "lights", "values") if k not in z.files]
                if missing:
                    raise FileFormatError(f"{path}: missing array(s) {', '.join(missing)} "
                                          "(a measurement file holds view, lights, values)")
                ch = z["channels"] if "channels" in z.files else None
                return cls.from_arrays(z["view"], z["lights"], z["values"], ch, path)
        if path.suffix.lower() == ".csv":
            return cls._load_csv(path)
        raise FileFormatError(f"{path}: measurements are read from .npz or .csv files")

    @classmethod
    def _load_csv(cls, path):
        lines = [ln for ln in path.read_text().splitlines() if ln.strip() and ln[0] != "#"]
        head = [c.strip() for c in lines[0].split(",")] if lines else []
        if head[:6] != _DIRS or len(head) < 7:
            raise FileFormatError(f"{path}: the header must start with {','.join(_DIRS)} and "
                                  "name at least one channel column")
        try:
            rows = np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]])
        except ValueError as exc:
            raise FileFormatError(f"{path}: a row is not a list of numbers ({exc})") from None
        if rows.ndim != 2 or rows.shape[1] != len(head):
            raise FileFormatError(f"{path}: every row needs {len(head)} numbers")
        views = rows[:, 3:6]
        if np.ptp(views, axis=0).max() > 1e-9:
            raise FileFormatError(f"{path}: field 'view_x/y/z': differs between rows; a file "
                                  "holds one view (fit each view separately, then use "
                                  "--complete)")
        return cls.from_arrays(views[0], rows[:, :3], rows[:, 6:], head[6:], path)

    def save(self, path) -> None:
        """Write the ``.npz`` layout (``.csv`` if the name ends so)."""
        path = Path(path)
        if path.suffix.lower() == ".csv":
            head = ",".join(_DIRS + list(self.channels))
            rows = np.hstack([self.lights, np.broadcast_to(self.view, self.lights.shape),
                              self.values])
            np.savetxt(path, rows, delimiter=",", header=head, comments="", fmt="%.10g")
        else:
            np.savez(path, view=self.view, lights=self.lights, values=self.values,
                     channels=np.array(self.channels))
