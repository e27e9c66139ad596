"""The out-of-core workspace: where blocks wait between their uses, and how they are handed
over (layersim.outofcore.workspace)."""

import numpy as np
import pytest
import scipy.sparse as sps

from layersim.config import configure
from layersim.outofcore import parking
from layersim.outofcore.workspace import Workspace


def _block(seed):
    return sps.random(40, 30, 0.2, random_state=seed, format="csr")


def test_blocks_park_only_owned_idle_blocks_and_hand_them_over(tmp_path, monkeypatch):
    """idle() parks the owned blocks only (in files of the workspace's directory); get() reads
    a block back and keeps it; take() reads it back and no longer holds it; both give the
    block's entries unchanged; no file is left once the blocks are taken."""
    monkeypatch.setattr(parking, "PARK_MIN_BYTES", 0)
    mine, theirs = _block(1), _block(2)
    ref_mine, ref_theirs = mine.copy(), theirs.copy()
    blocks = Workspace(str(tmp_path)).blocks({"A": mine, "B": theirs, "C": None}, owned={"A"})
    assert "C" not in blocks and blocks.bytes("A", "B") > 0
    blocks.idle("A", "B", "C")
    assert mine.nnz == 0 and theirs.nnz == ref_theirs.nnz       # A parked: its arrays gone
    assert len(list(tmp_path.iterdir())) == 0                    # the spool file has no name
    got = blocks.get("A")
    assert (got != ref_mine).nnz == 0 and blocks.get("A") is got  # read back once, kept
    blocks.idle("A")
    assert (blocks.take("A") != ref_mine).nnz == 0 and "A" not in blocks
    assert blocks.take("B") is theirs and "B" not in blocks      # not owned: as it was
    with pytest.raises(KeyError):
        blocks.take("B")


def test_blocks_put_results_are_owned_and_taken_in_pieces(tmp_path, monkeypatch):
    """A block put by the computation is owned (parked when idle); take_pieces hands an owned
    block over as row pieces in the workspace's files, a borrowed one as it is."""
    monkeypatch.setattr(parking, "PARK_MIN_BYTES", 0)
    ws = Workspace(str(tmp_path))
    blocks = ws.blocks({"B": _block(4)})
    ref = _block(3)
    blocks.put("Z", ref.copy())
    blocks.idle("Z")
    pieces = blocks.take_pieces("Z")
    assert pieces.on_disk and np.array_equal(pieces.to_csr(release=True).toarray(),
                                             ref.toarray())
    assert sps.issparse(blocks.take_pieces("B"))


def test_workspace_for_bytes_follows_the_park_dir_setting(tmp_path):
    """for_bytes parks in settings().park_dir where it has room, in memory otherwise; an
    in-memory workspace keeps its spools and row pieces in memory."""
    with configure(park_dir=str(tmp_path)):
        assert Workspace.for_bytes(1).directory == str(tmp_path)
        assert not Workspace.for_bytes(1 << 62).on_disk           # not enough free space
    with configure(park_dir=None):
        ws = Workspace.for_bytes(1)
        assert not ws.on_disk and not ws.spool().on_disk and not ws.pieces((3, 3)).on_disk
