"""What every executor shares: use as a context manager, and the check that a range runs on the
executor's backend."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Iterable, Iterator

from ..estimates import TallySum
from ..work import PathRange

__all__ = ["Executor", "check_backend"]


class Executor(ABC):
    """Base of the executors: ``with`` closes the executor on the way out (an exception or a
    KeyboardInterrupt in the consumer included), which cancels outstanding work."""

    def close(self) -> None:
        """Release what the executor holds (nothing here)."""

    @abstractmethod
    def describe(self) -> str:
        """One line naming where the ranges run (for a result file's metadata)."""

    @abstractmethod
    def map(self, ranges: Iterable[PathRange]) -> Iterator[tuple[PathRange, TallySum]]:
        """``(range, tally)`` for every range, in completion order."""

    @property
    def device(self) -> str:
        """Where the ranges run, as :meth:`describe` says it (what a result file records)."""
        return self.describe()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def check_backend(r: PathRange, backend: str) -> None:
    """Refuse a range whose walk names another backend than the executor's devices run.

    Raises
    ------
    ValueError
        One line naming both backends.
    """
    if r.walk.backend != backend:
        raise ValueError(f"walk backend {r.walk.backend!r} does not match the executor's "
                         f"devices, which run backend {backend!r}")
