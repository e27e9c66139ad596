"""The structure of the plan's cost model (layersim.plan.cost): what its memory and time
estimates count and how they scale. The estimates themselves are measured against solves in
benchmarks/speed/plan_estimates.py, not here."""

import numpy as np
import pytest

import layersim
from layersim.config import configure
from layersim.errors import InfeasibleError
from layersim.ingredients import microfacet
from layersim.operators.operator import Grid
from layersim.plan import budget, cost, make_plan
from layersim.plan.orders import interface_lengths
from layersim.scene import Scene

GOLD = [0.143552, 3.98397]
COAT = {"kind": "dielectric", "ior": 1.5, "roughness": 0.1}


def _ings(scene):
    plan = make_plan(scene, refuse=False)
    lengths = interface_lengths(plan.grid, scene.channel(0), plan.layers)
    return plan, cost.ingredients(scene, plan.layers, lengths, plan.grid, plan.md)


def _scene(*layers, **disc):
    data = {"layer": list(layers)}
    if disc:
        data["discretization"] = disc
    return Scene.from_dict(data)


def test_layers_shared_by_the_channels_are_built_once():
    """An RGB stack whose coat and medium are the same in every channel builds them once: only
    the coloured base is projected per channel, while every channel runs its adding."""
    medium = {"kind": "medium", "tau": 0.5, "albedo": 0.8, "g": 0.3}
    mono = _scene(COAT, medium, {"kind": "conductor", "ior": GOLD, "roughness": 0.2},
                  n=98, md=60)
    rgb = _scene(COAT, medium, {"kind": "conductor", "ior": [GOLD, [0.5, 2.2], [1.3, 1.8]],
                                "roughness": 0.2}, n=98, md=60)
    plan1, ings1 = _ings(mono)
    plan3, ings3 = _ings(rgb)
    assert [i.variants for i in ings3] == [1, 1, 3]
    coat, base = (i.pairs * plan3.md for i in (ings3[0], ings3[2]))
    assert plan3.work["pair_orders"] == pytest.approx(coat + 3 * base, rel=0.05)
    assert plan3.work["medium_entries"] == plan1.work["medium_entries"]
    assert plan3.work["dense_cubes"] == pytest.approx(3 * plan1.work["dense_cubes"])
    # the shared operators are held once; the peak grows by less than the channels
    assert plan1.memory_bytes < plan3.memory_bytes < 3 * plan1.memory_bytes


def test_projection_work_follows_pairs_and_orders():
    """Projection work is pairs x orders: about 4x for twice the ordinates (the pairs of a
    lobe of fixed angular width grow as h^2), exactly 2x for twice the orders."""
    base = dict(n=98, md=100)
    work = lambda **d: make_plan(_scene(COAT, **{**base, **d})).work["pair_orders"]
    assert 3.5 < work(n=196) / work() < 4.5
    assert work(md=200) == pytest.approx(2 * work())


def test_medium_work_scales_with_h_cubed_and_orders():
    """A medium costs its scattering orders x h^3 and the dense (md, h, h) arrays of its
    unscattered beam."""
    medium = {"kind": "medium", "tau": 1.0, "albedo": 0.9, "g": 0.5}
    w = lambda n, md: make_plan(_scene(medium, n=n, md=md)).work
    small, big = w(64, 40), w(128, 40)
    assert big["medium_entries"] / small["medium_entries"] == pytest.approx(4.0)
    assert big["medium_cubes"] / small["medium_cubes"] == pytest.approx(8.0, rel=0.2)
    assert w(64, 80)["medium_entries"] == pytest.approx(2 * small["medium_entries"])


