"""Discrete scattering operators of isotropic layers in the cosine basis.

Representation (Jakob's layerlab tutorial eq. (10), (14); Zeltner & Jakob 2018 eq. (5))
-----------------------------------------------------------
The solver uses the discrete-ordinates convention: ``mu > 0`` propagates deeper into the stack
(downwards), ``mu < 0`` towards the top. Radiance is expanded in azimuth as
``L(mu, phi) = sum_l L_l(mu) cos(l phi)`` and sampled at the ``h = n/2`` positive nodes ``mu_j``
of a :class:`Grid` (the same nodes serve both hemispheres). A layer maps incident to scattered
radiance independently for every order ``l``::

    L_out,l[o] = sum_i B_l[o, i] L_in,l[i],      B_l[o, i] = c_l f_l(mu_o, mu_i) w_i |mu_i|

with ``c_0 = 2 pi``, ``c_l = pi`` (l >= 1) and ``f(mu_i, mu_o, phi) = sum_l f_l cos(l phi)`` the
BSDF (1/sr, radiance convention) between *propagation* directions, ``phi`` the azimuth difference
of the propagation directions (``phi = 0`` is specular or straight-through).

Per order there are four ``h x h`` blocks, indexed ``[outgoing node, incident node]``:

=======  ===========================  =============================
block    incident                     outgoing
=======  ===========================  =============================
``Rt``   top, propagating down        leaves the top (up)
``Rb``   bottom, propagating up       leaves the bottom (down)
``Ttb``  top, propagating down        leaves the bottom (down)
``Tbt``  bottom, propagating up       leaves the top (up)
=======  ===========================  =============================

An opaque operator (bottom layer is a conductor or a diffuse base) stores ``Rt`` only; the other
blocks are ``None`` ("left out") and adding skips them.

A delta in direction (the unscattered transmission through media, the mirror reflection of a
smooth interface) sits on the diagonal of its block with the same value in every order. It stays
in the blocks (the adding equations need it), and is also recorded in ``delta[name]`` (per node,
any of the four blocks; :mod:`layersim.operators.deltas`), so that the BSDF can evaluate the smooth
part without it and report it separately.

Orders at or beyond ``m`` are exactly zero. Blocks are scipy CSR matrices (a list, or an
:class:`OrderStack` holding the orders of a block in one array triple); entries whose magnitude is
below :data:`DROP_TOLERANCE` times the largest entry of the same block and order are pruned when
an operator is assembled.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sps

from . import energy, quadrature
from ..errors import FileFormatError, OperatorError
from ..outofcore import memory

BLOCKS = ("Rt", "Rb", "Ttb", "Tbt")
#: Relative drop threshold for operator entries (per block and order).
DROP_TOLERANCE = 1e-12


def order_weight(l: int | np.ndarray):
    """c_l of eq. (14) of Jakob's layerlab tutorial: 2 pi for l = 0, pi otherwise."""
    return np.where(np.asarray(l) == 0, 2.0 * np.pi, np.pi)


@dataclass(frozen=True, eq=False)
class Grid:
    """Discrete ordinates: ``h = n // 2`` positive nodes ``mu`` (increasing) with weights ``w``
    of the named quadrature rule on [-1, 1]."""

    rule: str
    n: int
    mu: np.ndarray = field(repr=False)
    w: np.ndarray = field(repr=False)

    @classmethod
    def make(cls, rule: str, n: int) -> "Grid":
        mu, w = quadrature.hemisphere(rule, n)
        mu.setflags(write=False)
        w.setflags(write=False)
        return cls(rule, n, mu, w)

    @property
    def h(self) -> int:
        return self.n // 2

    @cached_property
    def flux_weight(self) -> np.ndarray:
        """``w_j mu_j``: the hemispherical flux of a unit radiance at node ``j`` is
        ``2 pi w_j mu_j`` (summed over nodes: ~pi)."""
        return self.w * self.mu

    def __eq__(self, other) -> bool:
        return isinstance(other, Grid) and self.rule == other.rule and self.n == other.n

    def __hash__(self) -> int:
        return hash((self.rule, self.n))


