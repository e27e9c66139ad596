"""The Monte Carlo result file: one or more walks, their exact tallies and estimates.

A ``.npz`` archive that numpy alone reads (``np.load(path)``, no pickles), laid out in
``docs/conventions.md`` ("Monte Carlo result files"): a walk table (scene, channel, incident
direction), arrays with a leading walk axis (exact integer tallies as little-endian uint64 words,
float estimates and standard errors), the scenes as TOML text, the run's options, versions, and
which path ranges are done, so that an interrupted run continues from it
(:mod:`.campaign`). Files are written atomically (a temporary file, then ``os.replace``): a
killed process leaves the previous checkpoint.

:func:`load` returns an :class:`MCFile`; :meth:`MCFile.result` gives a walk's
:class:`~layersim.montecarlo.MCResult`.
"""

from __future__ import annotations

import math
import os
import platform
import tempfile
import tomllib
from pathlib import Path

import numpy as np

from .estimates import TallySum
from .result import MCResult
from .stack import flatten

__all__ = ["FORMAT", "VERSION", "save", "load", "saved_progress", "MCFile"]

FORMAT = "layersim-mc"
VERSION = 1


def versions() -> np.ndarray:
    """``(name, version)`` rows of the software that ran the walks, shape (k, 2), str."""
    import warp
    from .. import __version__
    rows = [("layersim", __version__), ("numpy", np.__version__),
            ("warp", str(warp.config.version)), ("python", platform.python_version()),
            ("platform", platform.platform())]
    return np.array(rows, dtype=str)


def _estimates(t: TallySum, incident: int, shape: tuple) -> dict:
    """Fractions, bins and standard errors of one walk (NaN before any path)."""
    if t.particles == 0:
        nan = np.full(shape, np.nan)
        return {**{k: math.nan for k in ("reflectance", "transmittance", "absorbed",
                                         "reflectance_stderr", "transmittance_stderr",
                                         "absorbed_stderr")},
                **{k: nan for k in ("bins_top", "bins_bottom", "bins_top_stderr",
                                    "bins_bottom_stderr")}}
    (r, re), (tr, te), (a, ae) = t.side(incident), t.side(1 - incident), t.absorbed()
    (bt, bte), (bb, bbe) = t.bins(0, shape), t.bins(1, shape)
    return {"reflectance": r, "transmittance": tr, "absorbed": a, "reflectance_stderr": re,
            "transmittance_stderr": te, "absorbed_stderr": ae, "bins_top": bt,
            "bins_bottom": bb, "bins_top_stderr": bte, "bins_bottom_stderr": bbe}


def _angles(wi: np.ndarray) -> tuple:
    """(theta, phi) in degrees of unit directions (k, 3); phi in [0, 360)."""
    theta = np.degrees(np.arccos(np.clip(wi[:, 2], -1.0, 1.0)))
    phi = np.degrees(np.arctan2(wi[:, 1], wi[:, 0])) % 360.0
    return np.round(theta, 10), np.round(phi, 10) % 360.0


def _done_rows(campaign) -> tuple:
    """``done`` rows (walk, first, count), the indices of the pending ones and their tallies."""
    rows, pending, tallies = [], [], []
    for i, p in enumerate(campaign.progress):
        if p.prefix.particles:
            rows.append((i, 0, p.prefix.particles))
        for first in sorted(p.pending):
            pending.append(len(rows))
            rows.append((i, first, p.pending[first].particles))
            tallies.append(p.pending[first])
    return np.array(rows, np.int64).reshape(-1, 3), np.array(pending, np.int64), tallies


def _records(campaign) -> dict:
    """The arrays of the walks (leading walk axis)."""
    walks = campaign.walks
    wi = np.array([w.wi for w in walks], np.float64).reshape(-1, 3)
    shape = (len(walks[0].mu_edges) - 1, len(walks[0].phi_edges) - 1)
    totals = [p.total() for p in campaign.progress]
    words = [t.to_words() for t in totals]
    est = [_estimates(t, 0 if w.wi[2] > 0 else 1, shape) for t, w in zip(totals, walks)]
    theta, phi = _angles(wi)
    out = {"walk_scene": campaign.walk_scene, "walk_channel": campaign.walk_channel, "wi": wi,
           "theta_deg": theta, "phi_deg": phi,
           "left_out": np.array([",".join(flatten(w.scene).features.left_out()) for w in walks],
                                dtype=str),
           "particles": np.array([t.particles for t in totals], np.int64),
           "events": np.array([t.events for t in totals], np.int64),
           "truncated": np.array([t.truncated for t in totals], np.int64),
           "tally_w": np.stack([w for w, _ in words]),
           "tally_counts": np.stack([c for _, c in words]),
           "finished": np.array([campaign.finished(i) for i in range(len(walks))]),
           "target_met": np.array([p.target_met for p in campaign.progress])}
    for key in est[0]:
        out[key] = np.array([e[key] for e in est], np.float64)
    return out


