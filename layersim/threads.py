"""A thread pool for independent batches of numerical work.

numpy's ufuncs, FFTs, ``numpy.linalg`` and Warp's CPU kernels release the GIL for the heavy
parts of a batch, so batches of ordinate pairs (projection) or of right-hand sides
(substitution) run in parallel on threads. ``scipy.linalg``'s LAPACK wrappers must not be
called from these workers: called concurrently they return corrupted results (``numpy.linalg``
does not). SciPy's sparse products release the GIL too, so chunked products run on the pool as
well.

``layersim.config.settings().threads`` (``LAYERSIM_THREADS``) sets the number of workers
(default: the number of cores; 1 runs everything in the calling thread).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

from .config import settings


def workers() -> int:
    """Worker threads of :func:`parallel_map` (``settings().threads``)."""
    return settings().threads


def parallel_map(fn, items) -> list:
    """``[fn(x) for x in items]`` on :func:`workers` threads (in order)."""
    items = list(items)
    threads = workers()
    if threads <= 1 or len(items) <= 1:
        return [fn(x) for x in items]
    with ThreadPoolExecutor(min(threads, len(items))) as pool:
        return list(pool.map(fn, items))
