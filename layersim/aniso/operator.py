"""Scattering operators with coupled Fourier modes (anisotropic layers and stacks).

An :class:`AnisoOperator` holds the four blocks ``Rt, Rb, Ttb, Tbt`` of Zeltner & Jakob 2018
sec. 3.2 (same meaning and solver convention as :class:`~layersim.operator.IsoOperator`:
``mu > 0`` propagates down, blocks indexed ``[outgoing, incident]``) as real sparse matrices of shape ``(S h, S h)`` in
the slot basis of :mod:`layersim.aniso.basis` (``S = 2 md - 1`` real slots of ``h`` ordinates).
Row/column ``slot * h + node``. The block coupling Fourier mode ``k`` to ``l`` holds
``B_{l,k} = 2 pi f_{(l+k)/2, (l-k)/2} w |mu|`` (Zeltner & Jakob 2018 eq. (10)); ``ms`` records
the largest coupling ``|l - k| / 2`` present (0: block diagonal, i.e. isotropic).

Unscattered transmission through media (a delta in direction) sits on the diagonal of the
transmission blocks in every slot, and is recorded per node in ``delta`` exactly as for
isotropic operators.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sps

from .. import memory
from ..errors import FileFormatError, OperatorError
from ..operator import (BLOCKS, DROP_TOLERANCE, Grid, IsoOperator, Operator, header_arrays,
                        read_blocks, read_delta, register, write_blocks)
from . import basis
from .park import Parked, Spool
from .rowpieces import RowPieces, row_spans


@register
class AnisoOperator(Operator):
    """Operator of an anisotropic layer or stack in the real slot basis (module docstring);
    implements :class:`layersim.operator.Operator`.

    Parameters
    ----------
    grid : Grid
    md : int
        Fourier orders (modes ``-(md-1) .. md-1``).
    blocks : dict
        ``{"Rt": csr (S h, S h), ...}``; ``None`` or missing marks a block left out (opaque
        operators keep ``Rt`` only).
    eta_top, eta_bottom : float
        Absolute indices of the media above and below (``eta_bottom`` None when opaque).
    delta : dict, optional
        Unscattered transmission per node, ``{"Ttb": (h,), "Tbt": (h,)}``.
    ms : int, optional
        Largest mode coupling present (computed from the blocks when omitted).
    """

    representation = "anisotropic"

    def __init__(self, grid: Grid, md: int, blocks: dict, eta_top: float = 1.0,
                 eta_bottom: float | None = 1.0, delta: dict | None = None,
                 ms: int | None = None):
        self.grid = grid
        self.md = int(md)
        N = basis.n_slots(self.md) * grid.h
        self.blocks = {}
        for name in BLOCKS:
            mat = blocks.get(name)
            if mat is not None:
                if not isinstance(mat, Parked):     # parked: see aniso_interface_operator
                    mat = sps.csr_matrix(mat)
                if mat.shape != (N, N):
                    raise OperatorError(f"block {name} has shape {mat.shape}, expected ({N}, {N})"
                                        f" for md = {self.md} and h = {grid.h}")
            self.blocks[name] = mat
        if self.blocks["Rt"] is None:
            raise OperatorError("an operator needs an Rt block")
        self.eta_top = float(eta_top)
        self.eta_bottom = None if self.opaque else float(eta_bottom)
        self.delta = {} if self.opaque or not delta else {
            k: np.asarray(v, float) for k, v in delta.items() if v is not None}
        self.ms = self._coupling() if ms is None else int(ms)
        self.consumed = False           # see consume()

    # ---- structure ---------------------------------------------------------------------

    @property
    def m(self) -> int:
        """Number of Fourier orders (alias of ``md``, for code shared with IsoOperator)."""
        return self.md

    @property
    def slots(self) -> int:
        return basis.n_slots(self.md)

    @property
    def size(self) -> int:
        return self.slots * self.h

    def _coupling(self) -> int:
        mode = basis.slot_mode(self.md)
        worst = 0
        for name, mat in self.blocks.items():
            if mat is None or mat.nnz == 0:
                continue
            if isinstance(mat, Parked):
                raise OperatorError(f"block {name} is parked: pass ms")
            rs, cs = slot_pairs(mat, self.h)
            # |l - k| / 2 over the complex modes +-lo, +-li that the real entry stands for
            worst = max(worst, int(np.abs(mode[rs] - mode[cs]).max()) // 2)
        return worst

    def block(self, name: str) -> sps.csr_matrix:
        if self.consumed:
            raise OperatorError("this operator was consumed by an adding step (consume=True) "
                                "and no longer holds its blocks")
        mat = self.blocks[name]
        if mat is None:
            raise OperatorError(f"block {name} was left out of this operator (opaque)")
        if isinstance(mat, Parked):
            raise OperatorError(f"block {name} is parked on disk for an adding step that "
                                "consumes this operator (layersim.aniso.park)")
        return mat

    def nnz(self) -> int:
        return sum(m.nnz for m in self.blocks.values() if m is not None)

    def memory_bytes(self) -> int:
        """Resident bytes of the blocks (parked blocks not counted)."""
        return sum(memory.sparse_bytes(m) for m in self.blocks.values()
                   if not isinstance(m, Parked))

    def density(self) -> float:
        """Fraction of nonzero entries over the present blocks, counted on the complex
        operator of Zeltner & Jakob 2018 (modes ``-(md-1)..md-1``, the same count as the real
        one)."""
        present = sum(1 for m in self.blocks.values() if m is not None)
        return self.nnz() / max(1, present * self.size * self.size)

    def __repr__(self) -> str:
        return (f"AnisoOperator(n={self.grid.n}, rule={self.grid.rule}, md={self.md}, "
                f"ms={self.ms}, {'opaque' if self.opaque else 'transmissive'}, "
                f"nnz={self.nnz()}, density={100 * self.density():.3g}%)")

    # ---- construction ------------------------------------------------------------------

    @classmethod
    def from_iso(cls, op: IsoOperator, md: int | None = None) -> "AnisoOperator":
        """The isotropic operator in the slot basis: block diagonal, ``cos<-cos = sin<-sin =
        B_l`` (see :mod:`layersim.aniso.basis`). Orders at or beyond ``md`` are dropped;
        missing ones are zero, except for the unscattered beam of media, which occupies every
        order."""
        md = op.m if md is None else int(md)
        blocks = {}
        for name in BLOCKS:
            if op.blocks[name] is None:
                blocks[name] = None
                continue
            diag = [op.block(name, 0)]
            for l in range(1, md):
                b = op.block(name, l) if l < op.m or name not in op.delta \
                    else sps.diags(op.delta[name], format="csr")
                diag += [b, b]
            blocks[name] = sps.block_diag(diag, format="csr")
        return cls(op.grid, md, blocks, op.eta_top, op.eta_bottom, op.delta, ms=0)

    def rotational_average(self) -> IsoOperator:
        """The isotropic operator of this layer averaged over rotations of its tangent frame.

        Averaging over rotations keeps the ``s = 0`` coefficients ``f_{d,0}`` only, i.e. the
        ``B_{l,l}`` blocks; in the real basis ``Re B_{l,l}`` is the mean of the ``cos<-cos`` and
        ``sin<-sin`` diagonal slot blocks of order ``l`` (the ``B_{l,-l}`` terms they also hold
        cancel in the mean), the ``0<-0`` block for ``l = 0``. The odd part ``Im B_{l,l}`` (sine
        terms in ``phi_d``) is dropped: the result is the even part of the average, non-negative
        wherever the BSDF is. Used as the importance-sampling proposal of anisotropic stacks
        (:mod:`layersim.sampling`).
        """
        h = self.h
        blocks = {}
        for name in BLOCKS:
            mat = self.blocks[name]
            if mat is None:
                blocks[name] = None
                continue
            mat = mat.tocsr()
            diag = lambda slot: mat[slot * h:(slot + 1) * h, slot * h:(slot + 1) * h]
            orders = [diag(0)]
            for l in range(1, self.md):
                orders.append(((diag(2 * l - 1) + diag(2 * l)) * 0.5).tocsr())
            blocks[name] = [prune(sps.csr_matrix(b)) for b in orders]
        return IsoOperator(self.grid, blocks, self.eta_top, self.eta_bottom, self.delta)

    @classmethod
    def identity(cls, grid: Grid, md: int, eta: float) -> "AnisoOperator":
        return cls.from_iso(IsoOperator.identity(grid, md, eta), md)

    def as_coupled(self, md: int | None = None) -> "AnisoOperator":
        return self if md is None else self.with_md(md)

    def map_blocks(self, fn: Callable) -> "AnisoOperator":
        blocks = {k: None if v is None else fn(v) for k, v in self.blocks.items()}
        return AnisoOperator(self.grid, self.md, blocks, self.eta_top, self.eta_bottom,
                             self.delta)

    def reciprocity_error(self) -> float:
        return reciprocity_error(self)

    def with_md(self, md: int) -> "AnisoOperator":
        """The same operator with ``md`` orders (slots beyond are dropped / zero)."""
        if md == self.md:
            return self
        n_new = basis.n_slots(md) * self.h
        n_old = self.size
        blocks = {}
        for name, mat in self.blocks.items():
            if mat is None:
                blocks[name] = None
            elif md < self.md:
                blocks[name] = mat[:n_new, :n_new].tocsr()
            else:
                # new orders are empty, except for the unscattered beam, which occupies every
                # order (the diagonal of the transmission blocks)
                extra = np.tile(self.delta[name], 2 * (md - self.md)) if name in self.delta \
                    else np.zeros(n_new - n_old)
                blocks[name] = sps.block_diag([mat, sps.diags(extra)], format="csr")
        return AnisoOperator(self.grid, md, blocks, self.eta_top, self.eta_bottom, self.delta)

    def rotated(self, angle: float) -> "AnisoOperator":
        """The operator of this layer rotated by ``angle`` (radians) about the normal:
        ``Rot(angle) B Rot(-angle)``, i.e. ``f_{d,s} exp(-2 i s angle)``."""
        if angle == 0.0:
            return self
        blocks = {name: None if mat is None else rotate_block(mat, self.md, self.h, angle)
                  for name, mat in self.blocks.items()}
        return AnisoOperator(self.grid, self.md, blocks, self.eta_top, self.eta_bottom,
                             self.delta)

    def pruned(self, relerr: float) -> "AnisoOperator":
        """This operator made exactly reciprocal and without the coefficients below ``relerr``
        times the largest of their ordinate pair (:func:`reciprocal_prune`)."""
        blocks = dict(self.blocks)
        reciprocal_prune(blocks, self.grid, self.md, self.eta_top, self.eta_bottom,
                         self.delta, relerr)
        return AnisoOperator(self.grid, self.md, blocks, self.eta_top, self.eta_bottom,
                             self.delta)

    def consume(self) -> None:
        """Give up this operator's blocks (for callers that hand an operator over and free its
        memory as it is used, :func:`layersim.aniso.adding.add` with ``consume=True``): any
        later use of it raises."""
        self.blocks = dict.fromkeys(self.blocks)
        self.consumed = True

    # ---- coefficients ------------------------------------------------------------------

    def coefficients(self, name: str) -> sps.csr_matrix:
        """``G = B / (2 pi w_i |mu_i|)`` of block ``name`` (1/sr), same layout as the block:
        ``f = sum_{a,b} G[a h + o, b h + i] u_a(phi_o) v_b(phi_i)`` (see
        :mod:`layersim.aniso.basis`)."""
        fw = np.tile(self.grid.flux_weight, self.slots)
        return sps.csr_matrix(self.block(name) @ sps.diags(1.0 / (2.0 * np.pi * fw)))

    def albedo_slots(self) -> dict:
        """Energy fractions per incident slot and node: ``{"Rt": (S, h), ...}``.

        ``E[b, i] = sum_o B[0 h + o, b h + i] w_o mu_o / (w_i mu_i)``: a collimated beam from
        node ``i`` at propagation azimuth ``phi_i`` delivers ``sum_b E[b, i] v_b(phi_i)``
        (``v = (1, 2 cos k phi, 2 sin k phi)``) through the block's side; slot 0 alone is the
        energy for azimuthally uniform illumination.
        """
        fw = self.grid.flux_weight
        h = self.h
        out = {}
        for name, mat in self.blocks.items():
            if mat is None:
                continue
            row0 = mat.head if isinstance(mat, Parked) else mat[:h]
            if row0 is None or row0.shape[0] != h:
                raise OperatorError(f"block {name} is parked without its slot-0 rows")
            out[name] = ((row0.T @ fw) / np.tile(fw, self.slots)).reshape(self.slots, h)
        return out

    # ---- persistence -------------------------------------------------------------------

    def to_arrays(self, prefix: str = "") -> dict:
        d = header_arrays(self, prefix)
        d.update({f"{prefix}representation": np.array("anisotropic"),
                  f"{prefix}md": np.array(self.md), f"{prefix}ms": np.array(self.ms)})
        write_blocks(d, prefix, {name: mat for name, mat in self.blocks.items()
                                 if mat is not None})
        return d

    @classmethod
    def from_arrays(cls, d, prefix: str = "") -> "AnisoOperator":
        try:
            grid = Grid.make(str(d[f"{prefix}rule"]), int(d[f"{prefix}n"]))
            md, ms = int(d[f"{prefix}md"]), int(d[f"{prefix}ms"])
            eb = float(d[f"{prefix}eta_bottom"])
            N = basis.n_slots(md) * grid.h
            blocks = read_blocks(d, prefix, (N, N))
            delta = read_delta(d, prefix)
            op = cls(grid, md, blocks, float(d[f"{prefix}eta_top"]),
                     None if np.isnan(eb) else eb, delta, ms=ms)
        except (KeyError, ValueError, TypeError, OperatorError) as exc:
            raise FileFormatError(f"not a layersim anisotropic operator ({exc})") from None
        return op


def rotate_block(mat, md: int, h: int, angle: float) -> sps.csr_matrix:
    """One block of :meth:`AnisoOperator.rotated`: ``Rot(angle) B Rot(-angle)``."""
    if angle == 0.0:
        return mat
    rot = basis.rotation_matrix(md, h, angle)
    inv = basis.rotation_matrix(md, h, -angle)
    return prune(rot @ mat @ inv)


def slot_column_scale(grid: Grid, md: int) -> np.ndarray:
    """``D / (w |mu|)`` per unknown, shape (S h,): the column scale that turns a block ``B``
    into ``S = G D`` up to ``2 pi`` (``G`` the coefficients, ``D`` the slot scale of
    :func:`reciprocity_error`), in which reciprocity is a transpose."""
    return np.repeat(basis.slot_scale(md), grid.h) / np.tile(grid.flux_weight,
                                                              basis.n_slots(md))


def reciprocal_prune(blocks: dict, grid: Grid, md: int, eta_top: float,
                     eta_bottom: float | None, delta: dict, relerr: float,
                     directory: str | None = None) -> None:
    """Make the blocks of an operator exactly reciprocal and drop the coefficients below
    ``relerr`` times the largest of their ordinate pair, in place (``blocks`` is the
    ``{name: csr}`` dict of :class:`AnisoOperator`, a block possibly given as
    :class:`~layersim.aniso.rowpieces.RowPieces`, and CSR on return; each block is replaced
    as soon as its successor is formed, so a caller holding no other reference frees it
    then). This is the truncation that the coupled projection applies to each pair (see
    :data:`layersim.aniso.plan.COUPLED_RELERR`).

    In ``S = G D / eta^2`` (``G`` the coefficients, ``D`` the slot scale of
    :func:`reciprocity_error`, ``eta`` the index of the side light leaves to) reciprocity
    reads ``S_Rt = S_Rt^T``, ``S_Rb = S_Rb^T``, ``S_Ttb^T = S_Tbt``. An operator computed
    from truncated intermediates (:func:`layersim.aniso.adding.add` with ``relerr``) obeys
    it to about the truncation only; replacing ``S`` by the mean of ``S`` and its mirror
    image restores it exactly and, the exact operator being reciprocal, does not increase
    the error. Magnitudes are then compared on ``S``: an entry and its reciprocal are
    compared with the same pair maximum (over the pair and its mirror), so both are kept
    or both dropped. The unscattered beam on the diagonal of the transmission blocks
    (``delta``) is always kept and does not count in the maximum.

    With ``directory`` the means of the reflection blocks and the pruned blocks wait in files
    there between their passes (:func:`sum_pieces`), so that a reflection block, its image
    and their mean are never resident together.
    """
    h = grid.h
    col_scale = slot_column_scale(grid, md)            # B -> G D (no 2 pi)
    for name in ("Rt", "Rb"):           # pieces of the mean, pruned below
        if blocks.get(name) is not None:
            blocks[name] = with_reciprocal_image(blocks.pop(name), h, col_scale, 0.5, 0.5,
                                                 directory=directory)
    if blocks.get("Ttb") is not None:
        ratio = (eta_bottom / eta_top) ** 2
        image = reciprocal_image(blocks["Tbt"], h, col_scale, ratio)
        blocks["Ttb"] = sum_pieces(blocks.pop("Ttb"), image, 0.5, 0.5).to_csr(release=True)
        del image
        blocks["Tbt"] = reciprocal_image(blocks["Ttb"], h, col_scale, 1.0 / ratio)
    # reflection blocks are symmetric on their own; Ttb / eta_b^2 mirrors Tbt / eta_t^2;
    # per-entry quantities are formed in chunks of rows (the blocks of a coupled stack
    # have millions of entries)
    eta = {"Rt": 1.0, "Rb": 1.0, "Ttb": eta_bottom, "Tbt": eta_top}
    for first, second in (("Rt", None), ("Rb", None), ("Ttb", "Tbt")):
        parts = [(name, flip, RowPieces.of(blocks[name]))
                 for name, flip in ((first, False), (second, True))
                 if name is not None and blocks.get(name) is not None]

        def keyed(name, flip, piece, start, lo, hi, rows, one=second is None):
            cols = piece.indices[lo:hi]
            rows = rows + start
            o, i = rows % h, cols % h
            if one:                     # one symmetric block: unordered pairs
                o, i = np.minimum(o, i), np.maximum(o, i)
            elif flip:                  # Tbt[y, x] pairs with Ttb[x, y]
                o, i = i, o
            mag = np.abs(piece.data[lo:hi]) * col_scale[cols] / eta[name] ** 2
            beam = (rows == cols) if name in delta else np.zeros(hi - lo, bool)
            return o.astype(np.int64) * h + i, mag, beam

        big = np.zeros(h * h)
        for name, flip, mat in parts:
            for start, piece in mat:
                for lo, hi, rows in _row_chunks(piece):
                    key, mag, beam = keyed(name, flip, piece, start, lo, hi, rows)
                    np.maximum.at(big, key[~beam], mag[~beam])
        for name, flip, mat in parts:
            kept = RowPieces(mat.shape, directory)
            for start, piece in mat:
                keep = np.empty(piece.nnz, bool)
                for lo, hi, rows in _row_chunks(piece):
                    key, mag, beam = keyed(name, flip, piece, start, lo, hi, rows)
                    keep[lo:hi] = beam | (mag >= relerr * big[key])
                piece = _select(piece, keep)
                kept.append(start, piece.indptr, piece.indices, piece.data)
            blocks[name] = None
            mat.close()
            blocks[name] = kept.to_csr(release=True)
        parts = mat = piece = None


def as_aniso(op, md: int | None = None) -> AnisoOperator:
    """``op`` as an :class:`AnisoOperator` with ``md`` orders (isotropic operators are
    converted: block diagonal, no coupling)."""
    if isinstance(op, AnisoOperator):
        return op if md is None else op.with_md(md)
    if isinstance(op, IsoOperator):
        return AnisoOperator.from_iso(op, md)
    raise TypeError(f"expected an IsoOperator or AnisoOperator, got {type(op).__name__}")


#: Entries copied by :func:`from_parts` and :func:`_stack_rows` between two returns of freed
#: heap pages (:func:`layersim.memory.release`; 48 MiB of indices and values).
RELEASE_ENTRIES = 1 << 22


def _csr_arrays(n_rows: int, n_cols: int, total: int):
    """Zero row pointers and uninitialised indices and values for a CSR matrix of ``total``
    entries, with 32-bit indices where they fit (scipy would otherwise copy them down)."""
    index_type = np.int32 if max(total, n_cols) < 2**31 else np.int64
    return np.zeros(n_rows + 1, index_type), np.empty(total, index_type), np.empty(total)


def _trim(placed: int, trimmed: int) -> int:
    """Return the freed heap pages (:func:`layersim.memory.release`) once
    :data:`RELEASE_ENTRIES` more entries were placed since the last time (``trimmed``); the
    count at the last release. The parts and pieces that assemblies copy from are small arrays
    from the heap, whose freed pages stay resident until trimmed: without this, assembling
    ``K`` held two copies of it."""
    if placed - trimmed > RELEASE_ENTRIES:
        memory.release()
        return placed
    return trimmed


#: Entries per chunk of :func:`_row_chunks` (its per-entry temporaries: ~16 MiB per array).
CHUNK_ENTRIES = 1 << 21


def _row_chunks(mat: sps.csr_matrix, entries: int = CHUNK_ENTRIES):
    """``(lo, hi, rows)`` for chunks of rows of a CSR matrix holding about ``entries`` entries
    (one row at least): its entries ``lo:hi`` and their rows. Per-entry index arrays of the
    operators of coupled stacks (tens of millions of entries) took more memory than the
    matrices themselves when formed at once, and chunks of a fixed number of rows still took
    300 MiB on ``K`` of Table 2 row 6 of seed 000 (320 entries per row)."""
    for start, stop in row_spans(mat.indptr, 0, mat.shape[0], entries):
        ptr = mat.indptr[start:stop + 1]
        yield int(ptr[0]), int(ptr[-1]), np.repeat(np.arange(start, stop), np.diff(ptr))


def from_parts(parts, shape: tuple, fmt: str = "csr", select=None):
    """Sparse matrix of shape ``shape`` from ``parts``, a list or a
    :class:`~layersim.aniso.park.Spool` of ``(rows, cols, values)`` triplets (duplicates are
    summed), ``parts`` emptied.

    The matrices of coupled stacks hold tens of millions of entries, and the parts are
    scattered straight into the CSR arrays (counting sort by row), each part released (and
    the heap trimmed, :func:`_trim`) as it is placed, with no concatenated or COO copy: on the
    coating blocks of Table 2 row 6 of seed 000 (7-9 M entries) the resident memory now falls
    by 12-190 MiB across the assembly, where the concatenation and COO -> CSR conversion it
    replaces raised it by 88-105 MiB.

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
    indptr, indices, data = _csr_arrays(n_rows, n_cols, int(counts.sum()))
    np.cumsum(counts, out=indptr[1:])
    del counts
    fill = indptr[:-1].astype(np.int64)              # next free position of each row
    placed = trimmed = 0
    for part in (parts.drain() if isinstance(parts, Spool) else _drain(parts)):
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
        trimmed = _trim(placed, trimmed)
    out = sps.csr_matrix((data, indices, indptr), shape=(n_rows, n_cols))
    out.sum_duplicates()            # sorts each row and sums its duplicates in place
    return out.T if by_col else out


