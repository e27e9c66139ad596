"""A resumable Monte Carlo run of many walks: which path ranges are done, when to stop.

A campaign hands the path ranges of its walks (:mod:`.work`) to an *executor*, adds the tallies
that come back and checkpoints them into a result file (:mod:`.resultfile`), from which a
restarted run continues. The executor is anything with a method

    ``map(ranges) -> iterator of (PathRange, TallySum)``

that takes an iterable of :class:`~layersim.montecarlo.work.PathRange` (consumed lazily: a walk
that stops early yields no more ranges) and yields each range with its tally in *completion*
order, which may differ from the order of ``ranges`` (several GPUs, a cluster). It may have a
``device`` attribute (a string naming where it runs) that the result file records. The executors
of :mod:`.executors` (this process, several devices, a Dask cluster) are such objects; the default,
:class:`~layersim.montecarlo.executors.InProcess`, runs the ranges one after another here.

Each walk's paths ``[0, paths)`` are cut into ranges of ``batch`` paths, in order. The tallies of
the ranges completed so far are kept as the sum over the *in-order prefix* (ranges ``0 .. k-1``
all done) plus the ranges completed beyond it, each held separately. With a target standard
error the stopping rule is that of :func:`~layersim.montecarlo.simulate`: the walk stops after
the first prefix of ``k`` ranges whose R, T and A standard errors are all at most the target, and
the ranges completed beyond it are dropped. The decision is evaluated at every prefix length in
order, so it does not depend on the completion order: a distributed run stops at the same range
with the same integers as a single process. Tallies are exact integers, so the final ones are
bit-identical however the run was split, interrupted and resumed (on the same backend).
"""

from __future__ import annotations

import time
from collections import defaultdict, deque
from dataclasses import dataclass, field

import numpy as np

from ..scene import Scene
from . import resultfile
from .estimates import TallySum
from .executors import InProcess
from .work import PathRange, Walk, split

__all__ = ["InProcess", "Campaign", "Stopped", "walks_of", "max_stderr", "run_walks"]


class Stopped(KeyboardInterrupt):
    """A run interrupted (Ctrl-C) after its progress was checkpointed; ``paths`` were counted."""

    def __init__(self, paths: int):
        super().__init__(paths)
        self.paths = paths


def max_stderr(t: TallySum) -> float:
    """The largest standard error of R, T and A of a walk's tally (inf before 2 paths)."""
    if t.particles < 2:
        return float("inf")
    return max(t.side(0)[1], t.side(1)[1], t.absorbed()[1])


def walks_of(scene: Scene, wis, mu_edges, phi_edges, seed: int, max_steps: int,
             backend: str) -> list[Walk]:
    """The walks of ``scene`` lit from each of ``wis`` (validated unit vectors, shape (k, 3)):
    direction by direction, channel by channel (the same seed for every channel, as
    :func:`~layersim.montecarlo.simulate`)."""
    return [Walk(scene.channel(c), tuple(float(x) for x in wi), tuple(map(float, mu_edges)),
                 tuple(map(float, phi_edges)), seed, max_steps, backend)
            for wi in wis for c in range(scene.channels)]


@dataclass
class WalkProgress:
    """What is done of one walk: ``prefix`` sums its ranges ``[0, prefix.particles)``;
    ``pending`` maps the first path of each range completed beyond the prefix to its tally;
    ``target_met`` says the walk stopped at its target standard error."""

    prefix: TallySum
    pending: dict = field(default_factory=dict)
    target_met: bool = False

    def total(self) -> TallySum:
        """The tally of every counted range (prefix and pending)."""
        out = self.prefix
        for first in sorted(self.pending):
            out = out + self.pending[first]
        return out


def _check_shared(walks: list) -> None:
    """A campaign's walks share what its result file stores once."""
    if not walks:
        raise ValueError("a campaign needs at least one walk")
    shared = lambda w: (w.mu_edges, w.phi_edges, w.seed, w.max_steps, w.backend)
    if any(shared(w) != shared(walks[0]) for w in walks):
        raise ValueError("the walks of a campaign must share bin edges, seed, step cap and "
                         "backend")


def _scene_name(campaign, i: int) -> str:
    """The name of walk ``i``'s scene (without the channel tag of ``Scene.channel``)."""
    c = int(campaign.walk_channel[i])
    return campaign.walks[i].scene.name.removesuffix(f"[{'RGB'[c]}]" if c < 3 else "")