def _arrays(campaign) -> dict:
    """Every key of the file (docs/conventions.md, "Monte Carlo result files")."""
    w0 = campaign.walks[0]
    done, pending, tallies = _done_rows(campaign)
    n_bins = w0.n_bins
    pw = [t.to_words() for t in tallies]
    return {"format": np.array(FORMAT), "format_version": np.array(VERSION, np.int64),
            "scenes": np.array(campaign.scene_texts, dtype=str),
            "scene_names": np.array(campaign.scene_names, dtype=str),
            "mu_edges": np.array(w0.mu_edges, np.float64),
            "phi_edges": np.array(w0.phi_edges, np.float64),
            "seed": np.array(w0.seed, np.uint64), "backend": np.array(w0.backend),
            "device": np.array(campaign.device), "max_steps": np.array(w0.max_steps, np.int64),
            "paths": np.array(campaign.paths, np.int64),
            "batch": np.array(campaign.batch, np.int64),
            "target_stderr": np.array(np.nan if campaign.target is None else campaign.target),
            "versions": versions(), "seconds": np.array(float(campaign.seconds)),
            "complete": np.array(campaign.complete),
            **_records(campaign), "done": done, "pending": pending,
            "pending_w": (np.stack([w for w, _ in pw]) if pw
                          else np.zeros((0, 2, 2, n_bins, TallySum.WORDS), np.uint64)),
            "pending_counts": (np.stack([c for _, c in pw]) if pw
                               else np.zeros((0, 3, TallySum.WORDS), np.uint64))}


def save(path, campaign) -> Path:
    """Write ``campaign`` (:class:`~layersim.montecarlo.campaign.Campaign`) to ``path``
    atomically: a temporary file in the same folder, then ``os.replace``."""
    path = Path(path)
    arrays = _arrays(campaign)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.chmod(fd, 0o666 & ~_umask())        # mkstemp's 0600 is for secrets; this is not
        with os.fdopen(fd, "wb") as fh:
            np.savez(fh, **arrays)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


class MCFile:
    """A result file read back: ``data`` holds every key (numpy arrays); the walk table is
    ``walk_scene``, ``walk_channel``, ``wi``, ``theta_deg``, ``phi_deg``."""

    def __init__(self, data: dict, path: Path):
        self.data, self.path = data, path

    def __getattr__(self, key):
        try:
            return self.__dict__["data"][key]
        except KeyError:
            raise AttributeError(key) from None

    @property
    def n_walks(self) -> int:
        return int(self.data["wi"].shape[0])

    @property
    def shape(self) -> tuple:
        """(n_mu, n_phi) bins per side."""
        return (self.data["mu_edges"].size - 1, self.data["phi_edges"].size - 1)

    def label(self, i: int) -> str:
        """``"NAME[c] theta, phi"`` of walk ``i`` (channel shown for RGB scenes)."""
        s, c = int(self.walk_scene[i]), int(self.walk_channel[i])
        rgb = np.any(self.walk_channel[self.walk_scene == s] > 0)
        tag = f"[{'RGB'[c]}]" if rgb else ""
        return f"{self.scene_names[s]}{tag} at {self.theta_deg[i]:g},{self.phi_deg[i]:g} deg"

    def scene(self, i: int):
        """The (whole) scene of walk ``i``, from its TOML text."""
        from ..scene import Scene
        text = str(self.scenes[int(self.walk_scene[i])])
        return Scene.from_dict(tomllib.loads(text), source=str(self.path),
                               default_name=f"scene {int(self.walk_scene[i])}")

    def tally(self, i: int) -> TallySum:
        """Walk ``i``'s exact tally."""
        return TallySum.from_words(self.tally_w[i], self.tally_counts[i])

    def result(self, i: int) -> MCResult:
        """Walk ``i`` as an :class:`MCResult` (fractions as floats, bins (n_mu, n_phi))."""
        d = self.data
        f = {k: float(d[k][i]) for k in ("reflectance", "transmittance", "absorbed",
                                         "reflectance_stderr", "transmittance_stderr",
                                         "absorbed_stderr")}
        left = str(d["left_out"][i])
        return MCResult(**f, bins={"top": d["bins_top"][i], "bottom": d["bins_bottom"][i]},
                        bins_stderr={"top": d["bins_top_stderr"][i],
                                     "bottom": d["bins_bottom_stderr"][i]},
                        particles=int(d["particles"][i]), events=int(d["events"][i]),
                        truncated=int(d["truncated"][i]), backend=str(d["backend"]),
                        device=str(d["device"]), seconds=float(d["seconds"]),
                        seed=int(d["seed"]), wi=d["wi"][i], mu_edges=d["mu_edges"],
                        phi_edges=d["phi_edges"], left_out=tuple(left.split(",")) if left else ())


