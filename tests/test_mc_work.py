"""Path ranges and exact tallies (montecarlo/work.py, estimates.TallySum)."""

import math

import numpy as np
import pytest

from layersim import Scene
from layersim.montecarlo.estimates import TallySum
from layersim.montecarlo.work import PathRange, Walk, run_range, split

SLAB = {"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
                   {"kind": "medium", "tau": 1.0, "albedo": 0.8, "g": 0.5}]}


def _walk(seed=7):
    scene = Scene.from_dict(SLAB)
    wi = (math.sin(0.5), 0.0, math.cos(0.5))
    return Walk(scene, wi, (0.0, 0.5, 1.0), (0.0, math.pi, 2 * math.pi), seed, 1000, "warp-cpu")


def test_any_split_gives_the_same_integers():
    walk = _walk()
    whole = run_range(PathRange(walk, 0, 3000))
    parts = [run_range(r) for r in split(walk, 0, 3000, 700)]
    summed = parts[0]
    for p in reversed(parts[1:]):          # order does not matter either
        summed = summed + p
    assert summed.particles == whole.particles == 3000
    assert summed.events == whole.events
    assert np.array_equal(summed.w, whole.w)


def test_ranges_differ_and_seeds_differ():
    walk = _walk()
    a = run_range(PathRange(walk, 0, 500))
    b = run_range(PathRange(walk, 500, 500))
    c = run_range(PathRange(_walk(seed=8), 0, 500))
    assert not np.array_equal(a.w, b.w)
    assert not np.array_equal(a.w, c.w)


def test_words_round_trip_beyond_int64():
    t = TallySum(3)
    t.w[...] = (1 << 95) + 12345
    t.w[0, 1, 2] = 0
    t.particles, t.events, t.truncated = (1 << 63) + 5, (1 << 70), 0
    w, counts = t.to_words()
    assert w.dtype == np.uint64 and w.shape == (2, 2, 3, 3)
    back = TallySum.from_words(w, counts)
    assert np.array_equal(back.w, t.w)
    assert (back.particles, back.events, back.truncated) == (t.particles, t.events, t.truncated)


def test_tallies_of_different_bins_do_not_add():
    with pytest.raises(ValueError, match="different bins"):
        TallySum(3) + TallySum(4)
