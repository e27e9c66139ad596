"""The unit of Monte Carlo work: a range of paths of one walk, and its exact tally.

A :class:`Walk` is everything that fixes the random walk of one channel of a scene lit from one
direction: the monochromatic scene, the incident direction, the bin edges, the seed, the step cap
and the backend. Particle ``p`` of a walk draws its random numbers from ``(seed, p)`` alone
(:mod:`layersim.kernels.rng`) and the kernels sum fixed-point integers, so the tally of a walk is
the same integers however its paths are split into :class:`PathRange` s and in whatever order, on
whatever number of processes, devices or machines run them, provided they run the same backend
(CUDA and CPU code may round differently). Everything that schedules work (:func:`simulate`,
``layersim mc``, several GPUs, a Dask cluster) hands out path ranges and adds their
:class:`~layersim.montecarlo.estimates.TallySum` s.

A :class:`PathRange` pickles small (the scene record and a few numbers), which is what a Dask
worker receives; :func:`run_range` builds the backend's runner once per walk and device in each
thread and reuses it for the next range of the same walk.
"""

from __future__ import annotations

import hashlib
import pickle
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from ..scene import Scene
from .backends import Launch, make_runner
from .estimates import TallySum
from .stack import flatten

__all__ = ["Walk", "PathRange", "split", "run_range", "runner_device"]


@dataclass(frozen=True)
class Walk:
    """One channel of a scene lit from one direction, binned and seeded.

    Attributes
    ----------
    scene : layersim.Scene
        Monochromatic (one-channel) validated scene, e.g. ``scene.channel(c)``.
    wi : tuple of 3 float
        Unit direction toward the light (local frame), validated by the caller.
    mu_edges, phi_edges : tuple of float
        Bin edges in ``|cos theta_o|`` and ``phi_o`` (radians), validated by the caller.
    seed : int
        0 <= seed < 2^64.
    max_steps : int
        Cap on the interactions of one path.
    backend : str
        A resolved backend name (``"warp-cpu"``, ``"warp-cuda"``, ``"opencl"``).
    """

    scene: Scene
    wi: tuple
    mu_edges: tuple
    phi_edges: tuple
    seed: int
    max_steps: int
    backend: str

    @property
    def n_bins(self) -> int:
        """Bins per side including the total."""
        return (len(self.mu_edges) - 1) * (len(self.phi_edges) - 1) + 1

    def launch(self) -> Launch:
        """The backend's launch record (flattened stack, float32 directions and edges)."""
        return Launch(stack=flatten(self.scene), wi=np.asarray(self.wi, np.float32),
                      mu_edges=np.asarray(self.mu_edges, np.float32),
                      phi_edges=np.asarray(self.phi_edges, np.float32), seed=self.seed,
                      max_steps=self.max_steps)

    def key(self) -> str:
        """A digest that names the walk across processes (its pickled record)."""
        return hashlib.sha256(pickle.dumps(self, protocol=4)).hexdigest()[:32]


@dataclass(frozen=True)
class PathRange:
    """Paths ``first, first + 1, ..., first + count - 1`` of ``walk``."""

    walk: Walk
    first: int
    count: int


def split(walk: Walk, first: int, stop: int, batch: int) -> list[PathRange]:
    """Path ranges of at most ``batch`` paths covering ``[first, stop)``, in order."""
    return [PathRange(walk, a, min(batch, stop - a)) for a in range(first, stop, batch)]


#: Runners kept per thread: building one compiles (or loads) the walk's kernel and allocates
#: its buffers, so the ranges of one walk reuse it; a few walks cover a sweep's interleaving.
_RUNNER_CACHE_SIZE = 4
#: Each thread keeps its own runners: a runner owns mutable device buffers, so two threads (one
#: per device in :class:`~layersim.montecarlo.executors.Devices`, or several threads of a Dask
#: worker) must never share one, and a per-thread cache cannot be thrashed by other devices.
_LOCAL = threading.local()
#: Runners are built one at a time in a process: building compiles and loads the walk's Warp
#: module, which Warp does not guard against concurrent builds; launches then run in parallel.
_BUILD_LOCK = threading.Lock()


def _runner(walk: Walk, device: str | None):
    cache = getattr(_LOCAL, "runners", None)
    if cache is None:
        cache = _LOCAL.runners = OrderedDict()
    key = (walk.key(), device)
    runner = cache.get(key)
    if runner is None:
        with _BUILD_LOCK:
            runner = make_runner(walk.backend, walk.launch(), device=device)
        cache[key] = runner
        while len(cache) > _RUNNER_CACHE_SIZE:
            cache.popitem(last=False)
    else:
        cache.move_to_end(key)
    return runner


def run_range(r: PathRange, device: str | None = None) -> TallySum:
    """Walk the paths of ``r`` and return their exact tally.

    Parameters
    ----------
    r : PathRange
    device : str, optional
        The backend's device: a Warp CUDA device (``"cuda:1"``) for ``"warp-cuda"``, ``"cpu"``
        for ``"warp-cpu"``, ``"opencl:K"`` for ``"opencl"``; None for the backend's default
        device. Each thread keeps its own runners, so threads may run ranges at the same time.

    Returns
    -------
    TallySum
        The range's integer sums (add the tallies of other ranges with ``+``).
    """
    runner = _runner(r.walk, device)
    tally, counters = runner.run(r.first, r.count)
    total = TallySum(r.walk.n_bins)
    total.add(tally, counters, r.count)
    return total


def runner_device(walk: Walk, device: str | None = None) -> str:
    """The name of the device that runs ``walk`` here (builds the runner if needed)."""
    return _runner(walk, device).device_name