def load(path) -> MCFile:
    """Read a result file written by ``layersim mc`` / :func:`save`.

    Raises
    ------
    ValueError
        ``path`` is not such a file (or of a newer format version).
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError) as exc:
        if isinstance(exc, FileNotFoundError):
            raise
        raise ValueError(f"{path}: not a layersim mc result file (a numpy .npz archive "
                         "written by 'layersim mc')") from None
    if str(data.get("format", "")) != FORMAT:
        raise ValueError(f"{path}: not a layersim mc result file (no format = {FORMAT!r})")
    if int(data["format_version"]) > VERSION:
        raise ValueError(f"{path}: result file version {int(data['format_version'])} is newer "
                         f"than this layersim reads ({VERSION}); update layersim")
    return MCFile(data, path)


def _differences(f: MCFile, campaign) -> list:
    """What differs between the run of file ``f`` and ``campaign``, as phrases."""
    w0 = campaign.walks[0]
    wi = np.array([w.wi for w in campaign.walks], np.float64).reshape(-1, 3)
    target = math.nan if campaign.target is None else float(campaign.target)
    show = lambda t: "none" if math.isnan(t) else f"{t:g}"
    checks = [("the scene text differs", list(map(str, f.scenes)) == list(campaign.scene_texts)),
              (f"walks: {f.n_walks} in the file, {len(wi)} now", f.n_walks == len(wi)),
              (f"backend: {f.backend} in the file, {w0.backend} now", str(f.backend) == w0.backend),
              (f"seed: {int(f.seed)} in the file, {w0.seed} now", int(f.seed) == w0.seed),
              (f"paths: {int(f.paths)} in the file, {campaign.paths} now",
               int(f.paths) == campaign.paths),
              (f"batch: {int(f.batch)} in the file, {campaign.batch} now",
               int(f.batch) == campaign.batch),
              (f"stderr target: {show(float(f.target_stderr))} in the file, {show(target)} now",
               show(float(f.target_stderr)) == show(target)),
              (f"max steps: {int(f.max_steps)} in the file, {w0.max_steps} now",
               int(f.max_steps) == w0.max_steps),
              (f"bins: {f.shape[0]}x{f.shape[1]} in the file, {len(w0.mu_edges) - 1}x"
               f"{len(w0.phi_edges) - 1} now", np.array_equal(f.mu_edges, w0.mu_edges)
               and np.array_equal(f.phi_edges, w0.phi_edges))]
    if f.n_walks == len(wi):
        checks += [("the incident directions differ", np.array_equal(f.wi, wi)),
                   ("the walk table (scenes, channels) differs",
                    np.array_equal(f.walk_scene, campaign.walk_scene)
                    and np.array_equal(f.walk_channel, campaign.walk_channel))]
    return [what for what, same in checks if not same]


def _minus(a: TallySum, b: TallySum) -> TallySum:
    """``a - b`` for tallies with ``b`` a part of ``a`` (exact)."""
    out = TallySum(a.w.shape[2])
    out.w = a.w - b.w
    out.particles, out.events = a.particles - b.particles, a.events - b.events
    out.truncated = a.truncated - b.truncated
    return out


def saved_progress(path, campaign) -> dict | None:
    """The progress of the run in ``path``, if the file exists, for ``campaign`` to continue.

    Returns
    -------
    dict or None
        ``walks``: per walk ``(prefix, pending, target_met)`` (see
        :class:`~layersim.montecarlo.campaign.WalkProgress`); ``seconds``: wall time so far;
        ``device``. None if there is no file.

    Raises
    ------
    ValueError
        The file holds a different run (one line naming what differs) or is not a result file.
    """
    path = Path(path)
    if not path.exists():
        return None
    try:
        f = load(path)
    except ValueError as exc:
        raise ValueError(f"{exc}; rerun with --restart to overwrite it, or give another -o") \
            from None
    diff = _differences(f, campaign)
    if diff:
        raise ValueError(f"{path} holds a different run ({'; '.join(diff)}); rerun with "
                         "--restart to overwrite it, or give another -o")
    walks = []
    for i in range(f.n_walks):
        rows = np.flatnonzero(f.done[:, 0] == i)
        pending = {int(f.done[k, 1]): TallySum.from_words(f.pending_w[j], f.pending_counts[j])
                   for j, k in enumerate(f.pending) if f.done[k, 0] == i}
        prefix = f.tally(i)
        for t in pending.values():
            prefix = _minus(prefix, t)
        expected = sum(int(f.done[k, 2]) for k in rows)
        if prefix.particles + sum(t.particles for t in pending.values()) != expected:
            raise ValueError(f"{path}: walk {i}'s done ranges and tally disagree; the file is "
                             "damaged: rerun with --restart")
        walks.append((prefix, pending, bool(f.target_met[i])))
    return {"walks": walks, "seconds": float(f.seconds), "device": str(f.device)}
