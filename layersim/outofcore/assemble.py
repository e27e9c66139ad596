"""Sparse matrices assembled from parts and pieces, each released as it is copied.

The matrices of coupled stacks hold tens of millions of entries; a concatenation of their
parts, or a COO -> CSR conversion, holds two or three copies of them at once. These assemblies
write the parts straight into the result's arrays, releasing each part (and trimming the heap,
:func:`trim_heap`) as it is placed.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from .memory import release
from .spool import Spool


#: Entries copied by :func:`from_parts` and :func:`stack_rows` between two returns of freed
#: heap pages (:func:`~layersim.outofcore.memory.release`; 48 MiB of indices and values).
RELEASE_ENTRIES = 1 << 22


def csr_arrays(n_rows: int, n_cols: int, total: int):
    """Zero row pointers and uninitialised indices and values for a CSR matrix of ``total``
    entries, with 32-bit indices where they fit (scipy would otherwise copy them down)."""
    index_type = np.int32 if max(total, n_cols) < 2**31 else np.int64
    return np.zeros(n_rows + 1, index_type), np.empty(total, index_type), np.empty(total)


def trim_heap(placed: int, trimmed: int) -> int:
    """Return the freed heap pages (:func:`~layersim.outofcore.memory.release`) once
    :data:`RELEASE_ENTRIES` more entries were placed since the last time (``trimmed``); the
    count at the last release. The parts and pieces that assemblies copy from are small arrays
    from the heap, whose freed pages stay resident until trimmed: without this, assembling
    ``K`` holds two copies of it."""
    if placed - trimmed > RELEASE_ENTRIES:
        release()
        return placed
    return trimmed


def from_parts(parts, shape: tuple, fmt: str = "csr", select=None):
    """Sparse matrix of shape ``shape`` from ``parts``, a list or a
    :class:`~layersim.outofcore.spool.Spool` of ``(rows, cols, values)`` triplets (duplicates are
    summed), ``parts`` emptied.

    The matrices of coupled stacks hold tens of millions of entries, and the parts are
    scattered straight into the CSR arrays (counting sort by row), each part released (and
    the heap trimmed, :func:`trim_heap`) as it is placed, with no concatenated or COO copy, so
    that the resident memory falls across the assembly where a concatenation and a COO -> CSR
    conversion would raise it.

    Parameters
    ----------
    parts : list or Spool of (int ndarray (E,), int ndarray (E,), float ndarray (E,))
    shape : (int, int)
    fmt : {"csr", "csc"}
    select : callable, optional
        ``select(rows, cols, values)`` -> the triplet of the entries to keep, applied to
        every part as it is read (e.g. :meth:`PairPruner.final_filter` for a spool).
    """
    if fmt not in ("csr", "csc"):
        raise ValueError(f"fmt must be 'csr' or 'csc', not {fmt!r}")
    by_col = fmt == "csc"               # a CSC matrix is the CSR matrix of the transpose
    n_rows, n_cols = shape[::-1] if by_col else shape
    select = select or (lambda *part: part)
    counts = np.zeros(n_rows, np.int64)
    for part in parts:
        counts += np.bincount(select(*part)[1 if by_col else 0], minlength=n_rows)
    indptr, indices, data = csr_arrays(n_rows, n_cols, int(counts.sum()))
    np.cumsum(counts, out=indptr[1:])
    del counts
    fill = indptr[:-1].astype(np.int64)              # next free position of each row
    placed = trimmed = 0
    for part in (parts.drain() if isinstance(parts, Spool) else drain(parts)):
        r, c, v = select(*part)
        del part
        if by_col:
            r, c = c, r
        if r.size == 0:
            continue
        order = np.argsort(r, kind="stable")
        rs = r[order]
        first = np.flatnonzero(np.concatenate([[True], rs[1:] != rs[:-1]]))
        run = np.diff(np.append(first, rs.size))
        pos = fill[rs] + (np.arange(rs.size) - np.repeat(first, run))
        indices[pos], data[pos] = c[order], v[order]
        fill[rs[first]] += run
        placed += rs.size
        del r, c, v, order, rs, first, run, pos
        trimmed = trim_heap(placed, trimmed)
    out = sps.csr_matrix((data, indices, indptr), shape=(n_rows, n_cols))
    out.sum_duplicates()            # sorts each row and sums its duplicates in place
    return out.T if by_col else out


def drain(items: list):
    """Iterate over a list, releasing each item as it is handed out (the list is emptied)."""
    for k in range(len(items)):
        item, items[k] = items[k], None
        yield item
        del item
    items.clear()


def stack_rows(pieces, shape: tuple, total: int | None = None) -> sps.csr_matrix:
    """CSR matrix from consecutive row pieces ``(start, indptr, indices, data)``: a list
    (emptied, each piece released as soon as it is copied), or any iterable of them with
    their ``total`` entries (e.g. read one by one from a file)."""
    if total is None:
        total = int(sum(p[1][-1] for p in pieces))
    indptr, indices, data = csr_arrays(shape[0], shape[1], int(total))
    at = trimmed = 0
    for start, ptr, c, v in (drain(pieces) if isinstance(pieces, list) else pieces):
        n = int(ptr[-1])
        indptr[start + 1:start + ptr.size] = at + ptr[1:]
        indices[at:at + n], data[at:at + n] = c, v
        at += n
        del ptr, c, v
        trimmed = trim_heap(at, trimmed)
    np.maximum.accumulate(indptr, out=indptr)         # rows of no piece: empty
    return sps.csr_matrix((data, indices, indptr), shape=shape)


def select_entries(mat: sps.csr_matrix, keep: np.ndarray) -> sps.csr_matrix:
    """The entries of the CSR matrix ``mat`` where the boolean ``keep`` (nnz,) is true."""
    kept = np.concatenate([[0], np.cumsum(keep)])
    return sps.csr_matrix((mat.data[keep], mat.indices[keep], kept[mat.indptr]),
                          shape=mat.shape)