def _drain(items: list):
    """Iterate over a list, releasing each item as it is handed out (the list is emptied)."""
    for k in range(len(items)):
        item, items[k] = items[k], None
        yield item
        del item
    items.clear()


def reciprocal_image(mat, h: int, col_scale: np.ndarray, factor: float = 1.0,
                     skip_diagonal: bool = False) -> sps.csr_matrix:
    """``factor * diag(c) mat^T diag(1 / c)``: the block that reciprocity pairs with ``mat``
    (``c = col_scale``, the slot scale over the flux weights, see
    :meth:`AnisoOperator.pruned`), formed from one transposed copy scaled in place.

    Parameters
    ----------
    mat : sparse (N, N) or RowPieces
        Read piece by piece if given as :class:`~layersim.aniso.rowpieces.RowPieces` (see
        :func:`_transposed`).
    h : int
        Ordinates per slot.
    col_scale : ndarray (N,)
    factor : float
    skip_diagonal : bool
        Leave out the entries of the ordinate pairs ``o == i`` (the image of one triangle of
        pairs, to be added to that triangle).
    """
    t = _transposed(mat)
    for lo, hi, rows in _row_chunks(t):
        cols = t.indices[lo:hi]
        part = t.data[lo:hi]
        part *= factor * col_scale[rows] / col_scale[cols]
        if skip_diagonal:
            part[rows % h == cols % h] = 0.0
    if skip_diagonal:
        t.eliminate_zeros()
    return t


