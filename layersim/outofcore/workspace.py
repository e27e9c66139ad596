"""Where the blocks of a solve live between their uses: resident, or in files in one directory.

A :class:`Workspace` is decided once per solve (:meth:`Workspace.for_bytes`, from the plan's
memory estimate and ``layersim.config.settings().park_dir``) and handed to the projection and
to the adding steps. Its directory (None: everything stays in memory) is where

* the blocks of an operator that an adding step will consume wait, as the projection builds
  them, and the projected parts of each block and a triangle of pairs while its reciprocal
  image is formed;
* in an adding step, the blocks idle until after the solve are parked
  (:meth:`Blocks.idle`); the bottom's ``Rt`` (read piece by piece by both products), the
  right-hand side ``Rt2 Ttb1``, ``K`` and ``Tbt1 Z1`` are written piece by piece as they are
  formed (:class:`~layersim.outofcore.rowpieces.RowPieces` on a
  :class:`~layersim.outofcore.spool.Spool`); the right-hand sides grouped for the
  substitutions and the parts of the solution wait in spools; the result waits while its
  reciprocal image is formed.

Its operations are those of :mod:`layersim.outofcore`: spools, row pieces, parked blocks,
products (:func:`~layersim.outofcore.products.product`) and sums
(:func:`~layersim.outofcore.sums.sum_pieces`) that keep their pieces in the directory.
:class:`Blocks` holds the named blocks of one computation and hands each over with
:meth:`Blocks.take` at its last use, so that the lifetimes of the blocks are the workspace's
business, not the equations'.
"""

from __future__ import annotations

from .memory import release, sparse_bytes
from .parking import Parked, park, park_directory, unpark
from .products import product
from .rowpieces import RowPieces
from .spool import Spool
from .sums import sum_pieces


class Workspace:
    """Where the idle blocks and the pieces of intermediate results of a solve are kept.

    Parameters
    ----------
    directory : str, optional
        Directory of the spool files (on a disk); None keeps everything in memory.
    """

    def __init__(self, directory: str | None = None):
        self.directory = directory

    @classmethod
    def for_bytes(cls, need: int) -> "Workspace":
        """A workspace in ``settings().park_dir`` where that is on a disk with twice ``need``
        bytes free (:func:`~layersim.outofcore.parking.park_directory`), else in memory."""
        return cls(park_directory(need))

    @property
    def on_disk(self) -> bool:
        return self.directory is not None

    def __repr__(self) -> str:
        return f"Workspace({self.directory!r})"

    def spool(self) -> Spool:
        """An empty :class:`~layersim.outofcore.spool.Spool` here."""
        return Spool(self.directory)

    def pieces(self, shape: tuple) -> RowPieces:
        """An empty :class:`~layersim.outofcore.rowpieces.RowPieces` here."""
        return RowPieces(shape, self.directory)

    def written(self, mat) -> RowPieces:
        """``mat`` copied piece by piece here (wrapped, not copied, in memory)."""
        return RowPieces.written(mat, self.directory)

    def park(self, mat, head: int = 0):
        """``mat`` parked here (:func:`~layersim.outofcore.parking.park`), or ``mat``."""
        return park(mat, self.directory, head)

    def product(self, a, b, keep=None, pieces: bool = False):
        """``a @ b`` filtered by ``keep`` (:func:`~layersim.outofcore.products.product`), as
        row pieces here with ``pieces``."""
        return product(a, b, keep, pieces=pieces, directory=self.directory)

    def sum(self, a, b, alpha: float = 1.0, beta: float = 1.0) -> RowPieces:
        """``alpha a + beta b`` in row pieces here
        (:func:`~layersim.outofcore.sums.sum_pieces`)."""
        return sum_pieces(a, b, alpha, beta, self.directory)

    @staticmethod
    def release() -> None:
        """Give freed heap pages back to the system
        (:func:`~layersim.outofcore.memory.release`), between phases."""
        release()

    def blocks(self, blocks: dict, owned=()) -> "Blocks":
        """The named ``blocks`` of one computation held here (:class:`Blocks`)."""
        return Blocks(self, blocks, owned)


class Blocks:
    """Named blocks of one computation (e.g. ``"Rt1"``, ``"Z"``), held by a workspace.

    The blocks named in ``owned`` are referenced nowhere else: they may be parked while idle
    (:meth:`idle`), and the reference handed over by :meth:`take` is their last one, so that
    the block goes when the caller is done with it.
    """

    def __init__(self, workspace: Workspace, blocks: dict, owned=()):
        self.workspace = workspace
        self._blocks = {k: v for k, v in blocks.items() if v is not None}
        self._owned = set(owned) & set(self._blocks)

    def __contains__(self, name: str) -> bool:
        return name in self._blocks

    def put(self, name: str, block) -> None:
        """Hold ``block`` (owned: the caller keeps no reference)."""
        self._blocks[name] = block
        self._owned.add(name)

    def get(self, name: str):
        """Block ``name``, read back if parked, and still held."""
        block = self._blocks[name] = unpark(self._blocks[name])
        return block

    def take(self, name: str):
        """Block ``name``, read back if parked, handed over: no longer held here."""
        self._owned.discard(name)
        return unpark(self._blocks.pop(name))

    def use(self, name: str, last: bool):
        """:meth:`take` at the block's last use, else :meth:`get`."""
        return self.take(name) if last else self.get(name)

    def take_pieces(self, name: str):
        """:meth:`take`, the block copied to row pieces in the workspace's files if it is
        owned (then read piece by piece, out of memory), else as it is."""
        own = name in self._owned
        block = self.take(name)
        return self.workspace.written(block) if own else block

    def idle(self, *names: str) -> None:
        """Park the owned blocks among ``names`` until they are needed again."""
        for name in names:
            if name in self._owned:
                self._blocks[name] = self.workspace.park(self._blocks[name])

    def bytes(self, *names: str) -> int:
        """Bytes of the blocks ``names`` that are held (resident or parked)."""
        return sum(block_bytes(self._blocks[n]) for n in names if n in self._blocks)


def block_bytes(block) -> int:
    """Bytes of a sparse block, resident or parked."""
    return block.bytes if isinstance(block, Parked) else sparse_bytes(block)
