"""A thread pool for independent batches of numerical work.

numpy's ufuncs, FFTs, ``numpy.linalg`` and Warp's CPU kernels release the GIL for the heavy
parts of a batch, so batches of ordinate pairs (projection) or of right-hand sides
(substitution) run in parallel on threads. ``scipy.linalg``'s LAPACK wrappers must not be
called from these workers: called concurrently they returned corrupted results on the 2-core
CI machine (``numpy.linalg`` did not). scipy's sparse products (sparsetools) release it too
in recent SciPy (1.17 on the 2-core CI machine: two row chunks of a 40000 x 40000 product in
3.5 s on two threads against 6.2 s in turn), so chunked products run on the pool as well.

``$LAYERSIM_PROJECTION_THREADS`` sets the number of workers (default: the number of cores; 1
runs everything in the calling thread).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

#: Worker threads (see module docstring).
THREADS = int(os.environ.get("LAYERSIM_PROJECTION_THREADS", os.cpu_count() or 1))


def parallel_map(fn, items) -> list:
    """``[fn(x) for x in items]`` on :data:`THREADS` worker threads (in order)."""
    items = list(items)
    if THREADS <= 1 or len(items) <= 1:
        return [fn(x) for x in items]
    with ThreadPoolExecutor(min(THREADS, len(items))) as pool:
        return list(pool.map(fn, items))