class Campaign:
    """The walks of a run, their progress and the run's options.

    Parameters
    ----------
    walks : list of Walk
        All with the same bin edges.
    paths : int
        Paths per walk (the cap when ``target_stderr`` is given).
    batch : int
        Paths per range.
    target_stderr : float, optional
        Stop each walk at the first prefix of ranges whose R, T and A standard errors are all
        at most this value.
    scene_texts, scene_names : sequence of str
        The TOML text and name of each scene (what the result file records).
    walk_scene, walk_channel : sequence of int, optional
        The scene (index into ``scene_texts``) and channel of each walk (default 0 and 0).
    """

    def __init__(self, walks: list, paths: int, batch: int, target_stderr: float | None = None,
                 scene_texts=("",), walk_scene=None, walk_channel=None, scene_names=None):
        self.walks, self.paths, self.batch, self.target = list(walks), paths, batch, target_stderr
        _check_shared(self.walks)
        self.scene_texts = tuple(scene_texts)
        zeros = [0] * len(self.walks)
        self.walk_scene = np.asarray(zeros if walk_scene is None else walk_scene, np.int64)
        self.walk_channel = np.asarray(zeros if walk_channel is None else walk_channel, np.int64)
        if len(self.walk_scene) != len(self.walks) or len(self.walk_channel) != len(self.walks):
            raise ValueError("walk_scene and walk_channel need one entry per walk")
        if np.any(self.walk_scene < 0) or np.any(self.walk_scene >= len(self.scene_texts)):
            raise ValueError(f"walk_scene must index the {len(self.scene_texts)} scene text(s)")
        self.scene_names = tuple(scene_names) if scene_names is not None else tuple(
            _scene_name(self, int(np.argmax(self.walk_scene == s)))
            for s in range(len(self.scene_texts)))
        self.progress = [WalkProgress(TallySum(w.n_bins)) for w in self.walks]
        self.seconds = 0.0
        self.device = ""
        self._index = defaultdict(list)           # walk key -> indices (equal walks share one)
        for i, w in enumerate(self.walks):
            self._index[w.key()].append(i)
        self._issued = defaultdict(deque)          # (walk key, first) -> indices awaiting it

    def adopt(self, saved: dict) -> None:
        """Continue from ``saved`` progress (:func:`.resultfile.saved_progress`)."""
        self.progress = [WalkProgress(prefix, dict(pending), met)
                         for prefix, pending, met in saved["walks"]]
        self.seconds, self.device = saved["seconds"], saved["device"]

    def finished(self, i: int) -> bool:
        """Whether walk ``i`` takes no more paths (its cap or its target reached)."""
        p = self.progress[i]
        return p.target_met or p.prefix.particles >= self.paths

    @property
    def complete(self) -> bool:
        return all(self.finished(i) for i in range(len(self.walks)))

    def counted(self) -> int:
        """Paths counted over all walks."""
        return sum(p.prefix.particles + sum(t.particles for t in p.pending.values())
                   for p in self.progress)

    def ranges(self):
        """The ranges still to run, walk by walk and in order, skipping those done (lazy: a walk
        that finishes while they are handed out yields no more)."""
        for i, walk in enumerate(self.walks):
            for r in split(walk, self.progress[i].prefix.particles, self.paths, self.batch):
                if self.finished(i):
                    break
                if r.first not in self.progress[i].pending:
                    self._issued[(walk.key(), r.first)].append(i)
                    yield r

    def record(self, r: PathRange, tally: TallySum) -> int:
        """Count the tally of range ``r``; returns the index of its walk."""
        queue = self._issued.get((r.walk.key(), r.first))
        i = queue.popleft() if queue else self._walk_index(r)
        p = self.progress[i]
        if self.finished(i) or r.first < p.prefix.particles or r.first in p.pending:
            return i                               # beyond the stopping point, or done twice
        p.pending[r.first] = tally
        while not self.finished(i) and p.prefix.particles in p.pending:
            p.prefix = p.prefix + p.pending.pop(p.prefix.particles)
            if self.target is not None and max_stderr(p.prefix) <= self.target:
                p.target_met = True
        if self.finished(i):
            p.pending.clear()                      # ranges beyond the stop are not counted
        return i

    def _walk_index(self, r: PathRange) -> int:
        found = self._index.get(r.walk.key())
        if not found:
            raise ValueError(f"the executor returned a range of a walk of no campaign "
                             f"(paths {r.first} to {r.first + r.count})")
        return next((i for i in found if not self.finished(i)), found[0])

    def run(self, executor=None, *, checkpoint=None, every: float = 5.0,
            progress: bool = False) -> "Campaign":
        """Run the remaining ranges on ``executor`` (default :class:`InProcess`), calling
        ``checkpoint(self)`` every ``every`` seconds and when the run ends, however it ends. A
        Ctrl-C raises :class:`Stopped` once the progress is checkpointed."""
        executor = executor or InProcess()
        bar = _bar(self, progress)
        t0 = last = time.monotonic()
        results = executor.map(self.ranges())
        try:
            for r, tally in results:
                self.record(r, tally)
                _advance(bar, self)
                if checkpoint is not None and time.monotonic() - last >= every:
                    self.device = str(getattr(executor, "device", None) or self.device)
                    checkpoint(self)
                    last = time.monotonic()
                if self.complete:
                    break
        except KeyboardInterrupt:
            raise Stopped(self.counted()) from None
        finally:
            getattr(results, "close", lambda: None)()
            self.device = str(getattr(executor, "device", None) or self.device)
            self.seconds += time.monotonic() - t0
            bar.close()
            if checkpoint is not None:
                checkpoint(self)
        return self