class Operator(ABC):
    """The interface of a layer's or stack's scattering operator, whatever its representation.

    Two representations implement it: :class:`IsoOperator` (``representation = "isotropic"``:
    one ``h x h`` matrix per block and Fourier order, eq. (14) of Jakob's layerlab tutorial)
    and :class:`layersim.aniso.operator.AnisoOperator` (``"anisotropic"``: one ``(S h, S h)``
    matrix per block coupling the Fourier modes, Zeltner & Jakob 2018 eq. (10)). Code outside
    the operator modules (the solver's energy check, the BSDF, file export, subtraction) calls
    these methods, or picks a per-representation implementation from a registry keyed by
    :attr:`representation`, instead of testing the type.

    Attributes
    ----------
    representation : str
        ``"isotropic"`` or ``"anisotropic"``; the key of :func:`representation_class` and of the
        per-representation registries of :mod:`layersim.solved.bsdf` and
        :mod:`layersim.stacking.subtract`; stored in operator files (absent means isotropic).
    grid : Grid
        The discrete ordinates (``h = grid.h`` per hemisphere).
    m : int
        Number of Fourier orders (``md`` of the coupled representation).
    ms : int
        Largest coupling ``|l - k| / 2`` between Fourier modes (0 for isotropic operators).
    blocks : dict
        ``{"Rt", "Rb", "Ttb", "Tbt"}`` to the representation's matrices, ``None`` for a block
        left out (opaque operators keep ``Rt`` only).
    eta_top, eta_bottom : float
        Absolute indices of the media above and below (``eta_bottom`` None when opaque).
    delta : dict
        The delta (specular or straight-through) part of each block per node, ``{block: (h,)}``
        (:mod:`layersim.operators.deltas`): the unscattered transmission of media, smooth
        interfaces.

    Smooth dielectric boundaries and near-specular lobes applied where a stack is evaluated
    are the BSDF's (:attr:`layersim.solved.bsdf.BSDF.boundary`,
    :attr:`~layersim.solved.bsdf.BSDF.lobes`), not the operator's: the same blocks serve inside and
    outside them.
    """

    representation: str = ""
    #: True once an adding step that consumes its operands took this operator's blocks
    #: (:meth:`layersim.aniso.operator.AnisoOperator.consume`).
    consumed: bool = False

    # ---- structure (shared) -------------------------------------------------------------

    @property
    def opaque(self) -> bool:
        """True when only ``Rt`` is present (a conductor or diffuse base)."""
        return self.blocks["Ttb"] is None

    @property
    def h(self) -> int:
        """Ordinates per hemisphere."""
        return self.grid.h

    @abstractmethod
    def nnz(self) -> int:
        """Stored nonzero entries over all present blocks."""

    @abstractmethod
    def memory_bytes(self) -> int:
        """Resident bytes of the stored blocks (values, indices and row pointers)."""

    @abstractmethod
    def density(self) -> float:
        """Fraction of nonzero entries over the present blocks (0..1)."""

    # ---- energy ---------------------------------------------------------------------------

    @abstractmethod
    def albedo_slots(self) -> dict:
        """Energy fractions per incident slot and node, ``{block: (S, h)}``.

        Row 0 is the energy for azimuthally uniform illumination (:meth:`albedo`); rows
        ``b >= 1`` (coupled operators only, ``S = 2 md - 1``; ``S = 1`` for isotropic ones)
        weight the azimuth-dependent part, see
        :meth:`layersim.aniso.operator.AnisoOperator.albedo_slots`."""

    def albedo(self) -> dict:
        """Energy fractions per incident node for azimuthally uniform illumination,
        ``{block: (h,)}``: ``E[i] = sum_o B_0[o, i] w_o mu_o / (w_i mu_i)``, the fraction of the
        power of a beam arriving along node ``i`` that leaves through the block's side
        (quadrature-consistent)."""
        return {name: e[0] for name, e in self.albedo_slots().items()}

    def limit_energy(self) -> tuple[float, int] | None:
        """Remove a small energy excess of the quadrature in place, keeping reciprocity
        (:func:`layersim.operators.energy.limit_energy`); returns ``(excess, scaled ordinates)``, or
        None when the representation does not correct it (the caller then reports the excess)."""
        return None

    @abstractmethod
    def reciprocity_error(self) -> float:
        """Largest violation of (generalized) reciprocity relative to the largest coefficient."""

    # ---- conversions ------------------------------------------------------------------------

    @abstractmethod
    def map_blocks(self, fn: Callable) -> "Operator":
        """The same operator with ``fn`` applied to every stored sparse matrix (block by block
        in :data:`BLOCKS` order, orders in increasing order), e.g. to perturb the entries."""

    @abstractmethod
    def rotational_average(self) -> "IsoOperator":
        """The isotropic operator averaged over rotations about the normal (itself when
        isotropic)."""

    @abstractmethod
    def as_coupled(self, md: int | None = None) -> "Operator":
        """This operator in the coupled (anisotropic) representation with ``md`` orders
        (default: its own)."""

    @classmethod
    @abstractmethod
    def identity(cls, grid: Grid, m: int, eta: float) -> "Operator":
        """A layer that transmits everything unchanged in a medium of index ``eta``."""

    # ---- persistence ------------------------------------------------------------------------

    @abstractmethod
    def to_arrays(self, prefix: str = "") -> dict:
        """Flat named arrays for ``np.savez`` (read back with :func:`from_arrays`)."""

    @classmethod
    @abstractmethod
    def from_arrays(cls, d, prefix: str = "") -> "Operator":
        """Inverse of :meth:`to_arrays` for this representation."""


