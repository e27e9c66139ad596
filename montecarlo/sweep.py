"""Sweep files: many scenes x incidence angles x channels as one Monte Carlo campaign.

A sweep file is a TOML file with one ``[sweep]`` table (``docs/conventions.md``, "Sweep files")::

    [sweep]
    scenes = ["coated_gold.toml", "car_paint.toml"]   # scene files, relative to this file
    angles = [[0, 0], [30, 0], [60, 90]]               # incidence (theta, phi) in degrees
    channels = "all"                                    # or a list of channel indices, [0, 2]
    paths = 1e9                                         # per walk (the most, with stderr)
    stderr = 1e-4                                       # optional: stop a walk at this stderr
    bins = [10, 12]                                     # uniform bins in |cos theta_o|, phi_o
    seed = 0
    backend = "auto"
    max_steps = 100000

Each scene x angle x channel is one :class:`~layersim.montecarlo.work.Walk` (scene order, then
angle, then channel). ``theta`` > 90 lights the stack from below (not for an opaque stack);
``theta`` = 90 never enters. :func:`read_sweep` checks every field before any walk runs, with
one-line errors naming the file and the field (:class:`~layersim.errors.SweepError`).
"""

from __future__ import annotations

import math
import numbers
import tomllib
from pathlib import Path

import numpy as np

from ..errors import SweepError
from ..scene import Scene
from .backends import BACKENDS, resolve_backend
from .checks import check_wi
from .work import Walk

__all__ = ["read_sweep", "is_sweep_file", "direction", "FIELDS", "MAX_PATHS", "MAX_BINS"]

#: Fields of ``[sweep]`` and whether each must be given.
FIELDS = {"scenes": True, "angles": True, "channels": False, "paths": False, "stderr": False,
          "bins": False, "seed": False, "backend": False, "max_steps": False}
#: Paths of one walk at most (also the cap of a walk run to a stderr target without ``paths``):
#: 2^40 ~ 1.1e12 keeps every tally well inside the 96-bit words of a result file.
MAX_PATHS = 1 << 40
#: Bins along each axis at most.
MAX_BINS = 4096


def direction(theta_deg: float, phi_deg: float) -> tuple:
    """Unit vector toward the light (local frame) of incidence ``(theta, phi)`` in degrees."""
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return (math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t))


def is_sweep_file(path) -> bool:
    """Whether ``path`` is a TOML file with a ``[sweep]`` table (False for anything unreadable:
    the scene reader then says what is wrong with it)."""
    try:
        return "sweep" in tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False


def read_sweep(path, resolve=resolve_backend) -> tuple[list[Walk], dict, dict]:
    """Read and check a sweep file.

    Parameters
    ----------
    path : str or os.PathLike
        The sweep file.
    resolve : callable
        Turns the ``backend`` field into the backend the walks name (default
        :func:`~layersim.montecarlo.backends.resolve_backend`, which resolves ``"auto"`` here;
        ``layersim mc --cluster`` resolves it on the workers instead).

    Returns
    -------
    walks : list of Walk
        One per scene x angle x channel, in that order.
    scene_texts : dict
        ``{scene path as written in the file: the scene file's text}`` (for a result file's
        record of what ran).
    options : dict
        ``paths`` (int), ``stderr`` (float or None), ``bins`` ((n_mu, n_phi)), ``seed``,
        ``backend`` (resolved), ``max_steps``, ``angles`` (list of (theta, phi) degrees),
        ``channels`` ("all" or list), ``source`` (str), and per walk ``walk_scene`` (index
        into the scenes, in file order) and ``walk_channel``; ``scene_names``.

    Raises
    ------
    SweepError
        The file cannot be read, is not TOML, or a field is wrong (named).
    SceneError
        A scene file is invalid (the message names it).
    """
    path = Path(path)
    source = str(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SweepError(f"cannot read the sweep file: {exc.strerror or exc}", source=source)
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise SweepError(f"not a TOML sweep file: {exc}", source=source) from None
    table = _table(data, source)
    options = _options(table, source)
    options["backend"] = resolve(options["backend"])
    scenes, texts = _scenes(table["scenes"], path.parent, source)
    walks, options["walk_scene"], options["walk_channel"] = _walks(scenes, options, source)
    options["scene_names"] = [s.name for s in scenes]
    return walks, texts, options


def _table(data: dict, source: str) -> dict:
    """The ``[sweep]`` table, with no unknown or missing fields."""
    if set(data) != {"sweep"} or not isinstance(data["sweep"], dict):
        other = sorted(set(data) - {"sweep"})
        raise SweepError("a sweep file holds one [sweep] table" +
                         (f" and nothing else (found '{other[0]}')" if other else ""),
                         source=source)
    table = data["sweep"]
    unknown = sorted(set(table) - set(FIELDS))
    if unknown:
        raise SweepError(f"unknown field (allowed: {', '.join(FIELDS)})", unknown[0], source)
    for name, required in FIELDS.items():
        if required and name not in table:
            raise SweepError("missing", name, source)
    if "paths" not in table and "stderr" not in table:
        raise SweepError("give paths (per walk), a stderr target, or both", "paths", source)
    return table


def _options(t: dict, source: str) -> dict:
    """Every field but the scenes, checked."""
    stderr = t.get("stderr")
    if stderr is not None and not (_real(stderr) and 0 < stderr < 1):
        raise SweepError(f"must be a number in (0, 1), got {stderr!r}", "stderr", source)
    backend = t.get("backend", "auto")
    if backend not in BACKENDS:
        raise SweepError(f"must be one of {', '.join(BACKENDS)}, got {backend!r}", "backend",
                         source)
    bins = t.get("bins", [1, 1])
    if not (isinstance(bins, list) and len(bins) == 2):
        raise SweepError(f"must be [n_mu, n_phi], got {bins!r}", "bins", source)
    return dict(
        paths=_count(t.get("paths", MAX_PATHS), "paths", 1, MAX_PATHS, source),
        stderr=None if stderr is None else float(stderr),
        bins=tuple(_count(b, f"bins[{k}]", 1, MAX_BINS, source) for k, b in enumerate(bins)),
        seed=_count(t.get("seed", 0), "seed", 0, (1 << 64) - 1, source),
        max_steps=_count(t.get("max_steps", 100_000), "max_steps", 1, (1 << 31) - 1, source),
        angles=_angles(t["angles"], source), channels=_channels(t.get("channels", "all"), source),
        backend=backend, source=source)


def _real(v) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v)


