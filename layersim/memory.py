"""Returning freed memory to the operating system between the phases of a solve.

numpy arrays above glibc's mmap threshold are mapped and unmapped directly, but the threshold
adapts upwards (up to 32 MiB on 64-bit Linux) after large arrays are freed, so later
temporaries of a coupled-mode solve (index and value arrays of millions of entries) come from
the heap, and the heap keeps the freed pages resident: on Table 2 row 7 of seed 000 the
resident memory at the start of the second layer's projection was 1.5 GiB with ~0.4 GiB
alive. ``malloc_trim(0)`` releases every free page of the heap (and of the threads' arenas)
back to the system; :func:`release` calls it at phase boundaries (it costs milliseconds).
"""

from __future__ import annotations

import ctypes
import ctypes.util

import numpy as np

_libc = None


def _load():
    global _libc
    if _libc is None:
        try:
            lib = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
            _libc = lib if hasattr(lib, "malloc_trim") else False
        except OSError:  # pragma: no cover - no C library to load
            _libc = False
    return _libc


def sparse_bytes(mat) -> int:
    """Bytes held by a CSR / CSC matrix's arrays (values, indices, pointers); 0 for None."""
    if mat is None:
        return 0
    return mat.data.nbytes + mat.indices.nbytes + mat.indptr.nbytes


def empty_sparse(*mats) -> None:
    """Empty CSR / CSC matrices in place (shape kept), releasing their arrays for callers that
    handed them over: whoever else refers to the matrix object sees an empty matrix."""
    for mat in mats:
        if mat is not None and getattr(mat, "format", None) in ("csr", "csc"):
            mat.data = np.zeros(0, mat.data.dtype)
            mat.indices = np.zeros(0, mat.indices.dtype)
            mat.indptr = np.zeros_like(mat.indptr)


#: glibc's ``mallopt`` parameter for the number of arenas.
_M_ARENA_MAX = -8


def limit_arenas(count: int | None = None) -> bool:
    """Cap glibc's malloc arenas (``mallopt(M_ARENA_MAX)``) at ``count`` (default:
    ``LAYERSIM_MALLOC_ARENAS``, else 1; 0 leaves glibc's default of 8 per core); returns
    whether the cap was set.

    Every thread that allocates gets an arena of its own, up to 8 per core, and what the
    worker threads of the projection and of the substitutions freed stayed resident in theirs
    even after :func:`release`: on Table 2 row 6 of seed 000 the resident memory after the
    projection was ~100 MiB above the process's baseline with no array alive, and the peak of
    the solve 678 MiB above the baseline against 579 MiB with one arena, in the same time
    (111.6 and 113.5 s; ``benchmarks/memory_phases.py 6``). The cap is process-wide and
    applies to threads created afterwards: :mod:`layersim` sets it when it is imported.
    """
    import os
    if count is None:
        try:
            count = int(os.environ.get("LAYERSIM_MALLOC_ARENAS", "1"))
        except ValueError:
            count = 1
    lib = _load()
    if not lib or count <= 0 or not hasattr(lib, "mallopt"):
        return False
    return bool(lib.mallopt(_M_ARENA_MAX, int(count)))


def release() -> bool:
    """Give the free pages of the C heap back to the system (glibc ``malloc_trim``); returns
    whether anything was released (``False`` on other C libraries, where it does nothing)."""
    lib = _load()
    return bool(lib and lib.malloc_trim(0))