#: Operator classes by :attr:`Operator.representation` (see :func:`register`).
_REPRESENTATIONS: dict = {}


def register(cls):
    """Class decorator: make ``cls`` the operator class of ``cls.representation``."""
    _REPRESENTATIONS[cls.representation] = cls
    return cls


def representation_class(representation: str) -> type:
    """The operator class registered for ``representation`` ("isotropic", "anisotropic")."""
    try:
        return _REPRESENTATIONS[representation]
    except KeyError:
        raise OperatorError(f"unknown operator representation {representation!r}; known: "
                            + ", ".join(sorted(_REPRESENTATIONS))) from None


#: The representation that holds every other (see :func:`common_representation`).
COUPLED = "anisotropic"


def common_representation(*ops: Operator) -> str:
    """The representation in which the operators ``ops`` can be combined: the coupled one if
    any of them is coupled, else isotropic."""
    return COUPLED if any(op.representation == COUPLED for op in ops) else "isotropic"


def from_arrays(d, prefix: str = "") -> Operator:
    """An operator of the representation recorded in the saved arrays ``d`` (no
    ``representation`` entry: isotropic)."""
    representation = str(d.get(f"{prefix}representation", "isotropic"))
    return representation_class(representation).from_arrays(d, prefix=prefix)


@register
class IsoOperator(Operator):
    """Scattering operator of an isotropic layer or stack (see module docstring).

    Parameters
    ----------
    grid : Grid
    blocks : dict
        ``{"Rt": [csr (h, h)] * m, "Rb": ..., "Ttb": ..., "Tbt": ...}``; a missing or ``None``
        entry marks a block that is left out (opaque operators keep only ``Rt``).
    eta_top, eta_bottom : float
        Absolute indices of the media directly above and below (``eta_bottom`` is ``None`` for
        an opaque operator). Used for generalized reciprocity and transmission eval.
    """

    def __init__(self, grid: Grid, blocks: dict, eta_top: float = 1.0,
                 eta_bottom: float | None = 1.0, delta: dict | None = None):
        self.grid = grid
        self.blocks = {name: blocks.get(name) for name in BLOCKS}
        lengths = {len(v) for v in self.blocks.values() if v is not None}
        if self.blocks["Rt"] is None or len(lengths) != 1:
            raise OperatorError("an operator needs an Rt block and the same number of orders "
                                "in every block")
        self.m = lengths.pop()
        self.eta_top = float(eta_top)
        self.eta_bottom = None if self.opaque else float(eta_bottom)
        self.delta = {k: np.asarray(v, float) for k, v in (delta or {}).items()
                      if v is not None and self.blocks.get(k) is not None}

    representation = "isotropic"
    #: Isotropic operators couple no Fourier modes.
    ms = 0

    # ---- structure ---------------------------------------------------------------------

    def block(self, name: str, l: int) -> sps.csr_matrix:
        """Block ``name`` of order ``l`` (an all-zero matrix beyond ``m``)."""
        blk = self.blocks[name]
        if blk is None:
            raise OperatorError(f"block {name} was left out of this operator (opaque)")
        if l >= self.m:
            return sps.csr_matrix((self.h, self.h))
        return blk[l]

    def nnz(self) -> int:
        return sum(mat.nnz for blk in self.blocks.values() if blk is not None for mat in blk)

    def order_nnz(self, name: str, m: int | None = None) -> np.ndarray:
        """Stored entries of block ``name`` per order ``0 .. m-1`` (default :attr:`m`; zero
        past the last order), shape (m,), read from the row pointers of an
        :class:`OrderStack` without building its per-order matrices."""
        blk = self.blocks[name]
        if blk is None:
            raise OperatorError(f"block {name} was left out of this operator (opaque)")
        m = self.m if m is None else m
        out = np.zeros(m, np.int64)
        k = min(m, self.m)
        if isinstance(blk, OrderStack):
            out[:k] = blk.nnz_per_order()[:k]
        else:
            out[:k] = [mat.nnz for mat in blk[:k]]
        return out

    def memory_bytes(self) -> int:
        """Bytes held by the sparse blocks (values, indices and row pointers)."""
        return sum(memory.sparse_bytes(mat)
                   for blk in self.blocks.values() if blk is not None for mat in blk)

    def density(self) -> float:
        present = sum(1 for blk in self.blocks.values() if blk is not None)
        return self.nnz() / max(1, present * self.m * self.h * self.h)

    def truncated(self, m: int) -> "IsoOperator":
        """The same operator keeping orders ``0..m-1`` (padding with zero orders if larger)."""
        def fix(blk):
            if blk is None:
                return None
            if m <= len(blk):
                return blk[:m]
            return list(blk) + [sps.csr_matrix((self.h, self.h)) for _ in range(m - len(blk))]
        return IsoOperator(self.grid, {k: fix(v) for k, v in self.blocks.items()},
                           self.eta_top, self.eta_bottom, self.delta)

    def __repr__(self) -> str:
        return (f"IsoOperator(n={self.grid.n}, rule={self.grid.rule}, m={self.m}, "
                f"{'opaque' if self.opaque else 'transmissive'}, nnz={self.nnz()}, "
                f"density={100 * self.density():.3g}%)")

    # ---- construction ------------------------------------------------------------------

    @classmethod
    def from_series(cls, grid: Grid, m: int, series: dict, eta_top: float,
                    eta_bottom: float | None) -> "IsoOperator":
        """Assemble an operator from per-pair cosine series of the BSDF.

        ``series[name]`` is a list of chunks ``(o, i, coef)``: node indices ``o, i`` of shape (P,)
        and ``coef`` of shape (P, K) holding ``f_l(mu_o, mu_i)`` for ``l < K`` (zero-padded).
        A block given as ``None`` is left out; a block missing from ``series`` is all zero.
        """
        blocks = {}
        for name in BLOCKS:
            chunks = series.get(name, [])
            if chunks is None:
                blocks[name] = None
                continue
            blocks[name] = _orders_to_csr(chunks, m, grid)
        return cls(grid, blocks, eta_top, eta_bottom)

    @classmethod
    def from_dense(cls, grid: Grid, blocks: dict, eta_top: float,
                   eta_bottom: float | None, delta: dict | None = None) -> "IsoOperator":
        """Assemble from dense arrays ``blocks[name]`` of shape (m, h, h) (already scaled as
        ``B_l``), pruning small entries per order as :func:`prune_order` does, into one
        :class:`OrderStack` per block (the arrays are copied, not overwritten)."""
        out = {}
        for name in BLOCKS:
            arr = blocks.get(name)
            out[name] = None if arr is None else OrderStack.from_dense(np.array(arr, float))
        return cls(grid, out, eta_top, eta_bottom, delta)

    @classmethod
    def identity(cls, grid: Grid, m: int, eta: float) -> "IsoOperator":
        """A layer that transmits everything unchanged (all orders), reflecting nothing."""
        h = grid.h
        eye = sps.identity(h, format="csr")
        zero = sps.csr_matrix((h, h))
        blocks = {"Rt": [zero] * m, "Rb": [zero] * m, "Ttb": [eye] * m, "Tbt": [eye] * m}
        ones = np.ones(h)
        return cls(grid, blocks, eta, eta, delta={"Ttb": ones, "Tbt": ones})

    # ---- BSDF coefficients ---------------------------------------------------------------

    def coefficients(self, name: str, l: int) -> np.ndarray:
        """Dense ``f_l(mu_o, mu_i)`` (1/sr) of block ``name``, shape (h, h) [o, i]."""
        mat = self.block(name, l).toarray()
        return mat / (order_weight(l) * self.grid.flux_weight[None, :])

    # ---- diagnostics -------------------------------------------------------------------

    def albedo_nodes(self) -> dict:
        """Energy fractions per incident node: ``{"Rt": (h,), "Ttb": (h,), ...}``.

        ``E[i] = sum_o B_0[o, i] w_o mu_o / (w_i mu_i)``, the fraction of the power of a beam
        arriving along node ``i`` that leaves through the block's side (quadrature-consistent).
        """
        fw = self.grid.flux_weight
        out = {}
        for name, blk in self.blocks.items():
            if blk is None:
                continue
            out[name] = (blk[0].T @ fw) / fw
        return out

    def albedo(self) -> dict:
        return self.albedo_nodes()

    def albedo_slots(self) -> dict:
        return {name: e[None, :] for name, e in self.albedo_nodes().items()}

    def limit_energy(self) -> tuple[float, int]:
        return energy.limit_energy(self)

    def reciprocity_error(self) -> float:
        return self.as_coupled().reciprocity_error()

    # ---- conversions ---------------------------------------------------------------------

    def map_blocks(self, fn: Callable) -> "IsoOperator":
        blocks = {k: None if v is None else [fn(b) for b in v] for k, v in self.blocks.items()}
        return IsoOperator(self.grid, blocks, self.eta_top, self.eta_bottom, self.delta)

    def rotational_average(self) -> "IsoOperator":
        return self

    def as_coupled(self, md: int | None = None) -> Operator:
        """Block diagonal in the coupled representation (see
        :meth:`layersim.aniso.operator.AnisoOperator.from_iso`)."""
        return representation_class(COUPLED).from_iso(self, md)

    # ---- persistence -------------------------------------------------------------------

    def to_arrays(self, prefix: str = "") -> dict:
        """Flat arrays for ``np.savez`` (one CSR triple per block, orders concatenated)."""
        d = header_arrays(self, prefix)
        d[f"{prefix}m"] = np.array(self.m)
        write_blocks(d, prefix, {
            name: sps.vstack(blk, format="csr") if blk else sps.csr_matrix((0, self.h))
            for name, blk in self.blocks.items() if blk is not None})
        return d

    @classmethod
    def from_arrays(cls, d, prefix: str = "") -> "IsoOperator":
        try:
            rule = str(d[f"{prefix}rule"])
            n, m = int(d[f"{prefix}n"]), int(d[f"{prefix}m"])
            eta_top = float(d[f"{prefix}eta_top"])
            eb = float(d[f"{prefix}eta_bottom"])
            grid = Grid.make(rule, n)
            h = grid.h
            blocks = {name: None if stacked is None else OrderStack.from_csr(stacked, h)
                      for name, stacked in read_blocks(d, prefix, (m * h, h)).items()}
            delta = read_delta(d, prefix)
        except (KeyError, ValueError, TypeError) as exc:
            raise FileFormatError(f"not a layersim operator file ({exc})") from None
        return cls(grid, blocks, eta_top, None if np.isnan(eb) else eb, delta)


