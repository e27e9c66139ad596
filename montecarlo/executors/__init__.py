"""Executors: where the path ranges of Monte Carlo walks run.

An executor takes :class:`~layersim.montecarlo.work.PathRange` s and gives back each range with
its exact :class:`~layersim.montecarlo.estimates.TallySum`, in the order the ranges finish. The
protocol, which ``layersim mc`` and :mod:`layersim.montecarlo.campaign` rely on:

``map(ranges) -> Iterator[tuple[PathRange, TallySum]]``
    Runs every range of the iterable (read lazily, as workers free up) and yields each with its
    tally in completion order. Tallies add exactly in any order, so the sum is the same integers
    whatever executor, split or order ran them (on the same backend). Leaving the iteration early
    (``break``, an exception, a KeyboardInterrupt in the consumer) cancels the outstanding work.
``close()``
    Releases threads, clients and clusters; cancels work still outstanding.
``describe() -> str``
    One line for a result file's metadata (``"dask: 3 workers at tcp://..."``).

Executors are context managers (``with Dask(workers=4) as ex: ...``).

Modules: :mod:`.base` (the shared context-manager behaviour), :mod:`.inprocess`
(:class:`InProcess`, serial, the default), :mod:`.devices` (:class:`Devices`, one thread per device
of this host), :mod:`.cluster` (:class:`Dask`, a Dask distributed cluster, local or remote).
"""

from .cluster import Dask, tls_security
from .devices import Devices
from .inprocess import InProcess

__all__ = ["InProcess", "Devices", "Dask", "tls_security"]
