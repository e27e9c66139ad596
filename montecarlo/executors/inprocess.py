"""Run path ranges one after the other in this process: the default executor."""

from __future__ import annotations

from typing import Iterable, Iterator

from ..estimates import TallySum
from ..work import PathRange, run_range
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
        self.device = device

    def map(self, ranges: Iterable[PathRange]) -> Iterator[tuple[PathRange, TallySum]]:
        """Yield ``(range, tally)`` for each range, in order (serial order is completion order)."""
        for r in ranges:
            yield r, run_range(r, self.device)

    def describe(self) -> str:
        """One line: ``"in process"`` and the device, if one was named."""
        return "in process" + (f" on {self.device}" if self.device else "")
