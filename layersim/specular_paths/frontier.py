"""Which paths are traced and which are walked, at one incident wave vector.

Enumeration (:func:`.paths.enumerate_paths`) keeps every branch above the pruning at *some*
probe direction, so at a given incidence it keeps long paths whose central energy is tiny there:
light trapped between faces by total internal reflection after a slope deviation (a pane at
70 degrees, a coat over a bright metal). Such a path carries its light in the tails of its
events' lobes: where it enters the trapped region and where it leaves it. Tracing it on its
own (:func:`.trace.trace_path`) draws both from the lobes' cores and converges slowly (a GGX
pane of eta 1.3 at 70 degrees: transmittance off by 6e-3 at 4096 nodes per path, 1.8e-3 at
262144), while a walk over the faces (:mod:`.continuation`) follows the trapped light wherever
it goes, one walker per node. So at the incident wave vector ``p_i`` a branch whose central
energy there falls below :data:`WALK_BELOW` after a near-specular event is walked from that
prefix on, and only the paths above it are traced (:func:`split`). Every path of the tree lies
in exactly one of the two sets: a kept path, or the subtree of one walked prefix (the
enumeration's own cut branches included), so nothing is counted twice.

Paths of smooth events only are never walked (their energies are exact), nor is a path with one
near-specular event (its BSDF is exact, :meth:`.model.PathModel.eval_path`).
"""

from __future__ import annotations

import numpy as np

from .paths import Events, Path

__all__ = ["WALK_BELOW", "split"]

#: A branch whose central energy at the incident wave vector is below this fraction of the
#: incident power, after at least one near-specular event, is walked. Measured at 70 degrees on
#: stacks of ``benchmarks/accuracy/near_specular_anywhere.py`` against their 1e7-path walks
#: (GGX pane of eta 1.3, glass pane, pane with a smooth front, RGB coat over RGB gold): walking
#: nothing but the enumeration's cut branches leaves the trapped light of kept paths to tracing
#: (the GGX pane: transmittance 6.3 tolerances off, 52 % of the bins within 3 sigma); walking
#: below 3e-3, 1e-2 and 3e-2 gives 88 %, 91 % and 92 % there, and 3e-2 is as good or better on
#: the others (96.7-100 %); above it the same paths are kept.
WALK_BELOW = 3e-2


def _direction_after(step: tuple) -> bool:
    """Direction of travel (down) after one step ``(element, down, what)``."""
    _, down, what = step
    return (not down) if what == "R" else down


def _central(ev: Events, path: Path) -> np.ndarray:
    """Central energy (largest channel) of every prefix of ``path``: entry ``k - 1`` is that
    of its first ``k`` steps, at the wave vector of ``ev``."""
    w = np.ones(ev.chain.channels)
    out = np.empty(len(path.steps))
    for s, (e, down, what) in enumerate(path.steps):
        w = w * ev.step(e, down, what, path.gaps[s])[0]
        out[s] = w.max()
    return out


def _cut(path: Path, rough: list, ev: Events, complete: bool, below: float):
    """Length of the shortest prefix of ``path`` to walk (None: keep it). ``rough`` are the
    indices of its near-specular steps; ``complete`` whether ``path`` leaves the chain (a
    complete path with one near-specular event is kept: it is exact)."""
    if not rough or (complete and len(rough) == 1):
        return None
    last = len(path.steps) if complete else len(path.steps) - 1
    low = np.flatnonzero(_central(ev, path)[rough[0]:last] < below)
    return int(rough[0] + low[0] + 1) if low.size else None


def split(model, top: bool, p_i: np.ndarray, below: float | None = None):
    """The kept paths to trace and the prefixes to walk for light entering at the top
    (``top``) or bottom of ``model`` (:class:`.model.PathModel`) with wave vector ``p_i``
    (2,), walking below ``below`` (default :data:`WALK_BELOW`; 0 walks only the
    enumeration's cut branches).

    Returns
    -------
    entries : list
        The model's entries (paths with their lobes) traced at ``p_i``.
    prefixes : list of (Path, bool)
        Walked prefixes and the direction of travel (down) at their ends, none a prefix of
        another; the enumeration's own cut branches stay unless a shorter walked prefix
        contains them.
    """
    below = WALK_BELOW if below is None else below
    chain = model.chain
    ev = Events(chain, model.faces, np.asarray(p_i, float).reshape(1, 2))
    entries, walked = [], {}
    for x in model.entries[top]:
        k = _cut(x.path, x.steps, ev, True, below)
        if k is None:
            entries.append(x)
        else:
            walked[x.path.steps[:k]] = x.path
    for path, down in model.sets[top].frontier:
        k = _cut(path, path.rough_steps(chain), ev, False, below)
        if k is None:
            walked[path.steps] = (path, down)
        else:
            walked[path.steps[:k]] = path
    prefixes, seen = [], []
    for steps in sorted(walked, key=len):
        if any(steps[:len(s)] == s for s in seen):
            continue                   # inside the subtree of a shorter walked prefix
        seen.append(steps)
        item = walked[steps]
        if isinstance(item, tuple):
            prefixes.append(item)
        else:
            k = len(steps)
            prefixes.append((Path(steps, item.gaps[:k + 1], item.start_top, False),
                             _direction_after(steps[-1])))
    # a kept path below a walked prefix (one near-specular event, the rest smooth) is the
    # walk's: dropped here so that it is counted once
    entries = [x for x in entries if not any(x.path.steps[:len(s)] == s for s in seen)]
    return entries, prefixes