def _transposed(mat) -> sps.csr_matrix:
    """``mat^T`` in CSR. A matrix in a file (:class:`~layersim.aniso.rowpieces.RowPieces`) is
    transposed by a counting sort over its pieces, read twice (column counts, then each
    piece's entries scattered to their rows of the transpose), so that only the transpose
    and one piece are resident; the one conversion of scipy (C++) otherwise."""
    if isinstance(mat, RowPieces) and mat.wrapped is not None:
        mat = mat.wrapped
    if not isinstance(mat, RowPieces):
        return sps.csc_matrix(mat).T.tocsr()     # the CSC -> CSR conversion makes the copy
    n_rows, n_cols = mat.shape
    counts = np.zeros(n_cols, np.int64)
    for _, piece in mat:
        counts += np.bincount(piece.indices, minlength=n_cols)
    indptr, indices, data = _csr_arrays(n_cols, n_rows, int(counts.sum()))
    np.cumsum(counts, out=indptr[1:])
    free = indptr[:-1].astype(np.int64)          # next free place in each row of mat^T
    for start, piece in mat:
        by_col = piece.tocsc()                   # rows ascending within each column
        del piece
        n = np.diff(by_col.indptr)
        col = np.repeat(np.arange(n_cols, dtype=np.int32), n)
        at = free[col] + (np.arange(by_col.nnz) - by_col.indptr[col])
        indices[at] = by_col.indices + start
        data[at] = by_col.data
        free += n
        del by_col, col, at
    return sps.csr_matrix((data, indices, indptr), shape=(n_cols, n_rows))