class OrderStack(Sequence):
    """The ``m`` orders ``B_0 .. B_{m-1}`` (each (h, h)) of one block, held as the single CSR
    matrix of the stacked orders (row ``l h + o``): what the assembly (host or device) produces
    in one pass, and what operator files store.

    Indexing gives ``scipy.sparse.csr_matrix`` views of order ``l`` (sharing the arrays; built on
    first access and cached, since scipy's constructor is slow next to the projection of a
    whole operator on a GPU). A slice gives a list of them.

    Parameters
    ----------
    data : float64 ndarray (nnz,)
    indices : int32 ndarray (nnz,)
        Column (incident node) of each entry.
    indptr : int ndarray (m h + 1,)
        Row pointers of the stacked matrix.
    h : int
        Nodes per hemisphere.
    """

    def __init__(self, data, indices, indptr, h: int):
        self.h = int(h)
        self._data = np.asarray(data, dtype=np.float64)
        self._indices = np.asarray(indices, dtype=np.int32)
        self._indptr = np.asarray(indptr, dtype=np.int64)
        rows = self._indptr.size - 1
        if rows % self.h or self._indptr[0] != 0 or self._indptr[-1] != self._data.size \
                or self._indices.size != self._data.size:
            raise OperatorError(f"inconsistent stacked CSR arrays ({rows} rows for h={h}, "
                                f"{self._data.size} values, {self._indices.size} indices)")
        self._mats = [None] * (rows // self.h)

    @classmethod
    def from_csr(cls, stacked: sps.csr_matrix, h: int) -> "OrderStack":
        """From the stacked matrix of shape (m h, h)."""
        return cls(stacked.data, stacked.indices, stacked.indptr, h)

    @classmethod
    def from_dense(cls, dense: np.ndarray) -> "OrderStack":
        """From dense orders (m, h, h), each pruned at :data:`DROP_TOLERANCE` relative to its
        largest entry (exact zeros dropped too, as :func:`prune_order` does); ``dense`` is
        overwritten. ``|x| < cut`` is taken as two comparisons and ``max |x|`` as
        ``max(max, -min)``: no float temporary of the dense array (``np.abs`` of it would cost
        as much as the rest of the assembly of a small operator)."""
        m, h = dense.shape[0], dense.shape[1]
        flat = dense.reshape(m, h * h)
        cut = DROP_TOLERANCE * np.maximum(flat.max(axis=1), -flat.min(axis=1))[:, None]
        flat[(flat < cut) & (flat > -cut)] = 0.0
        at = np.flatnonzero(flat)
        row, col = np.divmod(at, h)             # row l h + o of the stacked matrix
        indptr = np.zeros(m * h + 1, np.int64)
        np.cumsum(np.bincount(row, minlength=m * h), out=indptr[1:])
        return cls(flat.reshape(-1)[at], col.astype(np.int32), indptr, h)

    @classmethod
    def concatenate(cls, stacks: list) -> "OrderStack":
        """The orders of ``stacks`` one after another."""
        h = stacks[0].h
        offsets = np.cumsum([0] + [s._data.size for s in stacks])
        indptr = np.concatenate([s._indptr[:-1] + off for s, off in zip(stacks, offsets)]
                                + [offsets[-1:]])
        return cls(np.concatenate([s._data for s in stacks]),
                   np.concatenate([s._indices for s in stacks]), indptr, h)

    def dense(self, orders: range) -> np.ndarray:
        """Orders ``orders`` (a step-1 range; zero past the last order) as a dense
        (len(orders), h, h) array, from the stacked rows at once."""
        h = self.h
        out = np.zeros((len(orders), h, h))
        stop = min(orders.stop, len(self))
        if stop > orders.start:
            ptr = self._indptr[orders.start * h:stop * h + 1]
            a, b = ptr[0], ptr[-1]
            rows = sps.csr_matrix((self._data[a:b], self._indices[a:b], ptr - a),
                                  shape=((stop - orders.start) * h, h))
            out[:stop - orders.start] = rows.toarray().reshape(-1, h, h)
        return out

    def nnz_per_order(self) -> np.ndarray:
        """Stored entries of each order, shape (m,)."""
        return np.diff(self._indptr[::self.h])

    def __len__(self) -> int:
        return len(self._mats)

    def __getitem__(self, l):
        if isinstance(l, slice):
            return [self[k] for k in range(*l.indices(len(self)))]
        l = range(len(self))[l]          # negative indices, IndexError past the end
        mat = self._mats[l]
        if mat is None:
            h = self.h
            ptr = self._indptr[l * h:(l + 1) * h + 1]
            a, b = ptr[0], ptr[-1]
            mat = sps.csr_matrix((self._data[a:b], self._indices[a:b], ptr - a), shape=(h, h))
            self._mats[l] = mat
        return mat


# ---- file arrays shared by IsoOperator and layersim.aniso.AnisoOperator ----------------

def header_arrays(op, prefix: str) -> dict:
    """Grid, indices and unscattered transmission of an operator as named arrays."""
    d = {f"{prefix}rule": np.array(op.grid.rule), f"{prefix}n": np.array(op.grid.n),
         f"{prefix}eta_top": np.array(op.eta_top),
         f"{prefix}eta_bottom": np.array(np.nan if op.eta_bottom is None else op.eta_bottom)}
    for name, vec in op.delta.items():
        d[f"{prefix}delta_{name}"] = vec
    return d


def write_blocks(d: dict, prefix: str, mats: dict) -> None:
    """Store CSR matrices ``{block: csr}`` as data / int32 indices / int64 indptr arrays."""
    for name, mat in mats.items():
        d[f"{prefix}{name}_data"] = mat.data
        d[f"{prefix}{name}_indices"] = mat.indices.astype(np.int32)
        d[f"{prefix}{name}_indptr"] = mat.indptr.astype(np.int64)


def read_blocks(d, prefix: str, shape: tuple) -> dict:
    """Inverse of :func:`write_blocks`: ``{block: csr of shape or None}`` for every block."""
    blocks = {}
    for name in BLOCKS:
        key = f"{prefix}{name}_data"
        blocks[name] = None if key not in d else sps.csr_matrix(
            (d[key], d[f"{prefix}{name}_indices"], d[f"{prefix}{name}_indptr"]), shape=shape)
    return blocks


def read_delta(d, prefix: str) -> dict:
    return {name: np.asarray(d[f"{prefix}delta_{name}"]) for name in BLOCKS
            if f"{prefix}delta_{name}" in d}


#: Largest dense scratch array _orders_to_csr uses (entries; 32 MiB): a slab of orders times
#: the pairs of a block (larger slabs fall out of cache and assemble no faster).
DENSE_ASSEMBLY_MAX = 1 << 22


def _orders_to_csr(chunks, m: int, grid: Grid) -> "OrderStack":
    """Per-order CSR blocks ``B_l = c_l f_l w_i mu_i`` from per-pair series chunks, pruned per
    order (:data:`DROP_TOLERANCE` relative to the order's largest entry, exact zeros dropped).
    The pairs ``(o, i)`` are unique across chunks, as the projection produces them.

    The pairs are sorted once by (row, column); a slab of orders of the series, one column per
    pair in that order, then lists its nonzeros row by row already in (order, row, column)
    order: no sort of the entries, and no scan of the empty ``(m, h, h)`` positions (most of a
    near-specular block's). When one order of the pairs exceeds the scratch limit
    (:data:`DENSE_ASSEMBLY_MAX`), the triplets are sorted by one combined integer key instead.
    """
    h = grid.h
    chunks = [(o, i, c[:, :m]) for o, i, c in chunks if o.size]
    if not chunks:
        return OrderStack(np.zeros(0), np.zeros(0, np.int32), np.zeros(m * h + 1, np.int64), h)
    weight = order_weight(np.arange(m))
    pairs = sum(o.size for o, _, _ in chunks)
    if pairs <= DENSE_ASSEMBLY_MAX:
        row, col, val = _pair_slabs(chunks, m, grid, weight, pairs)
    else:
        row, col, val = _sorted_triplets(chunks, m, grid, weight)
    indptr = np.zeros(m * h + 1, np.int64)
    np.cumsum(np.bincount(row, minlength=m * h), out=indptr[1:])
    return OrderStack(val, col, indptr, h)


def _pair_slabs(chunks, m: int, grid: Grid, weight: np.ndarray, pairs: int):
    """Stacked row ``l h + o``, column (int32) and value of the kept entries of
    :func:`_orders_to_csr`, in (order, row, column) order, from slabs ``(orders, pairs)`` with
    the pairs sorted by position.

    A slab holds only the pairs of chunks whose series reach its first order: the projection
    batches pairs of similar series length, and most of a block's short series end long before
    ``m`` (a third to a half of the (pair, order) table lies within its chunks' reach)."""
    h, fw = grid.h, grid.flux_weight
    o = np.concatenate([c[0] for c in chunks])
    i = np.concatenate([c[1] for c in chunks])
    by_position = np.argsort(o.astype(np.int64) * h + i, kind="stable")
    column = np.empty(pairs, np.int64)           # the sorted column of each chunk row
    column[by_position] = np.arange(pairs)
    o, i = o[by_position].astype(np.int64), i[by_position].astype(np.int32)
    starts = np.cumsum([0] + [c[0].size for c in chunks])
    reach = [_series_reach(c) for _, _, c in chunks]
    pair_reach = np.repeat(reach, np.diff(starts))[by_position]
    out, l0 = [], 0
    while l0 < m:
        active = pair_reach > l0
        if not active.any():
            break
        rank = np.cumsum(active) - 1             # slab column of each active sorted pair
        width = int(rank[-1]) + 1
        l1 = min(m, l0 + max(1, DENSE_ASSEMBLY_MAX // width))
        slab = np.zeros((l1 - l0, width))
        for (_, ik, c), a, b, k in zip(chunks, starts[:-1], starts[1:], reach):
            k = min(l1, k) - l0                  # orders of this chunk's series in the slab
            if k > 0:
                slab[:k, rank[column[a:b]]] = (c[:, l0:l0 + k] * fw[ik][:, None]).T
        slab *= weight[l0:l1, None]
        # |x| < cut as two comparisons, max |x| as max(max, -min): no float temporary
        cut = DROP_TOLERANCE * np.maximum(slab.max(axis=1), -slab.min(axis=1))[:, None]
        slab[(slab < cut) & (slab > -cut)] = 0.0
        at = np.flatnonzero(slab)
        ls, p = np.divmod(at, width)
        p = np.flatnonzero(active)[p]
        out.append(((ls + l0) * h + o[p], i[p], slab.reshape(-1)[at]))
        l0 = l1
    if not out:
        return np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros(0)
    return tuple(np.concatenate(part) for part in zip(*out))


def _series_reach(c: np.ndarray) -> int:
    """One past the last order (column) of ``c`` with a nonzero entry (0 when all zero)."""
    nonzero = np.flatnonzero(c.any(axis=0))
    return int(nonzero[-1]) + 1 if nonzero.size else 0


def _sorted_triplets(chunks, m: int, grid: Grid, weight: np.ndarray):
    """Stacked row, column (int32) and value of the kept entries of :func:`_orders_to_csr`,
    sorted by one combined integer key."""
    h = grid.h
    rows, cols, orders, vals = [], [], [], []
    for o, i, c in chunks:
        p, l = np.nonzero(c)
        rows.append(o[p])
        cols.append(i[p])
        orders.append(l)
        vals.append(c[p, l] * grid.flux_weight[i[p]] * weight[l])
    o, i = np.concatenate(rows), np.concatenate(cols)
    l, v = np.concatenate(orders), np.concatenate(vals)
    order = np.argsort((l.astype(np.int64) * h + o) * h + i, kind="stable")
    o, i, l, v = o[order], i[order], l[order], v[order]
    amax = np.zeros(m)
    np.maximum.at(amax, l, np.abs(v))
    keep = np.abs(v) >= DROP_TOLERANCE * amax[l]
    return l[keep].astype(np.int64) * h + o[keep], i[keep].astype(np.int32), v[keep]


def prune_order(mat: sps.csr_matrix) -> sps.csr_matrix:
    """Drop the entries of one order's block below :data:`DROP_TOLERANCE` times its largest
    magnitude, and exact zeros (in place; returns ``mat``)."""
    if mat.nnz:
        cut = DROP_TOLERANCE * np.abs(mat.data).max()
        mat.data[np.abs(mat.data) < cut] = 0.0
        mat.eliminate_zeros()
    return mat
