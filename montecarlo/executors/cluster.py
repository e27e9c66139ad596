"""Run path ranges on a Dask distributed cluster: processes on this machine, or a running scheduler
with workers on many machines.

Each range is one task: a worker unpickles the :class:`~layersim.montecarlo.work.PathRange`
(the scene record and a few numbers), calls :func:`~layersim.montecarlo.work.run_range` and sends
back the exact tally. A Dask cluster runs pickled code, so join only clusters you trust, and every
worker must have the same layersim installed as the client (checked when connecting: workers
without layersim, or with another version, are named in the error). Only a bounded number of
ranges is in flight at a time, so a campaign of 1e12 paths never holds millions of futures; a
worker that dies costs only the ranges it held, which the scheduler runs again elsewhere.

GPUs: a worker runs its walks on its backend's default device, so start one worker per GPU with
``CUDA_VISIBLE_DEVICES`` naming it (as ``dask-cuda-worker`` does), or run
:class:`~layersim.montecarlo.executors.Devices` on each host; ``Dask(workers=N)`` on one GPU
host puts every worker on its first GPU.

Security: ``security=`` is passed to :class:`distributed.Client`; :func:`tls_security` builds one
from a CA file, certificate and key. With none given, Dask's own configuration applies
(``distributed.comm.tls.*``, ``distributed.client.security-loader``).
"""

from __future__ import annotations

import logging
import os
from typing import Callable, Iterable, Iterator

from ...errors import ClusterError
from ..estimates import TallySum
from ..work import PathRange, run_range
from .base import Executor

__all__ = ["Dask", "tls_security"]

_NEEDS = "the Dask executor needs dask[distributed]: pip install 'dask[distributed]'"


def _distributed():
    try:
        import distributed
    except ImportError:
        raise ClusterError(_NEEDS) from None
    return distributed


def tls_security(ca_file: str | None = None, cert: str | None = None, key: str | None = None):
    """A :class:`distributed.security.Security` for a TLS scheduler, or None if no file is given
    (Dask's configuration then applies).

    Parameters
    ----------
    ca_file : str
        PEM file of the certificate authority that signed the scheduler's and workers' certificates.
    cert : str
        PEM certificate of this client (it may hold the key too).
    key : str, optional
        PEM private key of the certificate, if not inside ``cert``.

    Raises
    ------
    ValueError
        A file is missing or unreadable, or a key or CA is given without a certificate (one line
        naming the option).
    """
    files = {"tls_ca_file": ca_file, "tls_cert": cert, "tls_key": key}
    if all(v is None for v in files.values()):
        return None
    for name, path in files.items():
        if path is not None and not (os.path.isfile(path) and os.access(path, os.R_OK)):
            raise ValueError(f"{name}: cannot read the file {str(path)!r}")
    if cert is None or ca_file is None:
        raise ValueError(f"{'tls_cert' if cert is None else 'tls_ca_file'}: TLS needs both a CA "
                         "file and this client's certificate (and its key, if not inside it)")
    Security = _distributed().security.Security
    return Security(tls_ca_file=str(ca_file), tls_client_cert=str(cert),
                    tls_client_key=None if key is None else str(key), require_encryption=True)


def _worker_layersim() -> str:
    """Runs on each worker: the layersim it imports (its version)."""
    import layersim
    return layersim.__version__


def _worker_backend(name: str) -> tuple:
    """Runs on each worker: the backend ``name`` resolves to there and why it cannot run (or
    None)."""
    from ..backends import resolve_backend, why_unavailable
    backend = resolve_backend(name)
    return backend, why_unavailable(backend)