def test_only_dense_orders_cost_dense_lapack():
    """Below SPARSE_MIN_H ordinates every order is added densely; above it, the orders whose
    operands are sparse (a narrow coat's high orders, a medium's unscattered beam) are not
    priced as dense h^3 work."""
    stack = (COAT, {"kind": "medium", "tau": 0.5, "albedo": 0.9, "g": 0.3},
             {"kind": "conductor", "ior": GOLD, "roughness": 0.3})
    plan, ings = _ings(_scene(*stack, n=98))
    assert all(s.dense_orders == plan.md for s in cost.adding_chain(ings, plan.md, plan.grid.h))
    plan, ings = _ings(_scene(*stack, n=300))
    steps = cost.adding_chain(ings, plan.md, plan.grid.h)
    medium_orders = ings[1].orders[0]
    # the medium over the conductor: dense where the medium scatters, sparse beyond
    assert medium_orders <= steps[0].dense_orders < plan.md
    assert steps[0].sparse_nonzeros > 0


def test_memory_of_an_isotropic_solve_grows_with_its_transients():
    """The peak is at least the largest transient (an interface's projection, a medium's
    dense arrays) and grows with md."""
    scene = lambda md: _scene(COAT, {"kind": "medium", "tau": 1.0, "albedo": 0.9, "g": 0.3},
                              {"kind": "diffuse", "albedo": 0.5}, n=128, md=md)
    plan, ings = _ings(scene(100))
    transients = [cost.interface_transient(ings[0], plan.md),
                  cost.medium_transient(ings[1], plan.md, plan.grid.h)]
    assert plan.memory_bytes >= max(transients)
    assert make_plan(scene(200)).memory_bytes > plan.memory_bytes


def test_coupled_estimate_is_larger_with_resident_blocks():
    scene = _scene(COAT, {"kind": "conductor", "ior": GOLD, "roughness": [0.1, 0.3]}, n=64)
    plan, ings = _ings(scene)
    parked = cost.coupled_bytes(ings, plan.grid, plan.md, 1, parked=True)
    resident = cost.coupled_bytes(ings, plan.grid, plan.md, 1, parked=False)
    assert 0 < parked < resident
    with configure(park_dir=None):
        assert make_plan(scene).memory_bytes == resident
    assert plan.seconds["adding"] > 0 and plan.work["factor_cubes"] > 0


@pytest.mark.parametrize("kind, ior", [("dielectric", 1.5), ("conductor", GOLD)])
@pytest.mark.parametrize("alpha", [0.02, 0.1, 0.3, 1.0])
def test_pairs_lower_bound_holds(kind, ior, alpha):
    """The pair count the lower bound assumes is below the pre-pass's (which is what makes the
    refusal before the pre-pass safe)."""
    grid = Grid.make("gauss-lobatto", 96)
    layer = _scene({"kind": kind, "ior": ior, "roughness": alpha}).layers[0]
    lengths, _ = microfacet.series_lengths(grid, layer, 1.0)
    blocks = 4 if kind == "dielectric" else 1
    assert cost.pairs_lower_bound(alpha, blocks, grid.h) <= lengths.size


@pytest.mark.parametrize("layers, disc", [
    ((COAT, {"kind": "conductor", "ior": GOLD, "roughness": 0.1}), {}),
    (({"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
      {"kind": "medium", "tau": 1.0, "albedo": 0.9, "g": 0.3},
      {"kind": "conductor", "ior": GOLD, "roughness": 0.3}), {"n": 160}),
    ((COAT, {"kind": "conductor", "ior": GOLD, "roughness": [0.1, 0.3]}), {"n": 64}),
])
def test_lower_bound_is_below_the_estimate(layers, disc):
    scene = _scene(*layers, **disc)
    plan = make_plan(scene)
    mono = scene.channel(0)
    md, lower = budget.lower_bound(scene.discretization, mono, plan.layers, plan.grid, 1,
                                   plan.ms)
    assert md <= plan.md and lower <= plan.memory_bytes


def test_time_limit_refuses_a_coupled_plan_naming_ms():
    scene = _scene(COAT, {"kind": "conductor", "ior": GOLD, "roughness": [0.1, 0.3]}, n=64)
    plan = make_plan(scene)
    with configure(max_seconds=plan.seconds["total"] / 10), \
            pytest.raises(InfeasibleError, match=r"ms = \d+.*LAYERSIM_MAX_SECONDS"):
        layersim.solve(scene)
    assert np.isfinite(plan.seconds["total"])
