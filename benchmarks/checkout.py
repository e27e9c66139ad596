"""Run a checkout of layersim beside this one: the import path that makes a worker process import
that checkout's package, as the installed package lays it out.

In the source tree ``kernels/`` and ``montecarlo/`` sit beside ``layersim/`` and are installed as
``layersim.kernels`` and ``layersim.montecarlo``; an editable install maps those names to *its*
tree, whatever ``PYTHONPATH`` says. A staging folder whose ``layersim`` package links the
checkout's ``layersim/*``, ``kernels`` and ``montecarlo`` is found first and holds them all, so a
worker imports every module of the checkout it is given (the benchmarks that compare a tree with a
base check this: ``benchmarks/speed/speed_vs_base.py``, ``benchmarks/montecarlo/walk_vs_base.py``).
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["stage", "worker_env"]


def stage(checkout: Path, where: Path) -> Path:
    """Make ``where/layersim`` link the checkout's package folders; return ``where``."""
    checkout = Path(checkout).resolve()
    pkg = Path(where) / "layersim"
    pkg.mkdir(parents=True)
    for entry in (checkout / "layersim").iterdir():
        (pkg / entry.name).symlink_to(entry)
    for sub in ("kernels", "montecarlo"):
        (pkg / sub).symlink_to(checkout / sub)
    return Path(where)


def worker_env(site: Path) -> dict:
    """The environment of a worker importing from ``site`` first (the rest of ``PYTHONPATH``
    stays: where warp may be installed)."""
    path = os.pathsep.join(filter(None, [str(site), os.environ.get("PYTHONPATH")]))
    return dict(os.environ, PYTHONPATH=path)