class Dask(Executor):
    """Path ranges as tasks of a Dask distributed cluster.

    Parameters
    ----------
    workers : int, optional
        Start a local cluster of this many worker processes, one thread each (Warp's CPU device
        runs a launch on one core, so N workers keep N cores busy).
    address : str, optional
        Join the running scheduler at this address (``"tcp://host:8786"``, ``"tls://..."``).
        Exactly one of ``workers`` and ``address``.
    security : distributed.security.Security, optional
        Passed to the client (:func:`tls_security`); None lets Dask's configuration decide.
    in_flight : int, optional
        Ranges submitted and not yet returned, at most; default twice the workers' threads when
        :meth:`map` starts (at least 4), which keeps every worker fed while it sends a result
        back.
    retries : int
        Times a range whose task raised is run again (a lost worker's ranges are rerun by the
        scheduler anyway, up to its ``allowed-failures``).
    task : callable
        What a worker calls on each range (:func:`~layersim.montecarlo.work.run_range`; tests
        pass one that fails on purpose). It is pickled, so it must be importable on the workers.
    timeout : float
        Seconds to wait for the scheduler when connecting.

    Raises
    ------
    ValueError
        Bad arguments (named).
    ClusterError
        No scheduler at ``address``, or workers that cannot import this layersim.
    """

    def __init__(self, workers: int | None = None, *, address: str | None = None, security=None,
                 in_flight: int | None = None, retries: int = 3,
                 task: Callable[[PathRange], TallySum] = run_range, timeout: float = 30.0):
        _check_args(workers, address, security, in_flight, retries)
        distributed = _distributed()
        self.task, self.in_flight, self.retries = task, in_flight, retries
        self._cluster = None
        self._running: dict = {}
        if workers is not None:
            # no dashboard; the scheduler's own HTTP endpoint on a free local port, so that
            # several runs on one machine do not contend for Dask's default port 8787
            self._cluster = distributed.LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                scheduler_kwargs={"dashboard_address": "127.0.0.1:0"}, silence_logs=logging.ERROR)
            self.client = distributed.Client(self._cluster)
        else:
            _check_tls(distributed, address, security)
            try:
                self.client = distributed.Client(address, security=security, timeout=timeout)
            except (OSError, TimeoutError) as exc:
                raise ClusterError(f"cannot reach the Dask scheduler at {address!r}: "
                                   f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
                                   ) from None
        try:
            self._check_workers()
        except BaseException:
            self.close()
            raise

    def _check_workers(self) -> None:
        """Every worker imports this layersim (the same version), else ClusterError naming them."""
        import layersim
        try:
            found = self.client.run(_worker_layersim)
        except Exception as exc:
            first = (str(exc).splitlines() or [""])[0]
            raise ClusterError(f"the Dask workers cannot import layersim ({type(exc).__name__}: "
                               f"{first}); install layersim {layersim.__version__} on every "
                               "worker") from None
        other = {w: v for w, v in found.items() if v != layersim.__version__}
        if other:
            w, v = next(iter(other.items()))
            raise ClusterError(f"{len(other)} Dask worker(s) run layersim {v} (e.g. {w}), this "
                               f"client {layersim.__version__}; install the same layersim on "
                               "every worker")

    def resolve_backend(self, name: str) -> str:
        """The backend the workers run for ``name`` (``"auto"`` resolved there, not here),
        checked on every worker.

        Raises
        ------
        ClusterError
            No workers, a worker that cannot run it (named, with its reason), or workers that
            resolve ``"auto"`` differently (tallies of different backends differ).
        """
        found = self.client.run(_worker_backend, name)
        if not found:
            raise ClusterError(f"the Dask cluster at {self.client.scheduler.address} has no "
                               "workers")
        bad = {w: reason for w, (_, reason) in found.items() if reason}
        if bad:
            w, reason = next(iter(bad.items()))
            more = f" (and {len(bad) - 1} more)" if len(bad) > 1 else ""
            raise ClusterError(f"Dask worker {w}{more} cannot run the walk: {reason}")
        names = sorted({b for b, _ in found.values()})
        if len(names) > 1:
            raise ClusterError(f"backend {name!r} is {' on some workers, '.join(names)} on "
                               "others; name one backend (tallies of different backends differ)")
        return names[0]

    def _threads(self) -> int:
        workers = self.client.scheduler_info().get("workers", {})
        return sum(int(w.get("nthreads", 1)) for w in workers.values())

    def describe(self) -> str:
        """One line: ``"dask: 3 workers at tcp://127.0.0.1:40915 (local cluster)"``."""
        n = len(self.client.scheduler_info().get("workers", {}))
        where = " (local cluster)" if self._cluster is not None else ""
        return f"dask: {n} workers at {self.client.scheduler.address}{where}"

    def map(self, ranges: Iterable[PathRange]) -> Iterator[tuple[PathRange, TallySum]]:
        """Yield ``(range, tally)`` as the workers finish them (completion order), with at most
        ``in_flight`` ranges submitted at a time; leaving early cancels those still out."""
        distributed = _distributed()
        source = iter(ranges)
        limit = self.in_flight or max(4, 2 * self._threads())
        pending = distributed.as_completed()

        def submit() -> None:
            r = next(source, None)
            if r is not None:
                future = self.client.submit(self.task, r, pure=False, retries=self.retries)
                self._running[future] = r
                pending.add(future)

        try:
            for _ in range(limit):
                submit()
            for future in pending:
                r = self._running.pop(future)
                tally = _result(future, r, distributed)
                future.release()
                submit()
                yield r, tally
        finally:
            self._cancel()

    def _cancel(self) -> None:
        if self._running:
            futures = list(self._running)
            self._running.clear()
            self.client.cancel(futures)

    def close(self) -> None:
        """Cancel the ranges still out, close the client and any local cluster."""
        client = getattr(self, "client", None)
        if client is not None:
            self._cancel()
            client.close()
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None