def with_reciprocal_image(mat, h: int, col_scale: np.ndarray, alpha: float, beta: float,
                          skip_diagonal: bool = False,
                          directory: str | None = None) -> RowPieces:
    """``alpha mat + beta reciprocal_image(mat)`` (:func:`reciprocal_image`) in pieces of rows
    (:func:`sum_pieces`), for the mean of a reflection block and its image and for a block
    projected on one triangle of ordinate pairs.

    With ``directory`` the matrix is first written there piece by piece and its image built
    from the file (:func:`_transposed`), so that ``mat``, its image and their sum are never
    resident together: the caller hands ``mat`` over (no reference of its own left) and
    assembles the result once this returns (``to_csr(release=True)``). On Table 2 row 6 of
    seed 000 the result's mean with its image held 3 x 180 MiB at once.
    """
    mat = RowPieces.written(mat, directory)
    image = reciprocal_image(mat, h, col_scale, skip_diagonal=skip_diagonal)
    out = sum_pieces(mat, image, alpha, beta, directory)
    mat.close()
    return out


def slot_pairs(mat, h: int, columns=None):
    """Distinct ``(row slot, column slot)`` pairs holding entries of the CSR matrix ``mat``
    (slots of ``h`` rows / columns), optionally only entries in the columns where the boolean
    mask ``columns`` is true.

    ``mat`` may also be a :class:`~layersim.aniso.rowpieces.RowPieces` (read piece by piece).

    Returns
    -------
    rows, cols : int ndarray
    """
    pieces = mat if isinstance(mat, RowPieces) else [(0, sps.csr_matrix(mat))]
    mark = np.zeros((-(-mat.shape[0] // h), -(-mat.shape[1] // h)), bool)
    for start, piece in pieces:
        for lo, hi, rows in _row_chunks(piece):
            cols = piece.indices[lo:hi]
            if columns is not None:
                sel = columns[cols]
                rows, cols = rows[sel], cols[sel]
            mark[(rows + start) // h, cols // h] = True
    return np.nonzero(mark)


def prune_pairs(mat, h: int, relerr: float) -> sps.csr_matrix:
    """Drop the entries of ``mat`` below ``relerr`` times the largest entry of their ordinate
    pair ``(row % h, col % h)`` over all slots (CSR copy): the truncation of each pair's
    coefficients that the coupled projection applies
    (:data:`layersim.aniso.plan.COUPLED_RELERR`), for the intermediate products of the
    adding equations. See :meth:`AnisoOperator.pruned` for operators (reciprocity kept)."""
    mat = sps.csr_matrix(mat)
    big = np.zeros(h * h)
    key = lambda lo, hi, rows: (rows % h) * h + mat.indices[lo:hi] % h
    for lo, hi, rows in _row_chunks(mat):
        np.maximum.at(big, key(lo, hi, rows), np.abs(mat.data[lo:hi]))
    keep = np.empty(mat.nnz, bool)
    for lo, hi, rows in _row_chunks(mat):
        keep[lo:hi] = np.abs(mat.data[lo:hi]) >= relerr * big[key(lo, hi, rows)]
    return _select(mat, keep)


def _select(mat: sps.csr_matrix, keep: np.ndarray) -> sps.csr_matrix:
    """The entries of the CSR matrix ``mat`` where the boolean ``keep`` (nnz,) is true."""
    kept = np.concatenate([[0], np.cumsum(keep)])
    return sps.csr_matrix((mat.data[keep], mat.indices[keep], kept[mat.indptr]),
                          shape=mat.shape)


class PairPruner:
    """A filter for a stream of entries ``(rows, cols, values)`` that ends with the result of
    :func:`prune_pairs` of all of them, without holding them all unpruned.

    Calling it keeps the entries of a part not below ``relerr`` times the largest magnitude
    of their ordinate pair ``(row % h, col % h)`` seen so far (this part included): every
    entry it drops is dropped by :func:`prune_pairs` of the whole. :meth:`final_filter` then filters
    the kept parts against the largest magnitudes of the whole stream, which are exactly those
    of :func:`prune_pairs` (the largest entries are never dropped).
    """

    def __init__(self, h: int, relerr: float):
        self.h, self.relerr = int(h), float(relerr)
        self.big = np.zeros(self.h * self.h)

    def _filter(self, rows, cols, vals, update: bool):
        key = (rows % self.h).astype(np.int64) * self.h + cols % self.h
        mag = np.abs(vals)
        if update:
            np.maximum.at(self.big, key, mag)
        sel = mag >= self.relerr * self.big[key]
        return rows[sel], cols[sel], vals[sel]

    def __call__(self, rows, cols, vals):
        return self._filter(rows, cols, vals, True)

    def final_filter(self, rows, cols, vals):
        """One part (filtered by earlier calls) pruned against the whole stream's maxima."""
        return self._filter(rows, cols, vals, False)


#: Bound on the multiply-adds of one chunk of :func:`pruned_product` (it bounds the chunk's
#: unpruned entries whatever the operators' size): on Table 2 row 6 of seed 000,
#: ``K = Rt2 Rb1`` (21.6 M entries kept of 50 M, 14.6 G multiply-adds, 330 chunks) took 609 MiB
#: above its operands in 16 equal chunks of rows and 363 MiB in chunks of this bound with the
#: heap trimmed during assembly (:func:`_trim`), in the same time (22 s).
PRODUCT_CHUNK_FLOPS = 1 << 25


def product_row_chunks(a: sps.csr_matrix, b: sps.csr_matrix,
                       flops: int = PRODUCT_CHUNK_FLOPS) -> list:
    """Starts of the row chunks of ``a`` whose products with ``b`` take at most ``flops``
    multiply-adds each (one row at least), which bounds the entries of each chunk's unpruned
    product (ends with ``a.shape[0]``)."""
    per_entry = np.diff(b.indptr).astype(np.int64)
    bound = np.zeros(a.shape[0] + 1, np.int64)     # multiply-adds of rows 0 .. r-1
    for lo, hi, rows in _row_chunks(a):
        if hi > lo:
            np.add.at(bound, rows + 1, per_entry[a.indices[lo:hi]])
    np.cumsum(bound, out=bound)
    starts, at = [0], 0
    while at < a.shape[0]:
        nxt = int(np.searchsorted(bound, bound[at] + flops, side="right")) - 1
        at = max(at + 1, min(nxt, a.shape[0]))
        starts.append(at)
    return starts


def csr_product(a: sps.csr_matrix, lo: int, hi: int, b: sps.csr_matrix) -> tuple:
    """CSR arrays ``(indptr, indices, data)`` of ``a[lo:hi] @ b``, equal to scipy's product
    (the same routine, entries in the same order).

    SciPy's product runs a symbolic pass to size its output (``csr_matmat_maxnnz``: 11.6 of
    30.6 s of ``Rt @ Rb`` of the coating of Table 2 row 6 of seed 000 on one thread) before
    the numeric one. Here the output is sized by the multiply-adds of the rows instead, an
    upper bound on its entries, and left uninitialised: the pages past the entries written
    are never touched, so they take address space, not memory (the returned arrays are views
    of those buffers: callers that keep them copy them; where the address space is refused
    the product is sized exactly as SciPy does). The rows of ``a`` are read in place (no
    copy of the slice). Without SciPy's ``_sparsetools.csr_matmat`` (a private
    module) this falls back to the public product.
    """
    a0, a1 = int(a.indptr[lo]), int(a.indptr[hi])
    indices, data = a.indices[a0:a1], a.data[a0:a1]
    flops = int(np.diff(b.indptr)[indices].sum(dtype=np.int64))
    bound = min(flops, (hi - lo) * b.shape[1])

    def exact():
        """SciPy's product (symbolic pass, output sized exactly)."""
        rows = sps.csr_matrix((data, indices, a.indptr[lo:hi + 1] - a0),
                              shape=(hi - lo, a.shape[1]))
        c = sps.csr_matrix(rows @ b)
        return c.indptr, c.indices, c.data

    try:
        from scipy.sparse._sparsetools import csr_matmat
    except ImportError:                                     # pragma: no cover
        return exact()
    big = max(bound, a1 - a0, b.nnz, b.shape[1], hi - lo)
    idx = np.int32 if big < np.iinfo(np.int32).max else np.int64
    ptr = np.empty(hi - lo + 1, idx)
    if bound == 0:
        ptr[:] = 0
        return ptr, np.zeros(0, idx), np.zeros(0, np.result_type(a.data, b.data))
    try:
        cols = np.empty(bound, idx)
        vals = np.empty(bound, np.result_type(a.data, b.data))
    except MemoryError:     # address space refused (strict overcommit)
        return exact()
    csr_matmat(hi - lo, b.shape[1], (a.indptr[lo:hi + 1] - a0).astype(idx),
               indices.astype(idx, copy=False), data, b.indptr.astype(idx, copy=False),
               b.indices.astype(idx, copy=False), b.data, ptr, cols, vals)
    n = int(ptr[-1])
    return ptr, cols[:n], vals[:n]


def _int32_indices(mat: sps.csr_matrix) -> sps.csr_matrix:
    """``mat`` with 32-bit index arrays where its entries and columns allow (as is)."""
    if mat.indptr.dtype == np.int32 and mat.indices.dtype == np.int32:
        return mat
    if max(mat.nnz, mat.shape[1]) >= np.iinfo(np.int32).max:
        return mat
    return sps.csr_matrix((mat.data, mat.indices.astype(np.int32),
                           mat.indptr.astype(np.int32)), shape=mat.shape)


def pruned_product(a, b, h: int, relerr: float | None, pieces: bool = False,
                   directory: str | None = None):
    """``prune_pairs(a @ b, h, relerr)`` (``a @ b`` itself with ``relerr`` None, entries in
    SciPy's order) without holding the unpruned product: it is formed
    in chunks of rows of ``a`` of at most :data:`PRODUCT_CHUNK_FLOPS` multiply-adds
    (:func:`product_row_chunks`), each filtered by :class:`PairPruner` as it comes (on
    Table 2 row 7 of seed 000 the product ``Rt2 Rb1`` had several times the entries it
    keeps). The chunks are kept as CSR pieces and copied into the result one by one, each
    released as it is copied: the result's pages become resident as the pieces are freed, so
    that the assembly needs about one copy of the result (12 bytes per entry) instead of the
    three of a COO -> CSR conversion (44 bytes per entry).

    With ``pieces`` the result is a :class:`~layersim.aniso.rowpieces.RowPieces` instead,
    its pieces written to a file in ``directory`` as they are formed (kept in memory without
    one) and never assembled: only the operands and the pieces in flight are resident (for
    ``K`` of the adding equations, which the banded solve reads piece by piece).

    ``a`` may be given as :class:`~layersim.aniso.rowpieces.RowPieces` (e.g. in a file), read
    piece by piece: then only ``b`` is resident whole."""
    from ..threads import THREADS, parallel_map
    b = _int32_indices(sps.csr_matrix(b))       # converted once, not per chunk (csr_product)
    keep = None if relerr is None else PairPruner(h, relerr)
    shape = (a.shape[0], b.shape[1])
    store = RowPieces(shape, directory) if pieces else None
    kept = []
    formed = trimmed = 0
    for offset, rows in (a if isinstance(a, RowPieces) else [(0, sps.csr_matrix(a))]):
        bounds = product_row_chunks(rows, b)
        chunks = list(zip(bounds[:-1], bounds[1:]))
        for at in range(0, len(chunks), THREADS):      # THREADS chunks in flight at a time
            batch = chunks[at:at + THREADS]
            parts = parallel_map(lambda c, rows=rows: csr_product(rows, c[0], c[1], b),
                                 batch)
            for (start, _), part in zip(batch, parts):
                formed += part[1].size
                piece = _filter_piece(keep, offset + start, *part, True)
                if store is None:
                    kept.append(piece)
                else:
                    store.append(*piece)
            del parts, part, piece
            # the chunks' temporaries come from the heap, whose freed pages otherwise pile
            # up (K on Table 2 row 6 of seed 000: +135 MiB over the product written to a file)
            trimmed = _trim(formed, trimmed)
        del rows
    final = (lambda *piece: piece) if keep is None else \
        (lambda *piece: _filter_piece(keep, *piece, False))
    if store is not None:
        out = store.filtered(final)
    else:
        for k in range(len(kept)):
            kept[k] = final(*kept[k])
        out = _stack_rows(kept, shape)
    memory.release()                # the chunks' products and pieces came from the heap
    return out


def _filter_piece(keep: "PairPruner | None", start: int, indptr, indices, data, update: bool):
    """One CSR piece of rows ``start ..`` filtered by ``keep`` (``update``: also record its
    pair maxima; None keeps every entry), as ``(start, indptr, indices, data)`` with 32-bit
    indices."""
    if keep is None:        # copies: csr_product's arrays are views of larger buffers
        return start, np.asarray(indptr, np.int64), indices.astype(np.int32), data.copy()
    rows = np.repeat(np.arange(start, start + indptr.size - 1, dtype=np.int32), np.diff(indptr))
    r, c, v = keep._filter(rows, indices, data, update)
    counts = np.bincount(r - start, minlength=indptr.size - 1)
    ptr = np.zeros(indptr.size, np.int64)
    np.cumsum(counts, out=ptr[1:])
    return start, ptr, c.astype(np.int32, copy=False), v


def _stack_rows(pieces, shape: tuple, total: int | None = None) -> sps.csr_matrix:
    """CSR matrix from consecutive row pieces ``(start, indptr, indices, data)``: a list
    (emptied, each piece released as soon as it is copied), or any iterable of them with
    their ``total`` entries (e.g. read one by one from a file)."""
    if total is None:
        total = int(sum(p[1][-1] for p in pieces))
    indptr, indices, data = _csr_arrays(shape[0], shape[1], int(total))
    at = trimmed = 0
    for start, ptr, c, v in (_drain(pieces) if isinstance(pieces, list) else pieces):
        n = int(ptr[-1])
        indptr[start + 1:start + ptr.size] = at + ptr[1:]
        indices[at:at + n], data[at:at + n] = c, v
        at += n
        del ptr, c, v
        trimmed = _trim(at, trimmed)
    np.maximum.accumulate(indptr, out=indptr)         # rows of no piece: empty
    return sps.csr_matrix((data, indices, indptr), shape=shape)


def sum_pieces(a, b, alpha: float = 1.0, beta: float = 1.0,
               directory: str | None = None) -> RowPieces:
    """``alpha a + beta b`` as :class:`~layersim.aniso.rowpieces.RowPieces`, summed in chunks
    of rows of about :data:`CHUNK_ENTRIES` entries (read piece by piece of ``a`` if it is
    given as RowPieces), kept in a file in ``directory`` (in memory without one): the caller
    releases ``a`` and ``b`` before assembling the sum (``to_csr(release=True)``), which then
    takes the result's memory only, where a sum formed at once holds both operands beside it
    (on Table 2 row 6 of seed 000, ``Rt1 + Tbt1 Z1``: 3 x 170 MiB)."""
    b = sps.csr_matrix(b)
    if a.shape != b.shape:
        raise ValueError(f"sum_pieces: shapes {a.shape} and {b.shape} differ")
    out = RowPieces(a.shape, directory)
    for start, stop, rows in _summed_rows(a, b):
        part = beta * b[start:stop]
        part = sps.csr_matrix(part if rows is None else alpha * rows + part)
        out.append(start, part.indptr, part.indices, part.data)
        del part, rows
    return out


def _summed_rows(a, b):
    """``(start, stop, rows of a or None)`` over all rows for :func:`sum_pieces`: spans of
    about :data:`CHUNK_ENTRIES` entries of ``a + b``, within the pieces of ``a`` if it is
    given as RowPieces (and over the rows between them, ``a`` empty there)."""
    if isinstance(a, RowPieces) and a.wrapped is not None:
        a = a.wrapped
    n = a.shape[0]
    if not isinstance(a, RowPieces):
        a = sps.csr_matrix(a)
        both = a.indptr.astype(np.int64) + b.indptr
        for start, stop in row_spans(both, 0, n, CHUNK_ENTRIES):
            yield start, stop, a[start:stop]
        return
    done = 0
    for start, piece in a:
        for span in row_spans(b.indptr, done, start, CHUNK_ENTRIES):
            yield *span, None
        done = start + piece.shape[0]
        both = piece.indptr.astype(np.int64) + (b.indptr[start:done + 1] - b.indptr[start])
        for lo, hi in row_spans(both, 0, piece.shape[0], CHUNK_ENTRIES):
            yield start + lo, start + hi, piece[lo:hi]
        del piece
    for span in row_spans(b.indptr, done, n, CHUNK_ENTRIES):
        yield *span, None


def prune(mat, tolerance: float = DROP_TOLERANCE):
    """Drop entries below ``tolerance`` times the largest magnitude of ``mat``.

    A CSR matrix is pruned in place (pass a temporary) and returned; other formats are
    converted. :class:`~layersim.aniso.rowpieces.RowPieces` are pruned piece by piece (one
    pass for the largest magnitude, one to filter) into new RowPieces, these emptied."""
    if isinstance(mat, RowPieces) and mat.wrapped is None:
        cut = tolerance * max((np.abs(p.data).max() for _, p in mat if p.nnz), default=0.0)

        def drop(start, indptr, indices, data):
            piece = _drop_below(sps.csr_matrix((data, indices, indptr),
                                               shape=(indptr.size - 1, mat.shape[1])), cut)
            return start, piece.indptr, piece.indices, piece.data
        return mat.filtered(drop)
    mat = sps.csr_matrix(mat.wrapped if isinstance(mat, RowPieces) else mat)
    return _drop_below(mat, tolerance * np.abs(mat.data).max()) if mat.nnz else mat


def _drop_below(mat: sps.csr_matrix, cut: float) -> sps.csr_matrix:
    """``mat`` without its entries of magnitude below ``cut`` (in place)."""
    mat.data[np.abs(mat.data) < cut] = 0.0
    mat.eliminate_zeros()
    return mat


def reciprocity_error(op: AnisoOperator) -> float:
    """Largest violation of reciprocity, relative to the largest coefficient.

    In the complex basis reciprocity reads ``f_{d,s}(o <- i) = f_{-d,s}(i <- o)`` (reversing
    both propagation directions turns ``phi_i, phi_o`` into ``phi_o + pi, phi_i + pi``), i.e.
    ``G_{l,k}[o,i] = conj(G_{k,l}[i,o])``; in the real basis ``G^T = D^-1 G D`` with
    ``D = diag(1, 2, 2, ...)`` per slot (:func:`basis.slot_scale`). Transmission obeys the
    radiance-convention version ``G_tb / eta_b^2 = (G_bt / eta_t^2)^T``.
    """
    scale_slot = basis.slot_scale(op.md)
    D = sps.diags(np.repeat(scale_slot, op.h))
    Dinv = sps.diags(1.0 / np.repeat(scale_slot, op.h))
    G = {name: op.coefficients(name) for name, m in op.blocks.items() if m is not None}
    big = max(abs(g).max() for g in G.values()) + 1e-300
    worst = 0.0
    for name in ("Rt", "Rb"):
        if name in G:
            g = G[name]
            worst = max(worst, abs(g.T - Dinv @ g @ D).max() / big)
    if "Ttb" in G:
        diff = (G["Ttb"] / op.eta_bottom ** 2).T - Dinv @ (G["Tbt"] / op.eta_top ** 2) @ D
        worst = max(worst, abs(diff).max() / big)
    return float(worst)
