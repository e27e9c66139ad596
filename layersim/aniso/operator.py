"""Scattering operators with coupled Fourier modes (anisotropic layers and stacks).

An :class:`AnisoOperator` holds the four blocks ``Rt, Rb, Ttb, Tbt`` of Zeltner & Jakob 2018
sec. 3.2 (same meaning and solver convention as :class:`~layersim.operators.operator.IsoOperator`:
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

from ..errors import FileFormatError, OperatorError
from ..operators.operator import (BLOCKS, DROP_TOLERANCE, Grid, IsoOperator, Operator,
                                  header_arrays, read_blocks, read_delta, register, write_blocks)
from ..outofcore import memory
from ..outofcore.assemble import select_entries
from ..outofcore.parking import Parked
from ..outofcore.rowpieces import RowPieces
from ..outofcore.rows import row_chunks
from ..outofcore.sums import prune as prune_below, sum_pieces
from . import basis
from .pairs import slot_pairs
from .reciprocity import reciprocal_image, with_reciprocal_image


@register
class AnisoOperator(Operator):
    """Operator of an anisotropic layer or stack in the real slot basis (module docstring);
    implements :class:`layersim.operators.operator.Operator`.

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
        The delta part of each block per node, ``{block: (h,)}`` (:mod:`layersim.operators.deltas`).
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
        self.delta = {k: np.asarray(v, float) for k, v in (delta or {}).items()
                      if v is not None and self.blocks.get(k) is not None}
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
                                "consumes this operator (layersim.outofcore.parking)")
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
        (:mod:`layersim.solved.sampling`).
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
    :class:`~layersim.outofcore.rowpieces.RowPieces`, and CSR on return; each block is replaced
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
                for lo, hi, rows in row_chunks(piece):
                    key, mag, beam = keyed(name, flip, piece, start, lo, hi, rows)
                    np.maximum.at(big, key[~beam], mag[~beam])
        for name, flip, mat in parts:
            kept = RowPieces(mat.shape, directory)
            for start, piece in mat:
                keep = np.empty(piece.nnz, bool)
                for lo, hi, rows in row_chunks(piece):
                    key, mag, beam = keyed(name, flip, piece, start, lo, hi, rows)
                    keep[lo:hi] = beam | (mag >= relerr * big[key])
                piece = select_entries(piece, keep)
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


def prune(mat, tolerance: float = DROP_TOLERANCE):
    """Drop entries below ``tolerance`` times the largest magnitude of ``mat``
    (:func:`layersim.outofcore.sums.prune`, with :data:`layersim.operators.operator.DROP_TOLERANCE`
    by default)."""
    return prune_below(mat, tolerance)


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
