"""Returning freed memory to the operating system, and the size of sparse blocks.

numpy arrays above glibc's mmap threshold are mapped and unmapped directly, but the threshold
adapts upwards (up to 32 MiB on 64-bit Linux) after large arrays are freed, so later
temporaries of a coupled-mode solve (index and value arrays of millions of entries) come from
the heap, and the heap keeps the freed pages resident. ``malloc_trim(0)`` releases every free
page of the heap (and of the threads' arenas) back to the system; :func:`release` calls it at
phase boundaries (it costs milliseconds).

:func:`cap_arenas` caps glibc's malloc arenas. The cap is process-wide and cannot be undone:
glibc fixes its arena limit the first time a thread needs a new arena and ignores later
``mallopt(M_ARENA_MAX)`` calls (and values <= 0), so no library call applies it; a program
that owns its process (the command line, the benchmarks) may call it at start-up with
``layersim.config.settings().malloc_arenas``.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

import numpy as np

from ..config import settings

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


def cap_arenas(count: int) -> bool:
    """Cap glibc's malloc arenas (``mallopt(M_ARENA_MAX)``) at ``count`` for the rest of the
    process (0 leaves glibc's default of 8 per core); returns whether the cap was set.

    Every thread that allocates gets an arena of its own, up to 8 per core, and what the
    worker threads of the projection and of the substitutions free stays resident in theirs
    even after :func:`release`; with one arena it goes back to the system. Call it before
    worker threads allocate. It is irreversible (module docstring): a program that owns its
    process calls it, a library does not.
    """
    lib = _load()
    if not lib or count <= 0 or not hasattr(lib, "mallopt"):
        return False
    return bool(lib.mallopt(_M_ARENA_MAX, int(count)))


def release() -> bool:
    """Give the free pages of the C heap back to the system (glibc ``malloc_trim``); returns
    whether anything was released (``False`` on other C libraries, where it does nothing)."""
    lib = _load()
    return bool(lib and lib.malloc_trim(0))


def available_memory() -> int:
    """Physical memory available now (bytes; 8 GiB where the system does not say)."""
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        return 8 << 30


def memory_limit() -> int:
    """Bytes a solve may use: ``settings().max_memory`` (``LAYERSIM_MAX_MEMORY``) or half the
    available memory."""
    limit = settings().max_memory
    return available_memory() // 2 if limit is None else limit
