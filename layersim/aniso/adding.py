"""The adding equations for coupled-mode operators (Zeltner & Jakob 2018 eq. (11)-(12)).

For a top layer 1 and a bottom layer 2, with ``A' = I - Rt2 Rb1`` and the push-through
identities ``(I - Rb1 Rt2)^-1 = I + Rb1 A'^-1 Rt2`` and ``(I - Rb1 Rt2)^-1 Rb1 = Rb1 A'^-1``
(eq. (12)), all four outputs need solves with ``A'`` only (one factorisation)::

    [Z1 | Z2] = A'^-1 [Rt2 Ttb1 | Tbt2]
    Rt  = Rt1 + Tbt1 Z1            Tbt = Tbt1 Z2
    Ttb = Ttb2 Ttb1 + Ttb2 Rb1 Z1  Rb  = Rb2 + Ttb2 Rb1 Z2

(below an opaque bottom only ``Rt``). This is the mirror image of the arrangement of
:mod:`layersim.stacking.adding` (``A = I - Rb1 Rt2``): the solution is multiplied by the top layer's
transmission only, never by the bottom's reflection, which is the largest operator of a
coated anisotropic base (and ``Tbt1`` is block diagonal when the coating is isotropic).
``A'`` is banded by Fourier order and solved with :func:`~layersim.aniso.banded.banded_solve`
(block LU, pruned block substitution, sparse right-hand sides); results are pruned at
:data:`layersim.operators.operator.DROP_TOLERANCE` relative to each block's largest entry, and, with
the ``relerr`` of :func:`layersim.solve` (:data:`layersim.aniso.plan.COUPLED_RELERR`), per ordinate
pair as the projected layers are, intermediates included.

Memory: the blocks of the step are held by a
:class:`~layersim.outofcore.workspace.Workspace` (:class:`~layersim.outofcore.workspace.Blocks`)
and handed over at their last use (``take``). Operands that the caller consumes (``consume=``)
are owned by the step: their blocks go as soon as the equations no longer need them, and those
idle until after the solve are parked in the workspace's directory meanwhile (below an opaque
base, ``Rt1`` and ``Tbt1``); the bottom's ``Rt`` is then read piece by piece from a file by
both products. Whatever ``consume``, the right-hand side ``Rt2 Ttb1``, ``K``, the grouped
right-hand sides of the substitutions, the solution's parts and ``Tbt1 Z1`` are written to the
workspace's files as they are formed and read back piece by piece.

An isotropic operand is converted to the slot basis first (block diagonal): adding an
anisotropic layer to an isotropic one works, and the result is anisotropic.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import scipy.sparse as sps

from ..operators.deltas import add_deltas
from ..stacking.adding import check_pair
from ..errors import OperatorError
from ..operators.operator import DROP_TOLERANCE, Grid
from ..outofcore.workspace import Blocks, Workspace, block_bytes
from .banded import banded_solve
from .operator import AnisoOperator, as_aniso, prune, reciprocal_prune
from .pairs import pruned_product

#: Values of ``consume`` (:func:`add`).
CONSUME = (None, "top", "bottom", "both")


def add(top, bottom, relerr: float | None = None, relerr_intermediate: float | None = None,
        consume: str | None = None, workspace: Workspace | None = None) -> AnisoOperator:
    """Operator of ``top`` stacked on ``bottom`` (coupled modes; module docstring).

    Parameters
    ----------
    top, bottom : AnisoOperator or IsoOperator
        Same grid; isotropic operands are converted; the result has the larger ``md``.
    relerr : float, optional
        Drop coefficients of the result below ``relerr`` times the largest of their ordinate
        pair, keeping it exactly reciprocal (:func:`~.operator.reciprocal_prune`); the
        products with the solution are pruned per pair at ``relerr / 10`` as they are formed.
        By default only entries below :data:`~layersim.operators.operator.DROP_TOLERANCE` of their
        block's largest are dropped.
    relerr_intermediate : float, optional
        The same for ``K``, ``Rt2 Ttb1`` and the solution ``Z`` (:func:`~.pairs.prune_pairs`).
    consume : {None, "top", "bottom", "both"}
        Operands that the caller will not use again and holds no other reference to: emptied
        (:meth:`AnisoOperator.consume`), their blocks released and parked as the step goes.
    workspace : Workspace, optional
        Where idle blocks and intermediate pieces wait (default: one chosen for this step,
        :meth:`~layersim.outofcore.workspace.Workspace.for_bytes`).
    """
    pair, blocks = _operands(top, bottom, consume, workspace)
    opaque, whole = pair.opaque, relerr is None      # else the sums stay in row pieces
    multiply = functools.partial(_multiply, blocks.workspace, pair.h)
    product = functools.partial(multiply, relerr_intermediate, floor=1e-16)
    output = functools.partial(multiply, None if relerr is None else 0.1 * relerr)
    blocks.idle("Rt1", "Tbt1", "Ttb2", "Rb2")            # idle until after the solve
    # eq. (12): [Z1 | Z2] = A'^-1 [Rt2 Ttb1 | Tbt2], A' = I - K, K = Rt2 Rb1
    _hold_solution(blocks, pair, banded_solve(
        *_system(blocks, product, opaque), pair.h, pair.md, identity_minus=True,
        relerr=relerr_intermediate, release=True, workspace=blocks.workspace))
    # eq. (11): Rt = Rt1 + Tbt1 Z1, Tbt = Tbt1 Z2, Ttb = Ttb2 Ttb1 + W Z1, Rb = Rb2 + W Z2
    blocks.put("Tbt1 Z1", output(blocks.use("Tbt1", last=opaque),
                                 blocks.use("Z1", last=opaque), pieces=True))
    result = {"Rt": _sum(blocks, "Tbt1 Z1", "Rt1", whole)}
    if not opaque:
        blocks.put("W", multiply(None, blocks.get("Ttb2"), blocks.take("Rb1")))   # Ttb2 Rb1
        result["Tbt"] = prune(output(blocks.take("Tbt1"), blocks.get("Z2")), DROP_TOLERANCE)
        blocks.put("Ttb2 Ttb1", multiply(None, blocks.take("Ttb2"), blocks.take("Ttb1")))
        blocks.put("W Z1", output(blocks.get("W"), blocks.take("Z1")))
        result["Ttb"] = _sum(blocks, "Ttb2 Ttb1", "W Z1", whole)
        blocks.put("W Z2", output(blocks.take("W"), blocks.take("Z2")))
        result["Rb"] = _sum(blocks, "Rb2", "W Z2", whole)
    blocks.workspace.release()
    if relerr is not None:
        reciprocal_prune(result, pair.grid, pair.md, pair.eta_top, pair.eta_bottom,
                         pair.delta, relerr, blocks.workspace.directory)
        blocks.workspace.release()
    return AnisoOperator(pair.grid, pair.md, result, pair.eta_top,
                         None if opaque else pair.eta_bottom, pair.delta)


@dataclass
class _Pair:
    """What the result of adding two coupled-mode operators shares with them."""

    grid: Grid
    md: int
    h: int
    size: int               # unknowns of the slot basis
    eta_top: float
    eta_bottom: float | None
    opaque: bool
    delta: dict             # the deltas of the stack (layersim.operators.deltas)

    @classmethod
    def of(cls, top: AnisoOperator, bottom: AnisoOperator) -> "_Pair":
        opaque = bottom.opaque
        delta = add_deltas(top.delta, bottom.delta, opaque)     # diagonal algebra
        return cls(top.grid, top.md, top.h, top.size, top.eta_top, bottom.eta_bottom, opaque,
                   delta)


def _operands(top, bottom, consume, workspace) -> tuple:
    """``(_Pair, Blocks)``: the operands as coupled-mode operators of the same ``md``
    (checked), their blocks held as ``"Rt1", .. "Tbt1", "Rt2", ..``; those of consumed
    operands owned by the step (the operators emptied)."""
    for side, op in (("top", top), ("bottom", bottom)):
        if getattr(op, "consumed", False):
            raise OperatorError(f"the {side} operator was consumed by an earlier adding step "
                                "(consume=...) and no longer holds its blocks")
    md = max(top.m, bottom.m)
    top_a, bottom_a = as_aniso(top, md), as_aniso(bottom, md)
    check_pair(top_a, bottom_a)
    if consume not in CONSUME:
        raise ValueError(f"consume must be None, 'top', 'bottom' or 'both', not {consume!r}")
    pair = _Pair.of(top_a, bottom_a)
    held, owned = {}, set()
    for side, ops, k in (("top", (top, top_a), "1"), ("bottom", (bottom, bottom_a), "2")):
        held.update((name + k, mat) for name, mat in ops[1].blocks.items())
        if consume in (side, "both"):
            owned.update(name + k for name in ops[1].blocks)
            for op in {id(op): op for op in ops}.values():
                getattr(op, "consume", lambda: None)()
    if workspace is None:
        workspace = Workspace.for_bytes(_footprint(held, owned, pair.opaque))
    return pair, workspace.blocks(held, owned)


def _footprint(held: dict, owned: set, opaque: bool) -> int:
    """Bytes that an adding step may park: its owned idle blocks, ``Rt2`` and the pieces of
    ``Rt2 Ttb1``, ``K`` and ``Tbt1 Z1`` (estimated by the bytes of their factors and of
    ``Rt1``)."""
    size = lambda *names: sum(block_bytes(held.get(n)) for n in names)
    idle = ["Rt1", "Tbt1"] + ([] if opaque else ["Ttb1", "Rb1"]) if "Rt1" in owned else []
    idle += ["Ttb2", "Rb2"] if "Rt2" in owned and not opaque else []
    return size(*idle) + 3 * size("Rt2") + size("Ttb1", "Rb1", "Rt1")


def _system(blocks: Blocks, product, opaque: bool) -> tuple:
    """``(K, [Rt2 Ttb1 | Tbt2])`` of eq. (12), ``K = Rt2 Rb1`` as row pieces in the workspace
    (the banded solve reads it piece by piece)."""
    K, first = _products(blocks, product, opaque)
    blocks.idle("Ttb1", "Rb1")                      # needed again after the solve
    rhs = first.to_csr(release=True)
    if not opaque:
        rhs = sps.hstack([rhs, blocks.take("Tbt2")], format="csr")
    blocks.workspace.release()
    return K, rhs


def _products(blocks: Blocks, product, opaque: bool) -> tuple:
    """``(Rt2 Rb1, Rt2 Ttb1)`` as row pieces in the workspace; ``Rt2`` is read piece by piece
    (from a file where the step owns it) and goes when this returns."""
    Rt2 = blocks.take_pieces("Rt2")
    first = product(Rt2, blocks.use("Ttb1", last=opaque), pieces=True)
    return product(Rt2, blocks.use("Rb1", last=opaque), pieces=True), first


def _hold_solution(blocks: Blocks, pair: _Pair, Z) -> None:
    """Hold ``Z`` as ``"Z1"`` (and ``"Z2"``, its columns of ``Tbt2``)."""
    blocks.put("Z1", Z if pair.opaque else Z[:, :pair.size])
    if not pair.opaque:
        blocks.put("Z2", Z[:, pair.size:])
    blocks.workspace.release()


def _sum(blocks: Blocks, a: str, b: str, assemble: bool):
    """``prune(a + b)`` of the held blocks ``a`` and ``b`` (handed over): summed in row
    pieces in the workspace, the terms released before the sum is assembled. Without
    ``assemble`` the pruned sum is returned as row pieces
    (for :func:`~layersim.aniso.operator.reciprocal_prune`, which reads it piece by piece)."""
    pieces = blocks.workspace.sum(blocks.take(a), blocks.take(b))
    if not assemble:
        return prune(pieces, DROP_TOLERANCE)
    return prune(pieces.to_csr(release=True), DROP_TOLERANCE)


def _multiply(workspace: Workspace, h: int, relerr: float | None, a, b,
              floor: float | None = None, pieces: bool = False):
    """``a @ b`` by :func:`~layersim.aniso.pairs.pruned_product`: pruned per ordinate pair at
    ``relerr`` as it is formed, or, with ``relerr`` None, whole (without the entries below
    ``floor`` times its largest, if given); with ``pieces`` as row pieces in the workspace."""
    if relerr is not None or floor is None:
        return pruned_product(a, b, h, relerr, pieces=pieces, directory=workspace.directory)
    out = prune(pruned_product(a, b, h, None), floor)
    return workspace.written(out) if pieces else out