def _bar_total(campaign: Campaign) -> int:
    """Paths the run will count: the cap of each walk still running, the count of the others."""
    return sum(campaign.paths if not campaign.finished(i) else p.prefix.particles
               for i, p in enumerate(campaign.progress))


def _bar(campaign: Campaign, enabled: bool):
    from tqdm.auto import tqdm
    return tqdm(total=_bar_total(campaign), initial=campaign.counted(), unit="paths",
                unit_scale=True, desc="walks", disable=None if enabled else True, leave=False,
                smoothing=0.1)


def _advance(bar, campaign: Campaign) -> None:
    """Progress after a range: paths counted (ranges dropped beyond a stop leave the count),
    and the largest standard error of the walks still running (of all walks without a
    target)."""
    if bar.disable:
        return
    bar.total = _bar_total(campaign)
    errs = [max_stderr(q.total()) for k, q in enumerate(campaign.progress)
            if not campaign.finished(k) or campaign.target is None]
    errs = [e for e in errs if np.isfinite(e)]
    bar.set_postfix_str(f"largest stderr {max(errs):.2e}" if errs else "", refresh=False)
    bar.update(campaign.counted() - bar.n)


def run_walks(walks: list, paths: int, *, batch: int, target_stderr: float | None = None,
              executor=None, out=None, scene_texts=("",), scene_names=None, walk_scene=None,
              walk_channel=None, restart: bool = False, progress: bool = False, every: float = 5.0) -> Campaign:
    """Run ``walks`` to ``paths`` each (or to ``target_stderr``), resuming from ``out``.

    Parameters
    ----------
    walks : list of Walk
        E.g. :func:`walks_of` for each scene, concatenated; all with the same bin edges, seed,
        step cap and backend.
    paths, batch, target_stderr
        As :class:`Campaign`.
    executor : object with ``map(ranges)``, optional
        Default :class:`InProcess`.
    out : path, optional
        The result file (:mod:`.resultfile`): checkpointed every ``every`` seconds and at the
        end. If it exists and holds the same run (scenes, walks, bins, seed, backend, paths,
        batch, target), the run continues from it; a different run is refused (ValueError
        naming what differs) unless ``restart``.
    scene_texts, scene_names : sequence of str
        The TOML text and name of each scene; ``walk_scene[i]`` and ``walk_channel[i]`` say which scene
        and channel walk ``i`` is (default: scene 0, channel 0 for every walk).
    progress : bool
        A tqdm bar (on a terminal): paths, paths/s and the largest standard error.

    Returns
    -------
    Campaign
        Its ``progress[i].total()`` is walk ``i``'s exact tally.

    Raises
    ------
    Stopped
        On Ctrl-C, after the checkpoint.
    """
    campaign = Campaign(walks, paths, batch, target_stderr, scene_texts, walk_scene,
                        walk_channel, scene_names)
    checkpoint = None
    if out is not None:
        saved = None if restart else resultfile.saved_progress(out, campaign)
        if saved is not None:
            campaign.adopt(saved)
        checkpoint = lambda c: resultfile.save(out, c)
    return campaign.run(executor, checkpoint=checkpoint, every=every, progress=progress)
