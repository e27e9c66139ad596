"""Operator assembly on the device: per-pair cosine series -> per-order blocks -> stacked CSR.

The numeric projection on a GPU (``layersim.ingredients.numeric``) leaves its series on the
device; these kernels turn them into the CSR arrays of
:class:`layersim.operators.operator.OrderStack` without a round trip through the host, so that only
the nonzeros come back. They follow ``layersim.operators.operator._orders_to_csr`` exactly:
``B_l[o, i] = c_l f_l(o <- i) w_i |mu_i|`` with ``c_0 = 2 pi``, ``c_l = pi``, entries below ``tol``
times the largest of their order dropped, columns in increasing order within each row.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .runtime import device_for, ensure_init, host_array


@wp.kernel
def _scatter_kernel(coef: wp.array2d(dtype=wp.float64), o: wp.array(dtype=wp.int32),
                    i: wp.array(dtype=wp.int32), fw: wp.array(dtype=wp.float64),
                    direct: int, mirror: int, skip_diagonal: int, scale: wp.float64,
                    dense: wp.array3d(dtype=wp.float64)):
    """Write pair p's order-l coefficient at [l, o, i] (``direct``) and/or, times ``scale``, at
    the transposed position [l, i, o] (``mirror``; reciprocity), weighted as B_l."""
    p, l = wp.tid()
    v = coef[p, l]
    w = wp.float64(wp.pi)
    if l == 0:
        w = wp.float64(2.0) * wp.float64(wp.pi)
    a = o[p]
    b = i[p]
    if direct != 0:
        dense[l, a, b] = v * fw[b] * w
    if mirror != 0 and (skip_diagonal == 0 or a != b):
        dense[l, b, a] = v * scale * fw[a] * w


@wp.kernel
def _row_absmax_kernel(dense: wp.array3d(dtype=wp.float64), rowmax: wp.array2d(dtype=wp.float64)):
    l, r = wp.tid()
    big = wp.float64(0.0)
    for c in range(dense.shape[2]):
        big = wp.max(big, wp.abs(dense[l, r, c]))
    rowmax[l, r] = big


@wp.kernel
def _order_cut_kernel(rowmax: wp.array2d(dtype=wp.float64), tol: wp.float64,
                      cut: wp.array(dtype=wp.float64)):
    l = wp.tid()
    big = wp.float64(0.0)
    for r in range(rowmax.shape[1]):
        big = wp.max(big, rowmax[l, r])
    cut[l] = tol * big


@wp.func
def _kept(v: wp.float64, cut: wp.float64):
    return v != wp.float64(0.0) and wp.abs(v) >= cut


@wp.kernel
def _row_count_kernel(dense: wp.array3d(dtype=wp.float64), cut: wp.array(dtype=wp.float64),
                      counts: wp.array(dtype=wp.int64)):
    l, r = wp.tid()
    n = wp.int64(0)
    for c in range(dense.shape[2]):
        if _kept(dense[l, r, c], cut[l]):
            n += wp.int64(1)
    counts[l * dense.shape[1] + r] = n


@wp.kernel
def _compact_kernel(dense: wp.array3d(dtype=wp.float64), cut: wp.array(dtype=wp.float64),
                    ends: wp.array(dtype=wp.int64), counts: wp.array(dtype=wp.int64),
                    data: wp.array(dtype=wp.float64), indices: wp.array(dtype=wp.int32)):
    l, r = wp.tid()
    row = l * dense.shape[1] + r
    k = ends[row] - counts[row]
    for c in range(dense.shape[2]):
        v = dense[l, r, c]
        if _kept(v, cut[l]):
            data[k] = v
            indices[k] = c
            k += wp.int64(1)


class BlockAssembler:
    """Accumulates one block's orders on the device, then compacts them to CSR arrays.

    Parameters
    ----------
    m, h : int
        Orders and nodes per hemisphere; the scratch array is (m, h, h) float64 on the device.
    flux_weight : ndarray (h,)
        ``w_i |mu_i|`` of the grid.
    """

    def __init__(self, m: int, h: int, flux_weight: np.ndarray, device=None):
        ensure_init()
        self.device = device_for(device)
        self.m, self.h = int(m), int(h)
        self.dense = wp.zeros((self.m, self.h, self.h), dtype=wp.float64, device=self.device)
        self.fw = wp.array(np.asarray(flux_weight, np.float64), dtype=wp.float64,
                           device=self.device)

    def reset(self) -> None:
        """Zero the scratch block (for the next block of an operator)."""
        self.dense.zero_()

    def scatter(self, coef, o: np.ndarray, i: np.ndarray, *, direct: bool = True,
                mirror: bool = False, skip_diagonal: bool = True, scale: float = 1.0) -> None:
        """Add pairs ``(o, i)`` (node indices, shape (P,)) with series ``coef`` (a Warp or numpy
        array (P, >= m); its first ``m`` orders are used) to the block."""
        P = int(np.size(o))
        if P == 0:
            return
        if not isinstance(coef, wp.array):
            coef = host_array(coef, wp.float64, self.device)
        dev = self.device
        wp.launch(_scatter_kernel, dim=(P, self.m), device=dev,
                  inputs=[coef, wp.array(np.asarray(o, np.int32), dtype=wp.int32, device=dev),
                          wp.array(np.asarray(i, np.int32), dtype=wp.int32, device=dev),
                          self.fw, int(direct), int(mirror), int(skip_diagonal),
                          wp.float64(scale)], outputs=[self.dense])

    def compact(self, tol: float):
        """CSR arrays ``(data, indices, indptr)`` of the stacked orders (row ``l h + o``), entries
        below ``tol`` times the largest of their order dropped; numpy arrays on the host."""
        m, h, dev = self.m, self.h, self.device
        rowmax = wp.empty((m, h), dtype=wp.float64, device=dev)
        cut = wp.empty(m, dtype=wp.float64, device=dev)
        counts = wp.empty(m * h, dtype=wp.int64, device=dev)
        ends = wp.empty(m * h, dtype=wp.int64, device=dev)
        wp.launch(_row_absmax_kernel, dim=(m, h), device=dev, inputs=[self.dense],
                  outputs=[rowmax])
        wp.launch(_order_cut_kernel, dim=m, device=dev, inputs=[rowmax, wp.float64(tol)],
                  outputs=[cut])
        wp.launch(_row_count_kernel, dim=(m, h), device=dev, inputs=[self.dense, cut],
                  outputs=[counts])
        wp.utils.array_scan(counts, ends, inclusive=True)
        indptr = np.zeros(m * h + 1, np.int64)
        indptr[1:] = ends.numpy()
        nnz = int(indptr[-1])
        data = wp.empty(max(nnz, 1), dtype=wp.float64, device=dev)
        indices = wp.empty(max(nnz, 1), dtype=wp.int32, device=dev)
        wp.launch(_compact_kernel, dim=(m, h), device=dev,
                  inputs=[self.dense, cut, ends, counts], outputs=[data, indices])
        return data.numpy()[:nnz], indices.numpy()[:nnz], indptr