def _count(v, name: str, lo: int, hi: int, source: str) -> int:
    """An integer field (``1e9`` as written in TOML is a float and is accepted if integral)."""
    if not _real(v) or float(v) != int(v):
        raise SweepError(f"must be an integer, got {v!r}", name, source)
    if not lo <= int(v) <= hi:
        raise SweepError(f"must be in [{lo}, {hi}], got {int(v)}", name, source)
    return int(v)


def _angles(angles, source: str) -> list:
    if not isinstance(angles, list) or not angles:
        raise SweepError("must be a non-empty list of [theta, phi] pairs (degrees)", "angles",
                         source)
    out = []
    for k, a in enumerate(angles):
        if not (isinstance(a, list) and len(a) == 2 and all(_real(x) for x in a)):
            raise SweepError(f"must be [theta, phi] in degrees, got {a!r}", f"angles[{k}]",
                             source)
        theta, phi = float(a[0]), float(a[1])
        if not 0 <= theta <= 180 or theta == 90:
            raise SweepError(f"theta must be in [0, 180] degrees and not 90 (grazing light never "
                             f"enters), got {theta:g}", f"angles[{k}]", source)
        out.append((theta, phi))
    return out


def _channels(channels, source: str):
    if channels == "all":
        return "all"
    if not (isinstance(channels, list) and channels and all(
            isinstance(c, int) and not isinstance(c, bool) and 0 <= c for c in channels)
            and len(set(channels)) == len(channels)):
        raise SweepError(f"must be \"all\" or a list of distinct channel indices (0 = R), got "
                         f"{channels!r}", "channels", source)
    return list(channels)


def _scenes(names, folder: Path, source: str) -> tuple[list, dict]:
    """The scenes (validated) and their texts, read relative to the sweep file's folder."""
    if not (isinstance(names, list) and names and all(isinstance(n, str) for n in names)):
        raise SweepError("must be a non-empty list of scene file paths", "scenes", source)
    if len(set(names)) != len(names):
        raise SweepError("lists a scene file twice", "scenes", source)
    scenes, texts = [], {}
    for k, name in enumerate(names):
        file = folder / name
        if not file.is_file():
            raise SweepError(f"no scene file {str(file)!r}", f"scenes[{k}]", source)
        scenes.append(Scene.from_toml(file))
        texts[name] = file.read_text(encoding="utf-8")
    return scenes, texts


def _walks(scenes: list, o: dict, source: str) -> tuple[list[Walk], list, list]:
    """One walk per scene x angle x channel, with each walk's scene index and channel. The bin
    edges are those of ``layersim mc --bins`` (``numpy.linspace``), so that a sweep's walk and
    the same walk run alone are the same walk."""
    n_mu, n_phi = o["bins"]
    mu_edges = tuple(map(float, np.linspace(0.0, 1.0, n_mu + 1)))
    phi_edges = tuple(map(float, np.linspace(0.0, 2 * math.pi, n_phi + 1)))
    walks, walk_scene, walk_channel = [], [], []
    for s, scene in enumerate(scenes):
        channels = range(scene.channels) if o["channels"] == "all" else o["channels"]
        if max(channels) >= scene.channels:
            raise SweepError(f"channel {max(channels)} does not exist in scene '{scene.name}' "
                             f"({scene.channels} channel(s))", "channels", source)
        for k, (theta, phi) in enumerate(o["angles"]):
            if theta > 90 and scene.opaque:
                raise SweepError(f"theta {theta:g} > 90 lights the stack from below, but scene "
                                 f"'{scene.name}' is opaque", f"angles[{k}]", source)
            # normalised as layersim mc --wi does, so a sweep's walk is the same walk run alone
            wi = tuple(float(x) for x in check_wi(direction(theta, phi), scene))
            for c in channels:
                walks.append(Walk(scene.channel(c), wi, mu_edges, phi_edges, o["seed"],
                                  o["max_steps"], o["backend"]))
                walk_scene.append(s)
                walk_channel.append(c)
    return walks, walk_scene, walk_channel
