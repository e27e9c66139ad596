"""Spread path ranges over several devices of this host, one thread per device.

Each thread pulls the next range when its device is free (a faster device takes more ranges), runs
it with :func:`~layersim.montecarlo.work.run_range` on its device and hands the tally back. Every
thread keeps its own runners (buffers and loaded kernel) in a per-thread cache, so threads never
share a runner. Tallies are the same integers as on one device: the random numbers of path ``p``
depend on ``(seed, p)`` alone and tallies are integer sums (:mod:`layersim.montecarlo.work`).

Why threads suffice: Warp calls its compiled kernels through ``ctypes`` function pointers
(``CFUNCTYPE``; CUDA launches and copies through a ``ctypes.CDLL``), and ctypes releases the GIL
for the duration of every such call, so one Python process keeps several devices busy. The OpenCL
runner waits for its kernel in ``time.sleep``, which releases the GIL too. Measured on Warp's CPU
device (``tests/test_mc_executors.py``, shared 2-core VM, load average 4-8): while one thread runs
a 0.6-0.8 s launch, another thread's longest pause between two Python steps is 24-28 ms, against
300 ms during a 300 ms C call that keeps the GIL (``ctypes.PyDLL``). Runners are built one at a
time (:mod:`layersim.montecarlo.work`), each loading its kernel on its device, so that the threads'
first launches find the kernel loaded.
"""

from __future__ import annotations

import queue
import threading
from typing import Iterable, Iterator

from ..backends import check_device, device_names, resolve_backend
from ..estimates import TallySum
from ..work import PathRange, run_range
from .base import Executor, check_backend

__all__ = ["Devices", "parse_devices"]

#: How long the consumer waits on the result queue before looking again: short enough that a
#: KeyboardInterrupt in the consumer is handled at once on any platform.
_POLL_S = 0.1
_FINISHED = object()


def parse_devices(text: str | None) -> list[str] | None:
    """``"all"`` (or None) -> None (every device); ``"cuda:0,cuda:1"`` -> the list of names.

    Raises
    ------
    ValueError
        An empty name in the list.
    """
    if text is None or text.strip() == "all":
        return None
    names = [t.strip() for t in text.split(",")]
    if not all(names):
        raise ValueError(f"devices: expected 'all' or a comma-separated list such as "
                         f"'cuda:0,cuda:1', got {text!r}")
    return names


class Devices(Executor):
    """One thread per device of one host.

    Parameters
    ----------
    backend : {"warp-cuda", "opencl", "warp-cpu", "auto"}
        The backend every walk given to :meth:`map` must use.
    devices : list of str, optional
        Device names (:func:`~layersim.montecarlo.backends.device_names`): ``["cuda:0",
        "cuda:2"]``, ``["opencl:0", "opencl:1"]``; None (or ``"all"``) is every device of the
        backend here. A name may repeat: each occurrence gets its own thread and runners (two
        threads on Warp's one CPU device use two cores).

    Raises
    ------
    ValueError
        An unknown backend, a device of another backend, or no device at all.
    """

    def __init__(self, backend: str = "warp-cuda", devices: list[str] | str | None = None):
        self.backend = resolve_backend(backend)
        if isinstance(devices, str):
            devices = parse_devices(devices)
        present = device_names(self.backend)
        self.devices = list(present if devices is None else devices)
        if not self.devices:
            raise ValueError(f"devices: backend {self.backend!r} has no device here")
        for d in self.devices:
            check_device(self.backend, d)
        unknown = [d for d in self.devices if d not in present]
        if unknown:
            raise ValueError(f"devices: {unknown[0]!r} is not a device here (present: "
                             f"{', '.join(present) or 'none'})")
        self._runs: list[tuple[threading.Event, list[threading.Thread]]] = []

    def describe(self) -> str:
        """One line: ``"warp-cuda on cuda:0, cuda:1"``."""
        return f"{self.backend} on {', '.join(self.devices)}"

    def map(self, ranges: Iterable[PathRange]) -> Iterator[tuple[PathRange, TallySum]]:
        """Yield ``(range, tally)`` as the devices finish them (completion order).

        Leaving the loop early stops the threads after the launches under way (a launch cannot
        be interrupted; one range per device is the most that finishes unused)."""
        source, lock = iter(ranges), threading.Lock()
        # bounded: the devices run at most one range each ahead of a consumer that is busy
        done: queue.Queue = queue.Queue(maxsize=len(self.devices))
        stop = threading.Event()

        def take():
            with lock:
                return None if stop.is_set() else next(source, None)

        threads = [threading.Thread(target=self._serve, args=(device, take, done, stop),
                                    daemon=True,
                                    name=f"layersim-{device}-{k}")
                   for k, device in enumerate(self.devices)]
        run = (stop, threads)
        self._runs.append(run)
        for t in threads:
            t.start()
        try:
            yield from _results(done, len(threads))
        finally:
            _stop(run)
            self._runs.remove(run)

    def _serve(self, device: str, take, done: queue.Queue, stop: threading.Event) -> None:
        """A device's thread: run ranges until there are none (or the run stops)."""
        try:
            while (r := take()) is not None:
                check_backend(r, self.backend)
                _put(done, (r, run_range(r, device)), stop)
        except BaseException as exc:              # handed to the consumer, which re-raises it
            _put(done, exc, stop)
        finally:
            _put(done, _FINISHED, stop)

    def close(self) -> None:
        """Stop every run still going (after its launches under way) and join its threads."""
        for run in list(self._runs):
            _stop(run)


def _results(done: queue.Queue, n_threads: int):
    """Results from the queue until every thread has finished; a thread's error is raised."""
    running = n_threads
    while running:
        try:
            item = done.get(timeout=_POLL_S)
        except queue.Empty:
            continue
        if item is _FINISHED:
            running -= 1
        elif isinstance(item, BaseException):
            raise item
        else:
            yield item


def _put(done: queue.Queue, item, stop: threading.Event) -> None:
    """Hand an item to the consumer; drop it once the run has stopped (nobody reads any more)."""
    while not stop.is_set():
        try:
            done.put(item, timeout=_POLL_S)
            return
        except queue.Full:
            continue


def _stop(run) -> None:
    stop, threads = run
    stop.set()
    for t in threads:
        t.join()