def _result(future, r: PathRange, distributed) -> TallySum:
    """A range's tally; a range that keeps killing its workers is one line naming it."""
    try:
        return future.result()
    except distributed.KilledWorker as exc:
        last = getattr(exc.last_worker, "address", exc.last_worker)
        raise ClusterError(f"paths {r.first} to {r.first + r.count - 1} of the walk of "
                           f"'{r.walk.scene.name}' killed {exc.allowed_failures + 1} Dask workers "
                           f"(the last {last}); see the workers' logs (memory limit, GPU "
                           "errors)") from None


def _check_tls(distributed, address: str, security) -> None:
    """A ``tls://`` scheduler with no TLS files given or configured: say so in one line (Dask
    itself fails deep inside its comm layer)."""
    import dask
    if not address.startswith("tls://") or (
            security is None and dask.config.get("distributed.client.security-loader", None)):
        return
    security = security or distributed.security.Security()
    if security.get_connection_args("client").get("ssl_context") is None:
        raise ValueError(f"security: the scheduler {address!r} speaks TLS; give the CA file, "
                         "certificate and key (tls_security; layersim mc --tls-ca-file, "
                         "--tls-cert, --tls-key) or set Dask's distributed.comm.tls config")


def _check_args(workers, address, security, in_flight, retries) -> None:
    """One-line errors naming the argument, before any cluster starts."""
    def positive_int(name, value, lo):
        if isinstance(value, bool) or not isinstance(value, int) or value < lo:
            raise ValueError(f"{name} must be an integer >= {lo}, got {value!r}")
    if (workers is None) == (address is None):
        raise ValueError("workers/address: give workers=N (a local cluster) or address=... "
                         "(a running scheduler), exactly one of them")
    if workers is not None:
        positive_int("workers", workers, 1)
        if security is not None:
            raise ValueError("security: applies to address=, not to a local cluster")
    elif not isinstance(address, str) or not address.strip():
        raise ValueError(f"address must be a scheduler address such as 'tcp://host:8786', got "
                         f"{address!r}")
    if in_flight is not None:
        positive_int("in_flight", in_flight, 1)
    positive_int("retries", retries, 0)
