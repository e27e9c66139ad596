"""Run path ranges one after the other in this process: the default executor."""

from __future__ import annotations

from typing import Iterable, Iterator

from ..estimates import TallySum
from ..work import PathRange, run_range, runner_device
from .base import Executor

__all__ = ["InProcess"]


class InProcess(Executor):
    """Serial executor: each range runs in the calling thread, in the order given.

    Parameters
    ----------
    device : str, optional
        The backend's device (:func:`~layersim.montecarlo.work.run_range`); None is its default.
    """

    def __init__(self, device: str | None = None):
        self.device_request = device
        self.ran_on = None            # the device's name, once a range has run

    def map(self, ranges: Iterable[PathRange]) -> Iterator[tuple[PathRange, TallySum]]:
        """Yield ``(range, tally)`` for each range, in order (serial order is completion order)."""
        for r in ranges:
            if self.ran_on is None:
                self.ran_on = runner_device(r.walk, self.device_request)
            yield r, run_range(r, self.device_request)

    def describe(self) -> str:
        """One line: the device's name once a range has run (``"cpu (AMD EPYC ...)"``, what
        :func:`~layersim.montecarlo.simulate` reports), else ``"in process"``."""
        return self.ran_on or self.device_request or "in process"
