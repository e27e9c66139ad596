"""Isotropic layer calculus: published tables, closed forms, conservation, reciprocity and the
algebra of the adding equations."""

import numpy as np
import pytest
import scipy.sparse as sps

import layersim
from layersim.stacking import adding
from layersim.config import configure
from layersim.errors import InfeasibleError, OperatorError
from layersim.ingredients import diffuse_operator, interface_operator, medium_operator
from layersim.operators.operator import Grid, IsoOperator
from layersim.scene import Conductor, Dielectric

from conftest import unit

GRID = Grid.make("gauss-lobatto", 48)
M = 24


def close_ops(a, b, rtol):
    for name in ("Rt", "Rb", "Ttb", "Tbt"):
        if a.blocks[name] is None:
            assert b.blocks[name] is None
            continue
        for l in range(max(a.m, b.m)):
            x, y = a.block(name, l).toarray(), b.block(name, l).toarray()
            scale = max(np.abs(y).max(), 1e-300)
            assert np.abs(x - y).max() <= rtol * scale, (name, l, np.abs(x - y).max() / scale)


def reciprocity_error(op):
    worst = 0.0
    for l in range(op.m):
        f = {k: op.coefficients(k, l) for k, v in op.blocks.items() if v is not None}
        scale = max(np.abs(v).max() for v in f.values()) + 1e-300
        for k in ("Rt", "Rb"):
            if k in f:
                worst = max(worst, np.abs(f[k] - f[k].T).max() / scale)
        if "Ttb" in f:
            diff = f["Ttb"] / op.eta_bottom ** 2 - f["Tbt"].T / op.eta_top ** 2
            worst = max(worst, np.abs(diff).max() / scale)
    return worst


# ---- published reference: van de Hulst (1980), Vol. 1, Table 12 ------------------------------

def test_van_de_hulst_table_12_isotropic_slab():
    """tau = 2, albedo 0.9, mu_i = 0.9: reflected intensity pi f (Jakob's layerlab tutorial, sec. 6.1)."""
    scene = layersim.Scene.from_dict({"layer": [{"kind": "medium", "albedo": 0.9, "tau": 2.0}],
                                      "discretization": {"n": 200}})
    bsdf = layersim.solve(scene)
    mu_o = np.array([0.1, 0.3, 0.5, 0.7, 0.9, 1.0])
    table = np.array([0.45143, 0.43807, 0.40866, 0.37554, 0.34382, 0.32910])
    wi = np.array([np.sqrt(1 - 0.81), 0.0, 0.9])
    wo = np.stack([-np.sqrt(1 - mu_o ** 2), 0 * mu_o, mu_o], axis=-1)
    got = np.pi * bsdf.eval(wi, wo)
    np.testing.assert_allclose(got, table, rtol=1e-4)
    R, T = bsdf.albedo(wi)
    assert R == pytest.approx(0.38040, abs=1e-5)   # flux column of the same table row


# ---- closed forms --------------------------------------------------------------------------

def test_lambertian_base_reflects_exactly_its_albedo():
    bsdf = layersim.solve(layersim.Scene.from_dict({"layer": [{"kind": "diffuse",
                                                                "albedo": 0.7}]}))
    wi = unit([0.0, 30.0, 75.0, 89.0])
    R, T = bsdf.albedo(wi)
    np.testing.assert_allclose(R, 0.7, rtol=1e-13)
    np.testing.assert_array_equal(T, 0.0)
    # pointwise: albedo / pi, normalised by the grid's hemispherical flux integral
    grid = bsdf.grid
    expected = 0.7 / (2 * np.pi * np.sum(grid.w * grid.mu))
    np.testing.assert_allclose(bsdf.eval(wi, unit([10.0, 50.0, 60.0, 5.0], 77.0)), expected,
                               rtol=1e-12)
    assert expected == pytest.approx(0.7 / np.pi, rel=1e-3)


def test_smooth_limit_fresnel_at_normal_incidence():
    bsdf = layersim.solve(layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.1}]}))
    R, T = bsdf.albedo(unit(0.0))
    assert R == pytest.approx(0.04, abs=5e-5)
    assert T == pytest.approx(0.96, abs=5e-5)
    R, T = bsdf.albedo(unit(0.0, below=True))  # from inside the glass: the same Fresnel
    assert R == pytest.approx(0.04, abs=5e-5)


def _diffuser(grid, r, t, eta=1.0):
    """A layer that scatters r (reflected) and t (transmitted) of any beam into a Lambertian
    distribution: blocks r U and t U with the projector U = 1 fw^T / sum(fw)."""
    fw = grid.flux_weight
    U = sps.csr_matrix(np.outer(np.ones(grid.h), fw) / fw.sum())
    z = sps.csr_matrix((grid.h, grid.h))
    return IsoOperator(grid, {"Rt": [r * U, z], "Rb": [r * U, z], "Ttb": [t * U, z],
                              "Tbt": [t * U, z]}, eta, eta)


def test_adding_two_scalar_diffusers_gives_the_stokes_sums():
    """Stokes (1860) / Jakob's layerlab tutorial, eq. (1): R = r1 + t1^2 r2 / (1 - r1 r2), T = t1 t2 / (1 - r1 r2)."""
    r1, t1, r2, t2 = 0.3, 0.6, 0.5, 0.25
    stack = adding.add(_diffuser(GRID, r1, t1), _diffuser(GRID, r2, t2))
    alb = stack.albedo_nodes()
    np.testing.assert_allclose(alb["Rt"], r1 + t1 ** 2 * r2 / (1 - r1 * r2), rtol=1e-13)
    np.testing.assert_allclose(alb["Ttb"], t1 * t2 / (1 - r1 * r2), rtol=1e-13)
    np.testing.assert_allclose(alb["Rb"], r2 + t2 ** 2 * r1 / (1 - r1 * r2), rtol=1e-13)
    # a glass plate: two identical non-absorbing diffusers, R + T = 1
    plate = adding.add(_diffuser(GRID, 0.04, 0.96), _diffuser(GRID, 0.04, 0.96))
    a = plate.albedo_nodes()
    np.testing.assert_allclose(a["Rt"], 0.04 + 0.96 ** 2 * 0.04 / (1 - 0.04 ** 2), rtol=1e-13)
    np.testing.assert_allclose(a["Rt"] + a["Ttb"], 1.0, rtol=1e-14)


# ---- conservation --------------------------------------------------------------------------

@pytest.mark.parametrize("g", [0.0, 0.7, -0.5])
def test_conservative_slab_conserves_energy(g):
    op = medium_operator(GRID, M, 1.0, g, 3.0, 1.0)
    a = op.albedo_nodes()
    np.testing.assert_allclose(a["Rt"] + a["Ttb"], 1.0, atol=1e-12)
    np.testing.assert_allclose(a["Rb"] + a["Tbt"], 1.0, atol=1e-12)
    absorbing = medium_operator(GRID, M, 0.8, g, 3.0, 1.0).albedo_nodes()
    assert np.all(absorbing["Rt"] + absorbing["Ttb"] < 1.0 - 1e-3)


def test_thick_conservative_slab_stays_finite_and_conserving():
    op = medium_operator(GRID, 1, 1.0, 0.0, 1e4, 1.0)
    a = op.albedo_nodes()
    assert np.all(np.isfinite(a["Rt"]))
    np.testing.assert_allclose(a["Rt"] + a["Ttb"], 1.0, atol=1e-9)
    assert np.all(a["Ttb"] < 2e-4)  # diffusion: T ~ 4/(3 tau) for tau -> infinity


def test_stacks_never_create_energy(coated_gold, rough_glass):
    for bsdf in (coated_gold, rough_glass):
        a = bsdf.operators[0].albedo_nodes()
        assert np.all(a["Rt"] + a.get("Ttb", 0.0) <= 1.0 + 1e-9)
        assert np.all(a["Rt"] > 0)
    # lacquer over a conservative HG slab (transmissive stack, all four blocks)
    d = interface_operator(GRID, M, Dielectric(ior=1.5, alpha_u=0.3, alpha_v=0.3), 1.0)
    stack = adding.add(d, medium_operator(GRID, M, 1.0, 0.5, 2.0, 1.5))
    a = stack.albedo_nodes()
    assert np.all(a["Rt"] + a["Ttb"] <= 1.0 + 1e-9)
    assert np.all(a["Rb"] + a["Tbt"] <= 1.0 + 1e-9)


# ---- reciprocity ---------------------------------------------------------------------------

def test_every_ingredient_and_stack_is_reciprocal(coated_gold, rough_glass):
    d = interface_operator(GRID, M, Dielectric(ior=1.5, alpha_u=0.3, alpha_v=0.3), 1.0)
    c = interface_operator(GRID, M, Conductor(ior=complex(0.2, 3.0), alpha_u=0.2,
                                              alpha_v=0.2), 1.5)
    hg = medium_operator(GRID, M, 0.9, 0.6, 1.5, 1.5)
    diff = diffuse_operator(GRID, 0.5, 1.5)
    for op in (d, c, hg, diff, adding.add(d, hg), adding.add(d, adding.add(hg, c)),
               coated_gold.operators[0], rough_glass.operators[0]):
        assert reciprocity_error(op) < 1e-10


def test_projection_of_all_blocks_is_reciprocal_without_the_shortcut():
    """Projecting every block independently (no reciprocity shortcut) reproduces the
    shortcut's operator: this checks the physics and the projection against reciprocity."""
    layer = Dielectric(ior=1.5, alpha_u=0.3, alpha_v=0.3)
    full = interface_operator(GRID, M, layer, 1.0, reciprocity=False)
    short = interface_operator(GRID, M, layer, 1.0)
    close_ops(full, short, rtol=1e-4)
    assert reciprocity_error(full) < 1e-4


def test_eval_is_reciprocal_in_the_radiance_convention(rough_glass):
    rng = np.random.default_rng(7)
    from conftest import random_directions
    for lower in (False, True):
        wi = random_directions(rng, 300)
        wo = random_directions(rng, 300, lower)
        f_io = rough_glass.eval(wi, wo)
        f_oi = rough_glass.eval(wo, wi)
        eta_i, eta_o = 1.0, (1.5 if lower else 1.0)
        np.testing.assert_allclose(f_io / eta_o ** 2, f_oi / eta_i ** 2, rtol=1e-8,
                                   atol=1e-10 * np.abs(f_io).max())


# ---- algebra -------------------------------------------------------------------------------

def test_adding_is_associative():
    a = interface_operator(GRID, M, Dielectric(ior=1.5, alpha_u=0.3, alpha_v=0.3), 1.0)
    b = medium_operator(GRID, M, 0.9, 0.5, 1.0, 1.5)
    c = interface_operator(GRID, M, Dielectric(ior=1.0, alpha_u=0.2, alpha_v=0.2), 1.5)
    close_ops(adding.add(adding.add(a, b), c), adding.add(a, adding.add(b, c)), rtol=1e-10)
    base = diffuse_operator(GRID, 0.6, 1.0)
    close_ops(adding.add(adding.add(a, b), adding.add(c, base)),
              adding.add(a, adding.add(adding.add(b, c), base)), rtol=1e-10)


def test_adding_an_index_matched_clear_layer_is_a_no_op():
    a = interface_operator(GRID, M, Dielectric(ior=1.5, alpha_u=0.3, alpha_v=0.3), 1.0)
    clear = IsoOperator.identity(GRID, M, 1.5)
    close_ops(adding.add(a, clear), a, rtol=1e-14)
    close_ops(adding.add(IsoOperator.identity(GRID, M, 1.0), a), a, rtol=1e-14)
    empty = medium_operator(GRID, M, 0.9, 0.3, 0.0, 1.5)   # tau = 0
    close_ops(adding.add(a, empty), a, rtol=1e-14)


@pytest.mark.parametrize("g", [0.0, 0.8])
def test_adding_doubling_of_tau_equals_adding_two_halves(g):
    full = medium_operator(GRID, M, 0.95, g, 3.0, 1.0)
    half = medium_operator(GRID, M, 0.95, g, 1.5, 1.0)
    close_ops(adding.add(half, half), full, rtol=1e-10)
    assert np.allclose(adding.add(half, half).delta["Ttb"], full.delta["Ttb"], rtol=1e-14)


def test_threaded_adding_equals_serial_adding():
    """layerlab's HG layers went wrong when built in parallel; ours must not."""
    hg = medium_operator(GRID, M, 0.9, 0.7, 0.5, 1.0)
    serial = adding.add(hg, hg, threads=1)
    parallel = adding.add(hg, hg, threads=2)
    close_ops(parallel, serial, rtol=0.0)


@pytest.mark.parametrize("opaque", [False, True])
def test_sparse_and_dense_orders_agree(monkeypatch, opaque):
    """Each order is added with dense LAPACK or sparse LU (by density and size of its
    blocks), or, below SPARSE_MIN_H ordinates, all orders dense in stacked batches: all three
    give the same operator (orders forced each way; batches of 5 orders, the last short)."""
    top = interface_operator(GRID, M, Dielectric(ior=1.5, alpha_u=0.2, alpha_v=0.2), 1.0)
    if opaque:
        bottom = interface_operator(GRID, M, Conductor(ior=complex(0.2, 3.0), alpha_u=0.3,
                                                       alpha_v=0.3), 1.5)
    else:
        bottom = medium_operator(GRID, M, 0.9, 0.6, 0.8, 1.5)
    monkeypatch.setattr(adding, "SPARSE_MIN_H", 0)
    monkeypatch.setattr(adding, "SPARSE_DENSITY", 2.0)          # every order sparse
    sparse = adding.add(top, bottom)
    monkeypatch.setattr(adding, "SPARSE_DENSITY", 0.0)          # every order dense
    dense = adding.add(top, bottom)
    close_ops(sparse, dense, rtol=1e-10)
    assert (sparse.blocks["Ttb"] is None) == opaque
    monkeypatch.setattr(adding, "SPARSE_MIN_H", GRID.h + 1)      # batches of orders
    monkeypatch.setattr(adding, "ORDER_BATCH_ELEMENTS", 5 * GRID.h ** 2)
    batched = adding.add(top, bottom)
    close_ops(batched, dense, rtol=1e-13)
    for name, blk in batched.blocks.items():                   # same entries, per order
        if blk is not None:
            assert len(blk) == M
            assert all(blk[l].nnz == dense.blocks[name][l].nnz for l in range(M))


def test_adding_mixes_dense_runs_and_sparse_orders(monkeypatch):
    """With the density threshold inside the range of the orders' densities, one adding step
    groups its orders into dense batches and sparse runs covering every order once; the
    operator agrees with the all-dense one, order by order, to round-off."""
    top = interface_operator(GRID, M, Dielectric(ior=1.5, alpha_u=0.1, alpha_v=0.1), 1.0)
    bottom = medium_operator(GRID, M, 0.9, 0.6, 0.8, 1.5)
    monkeypatch.setattr(adding, "SPARSE_MIN_H", 0)
    monkeypatch.setattr(adding, "SPARSE_DENSITY", 0.0)
    dense = adding.add(top, bottom)
    counts = sum(op.order_nnz(k, M) for op, k in ((top, "Rb"), (top, "Ttb"), (top, "Tbt"),
                                                  (bottom, "Rt"), (bottom, "Rb"),
                                                  (bottom, "Ttb"), (bottom, "Tbt")))
    density = counts / (7 * GRID.h ** 2)
    threshold = np.median(density)
    monkeypatch.setattr(adding, "SPARSE_DENSITY", 1.0)
    growth = adding.sparse_density(GRID.h)          # the factor of SPARSE_DENSITY at this h
    monkeypatch.setattr(adding, "SPARSE_DENSITY", threshold / growth)
    assert adding.sparse_density(GRID.h) == pytest.approx(threshold)
    monkeypatch.setattr(adding, "ORDER_BATCH_ELEMENTS", 3 * GRID.h ** 2)
    tasks = adding.order_tasks(top, bottom, M, opaque=False)
    assert [l for orders, _ in tasks for l in orders] == list(range(M))
    assert {kind for _, kind in tasks} == {True, False}
    for orders, kind in tasks:
        assert all((density[l] >= threshold) == kind for l in orders)
        assert not kind or len(orders) <= 3
    mixed = adding.add(top, bottom)
    close_ops(mixed, dense, rtol=1e-10)


def test_adding_refuses_mismatched_operators():
    a = interface_operator(GRID, M, Dielectric(ior=1.5, alpha_u=0.3, alpha_v=0.3), 1.0)
    other = medium_operator(Grid.make("gauss-lobatto", 50), M, 0.5, 0.0, 1.0, 1.5)
    with pytest.raises(OperatorError, match="different grids"):
        adding.add(a, other)
    with pytest.raises(OperatorError, match="index mismatch"):
        adding.add(a, medium_operator(GRID, M, 0.5, 0.0, 1.0, 1.0))
    with pytest.raises(OperatorError, match="opaque"):
        adding.add(diffuse_operator(GRID, 0.5, 1.0), a)


# ---- stiff cases and refusals --------------------------------------------------------------

@pytest.mark.parametrize("alpha,n", [(0.3, 128), (0.5, 96)])
def test_rough_coatings_at_high_resolution_are_finite_and_conserving(alpha, n):
    """layerlab crashes for coatings with alpha >= 0.2 at n >= ~92."""
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": alpha},
        {"kind": "medium", "albedo": 0.99, "g": 0.3, "tau": 1.0},
        {"kind": "diffuse", "albedo": 0.8}], "discretization": {"n": n}})
    bsdf = layersim.solve(scene)
    R, T = bsdf.albedo(unit([0.0, 45.0, 85.0]))
    assert np.all(np.isfinite(R)) and np.all((R > 0.3) & (R < 1.0))


def test_smooth_interface_alone_is_fresnel_and_snell():
    """A bare smooth interface: R = F and T = 1 - F, both deltas, T along the refracted
    direction (layersim.solved.boundary)."""
    from layersim.kernels.fresnel import fresnel
    scene = layersim.Scene.from_dict({"layer": [{"kind": "dielectric", "ior": 1.5}]})
    bsdf = layersim.solve(scene)
    wi = unit([0.0, 45.0, 85.0])
    R, T = bsdf.albedo(wi)
    F = fresnel(wi[:, 2], 1.5)
    assert np.allclose(R, F, atol=1e-12) and np.allclose(T, 1 - F, atol=1e-12)
    wt = bsdf.specular(wi)["bottom"][1]
    assert np.allclose(np.hypot(wt[:, 0], wt[:, 1]) * 1.5, np.hypot(wi[:, 0], wi[:, 1]))
    assert np.all(wt[:, 2] < 0)


def test_nearly_index_matched_interface_is_refused_up_front():
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.0001, "roughness": 0.1}]})
    with pytest.raises(InfeasibleError, match="layer 0 \\(dielectric\\).*refraction lobe.*ordinates"):
        layersim.make_plan(scene)


def test_memory_limit_is_enforced_before_any_heavy_work():
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.1},
        {"kind": "conductor", "ior": [0.143552, 3.98397], "roughness": 0.1}]})
    with configure(max_memory=1_000_000), \
            pytest.raises(InfeasibleError, match="GiB.*LAYERSIM_MAX_MEMORY"):
        layersim.solve(scene)


def test_under_resolved_override_is_refused_instead_of_creating_energy():
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.02}], "discretization": {"n": 64}})
    assert any("below the" in note for note in layersim.make_plan(scene).notes)
    with pytest.raises(InfeasibleError, match="layer 0 \\(dielectric\\).*raise n"):
        layersim.solve(scene)


def test_plan_reports_what_it_leaves_out():
    plan = layersim.make_plan(layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.0, "roughness": 0.3},     # index matched: no-op
        {"kind": "medium", "albedo": 0.5, "tau": 0.0},            # empty medium: no-op
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
        {"kind": "diffuse", "albedo": 0.5}]}))
    text = plan.report()
    assert "index-matched" in text and "tau = 0" in text
    assert "transmission blocks" in text and "opaque" in text
    assert "ms = 0" in text
    assert [lp.action for lp in plan.layers] == ["left out", "left out", "project", "diffuse"]


def test_energy_limiter_removes_overcounting_and_keeps_reciprocity():
    from layersim.operators.energy import limit_energy, node_energy
    d = interface_operator(GRID, M, Dielectric(ior=1.5, alpha_u=0.3, alpha_v=0.3), 1.0)
    # simulate a quadrature that over-counts the lobes of a few ordinates by 0.5 %
    bump = np.ones(GRID.h)
    bump[-4:] = 1.0025   # near-normal ordinates, where R + T is within 1e-5 of 1
    B = sps.diags(bump)
    for name in ("Rt", "Ttb", "Rb", "Tbt"):
        d.blocks[name] = [(B @ mat @ B).tocsr() for mat in d.blocks[name]]
    top, bot = node_energy(d, np.ones(GRID.h), np.ones(GRID.h))
    assert max(top.max(), bot.max()) > 1.0 + 1e-3
    excess, scaled = limit_energy(d)
    assert excess > 1e-3 and scaled > 0
    top, bot = node_energy(d, np.ones(GRID.h), np.ones(GRID.h))
    assert max(top.max(), bot.max()) <= 1.0 + 1e-12
    assert reciprocity_error(d) < 1e-10


def test_operator_assembly_dense_and_sorted_paths_agree(monkeypatch):
    """_orders_to_csr scatters small operators into a dense array and sorts the triplets of
    large ones: both must give the same pruned per-order blocks (sorted by row, then column)."""
    from layersim.operators import operator as opmod
    grid = opmod.Grid.make("gauss-legendre", 24)
    rng = np.random.default_rng(3)
    h, m = grid.h, 7
    chunks = []
    for _ in range(3):
        o, i = rng.integers(0, h, 40), rng.integers(0, h, 40)
        c = rng.normal(size=(40, m + 2)) * (rng.random((40, m + 2)) > 0.3)
        c[0, 1] = 1e-15  # below the drop tolerance of its order
        chunks.append((o, i, c))
    # pairs must be unique across chunks, as the projection produces them
    seen, unique = set(), []
    for o, i, c in chunks:
        keep = [k for k in range(o.size) if (o[k], i[k]) not in seen and not seen.add((o[k], i[k]))]
        unique.append((o[keep], i[keep], c[keep]))
    dense = opmod._orders_to_csr(unique, m, grid)
    monkeypatch.setattr(opmod, "DENSE_ASSEMBLY_MAX", 0)
    srt = opmod._orders_to_csr(unique, m, grid)
    for l in range(m):
        assert dense[l].has_sorted_indices and srt[l].has_sorted_indices
        assert dense[l].nnz == srt[l].nnz
        np.testing.assert_allclose(dense[l].toarray(), srt[l].toarray(), rtol=1e-15)
        ref = np.zeros((h, h))
        for o, i, c in unique:
            ref[o, i] = c[:, l] * grid.flux_weight[i] * opmod.order_weight(l)
        ref[np.abs(ref) < opmod.DROP_TOLERANCE * np.abs(ref).max()] = 0.0
        np.testing.assert_allclose(dense[l].toarray(), ref, rtol=1e-15)


def test_operator_assembly_slabs_of_orders(monkeypatch):
    """_orders_to_csr in slabs of a few orders (small scratch limit), with a chunk whose series
    stops short of m: the same stacked CSR arrays, bit for bit, as one slab of every order and
    as the sorted triplets, and the entries of a dense reference (B_l = c_l f_l w_i mu_i,
    pruned per order)."""
    from layersim.operators import operator as opmod
    grid = opmod.Grid.make("gauss-lobatto", 30)
    rng = np.random.default_rng(5)
    h, m = grid.h, 9
    o, i = np.divmod(rng.permutation(h * h)[:150], h)
    c = rng.normal(size=(150, m)) * 10.0 ** rng.integers(-15, 0, size=(150, 1))
    c[rng.random(c.shape) < 0.4] = 0.0
    chunks = [(o[:100], i[:100], c[:100]), (o[100:], i[100:], c[100:, :4])]   # short series
    one = opmod._orders_to_csr(chunks, m, grid)
    monkeypatch.setattr(opmod, "DENSE_ASSEMBLY_MAX", 2 * 150)                  # 2 orders a slab
    slabs = opmod._orders_to_csr(chunks, m, grid)
    monkeypatch.setattr(opmod, "DENSE_ASSEMBLY_MAX", 0)                        # sorted triplets
    srt = opmod._orders_to_csr(chunks, m, grid)
    for other in (slabs, srt):
        for a, b in ((one._data, other._data), (one._indices, other._indices),
                     (one._indptr, other._indptr)):
            np.testing.assert_array_equal(a, b)
    for l in range(m):
        ref = np.zeros((h, h))
        for ok, ik, ck in chunks:
            if l < ck.shape[1]:
                ref[ok, ik] = ck[:, l] * grid.flux_weight[ik] * opmod.order_weight(l)
        ref[np.abs(ref) < opmod.DROP_TOLERANCE * np.abs(ref).max()] = 0.0
        assert one[l].has_sorted_indices and one[l].nnz == np.count_nonzero(ref)
        np.testing.assert_array_equal(one[l].toarray(), ref)


def test_order_stack_views_and_file_round_trip(tmp_path):
    """OrderStack: per-order CSR views of the stacked arrays (indexing, negative indices,
    slices), consistency checks, and an operator file round trip that keeps every order."""
    import scipy.sparse as sps
    from layersim.errors import OperatorError
    from layersim.operators.operator import Grid, IsoOperator, OrderStack
    rng = np.random.default_rng(0)
    h, m = 5, 4
    dense = rng.random((m, h, h)) * (rng.random((m, h, h)) < 0.4)
    stack = OrderStack.from_csr(sps.csr_matrix(dense.reshape(m * h, h)), h)
    assert len(stack) == m
    for l in range(m):
        np.testing.assert_array_equal(stack[l].toarray(), dense[l])
    np.testing.assert_array_equal(stack[-1].toarray(), dense[-1])
    assert [mat.shape for mat in stack[1:3]] == [(h, h), (h, h)]
    with pytest.raises(IndexError):
        stack[m]
    with pytest.raises(OperatorError):
        OrderStack(np.ones(3), np.zeros(3, np.int32), np.zeros(m * h), h)
    grid = Grid.make("gauss-lobatto", 2 * h)
    op = IsoOperator(grid, {"Rt": stack}, 1.0, None)
    path = tmp_path / "op.npz"
    np.savez(path, **op.to_arrays())
    back = IsoOperator.from_arrays(np.load(path))
    for l in range(m):
        np.testing.assert_array_equal(back.block("Rt", l).toarray(), dense[l])
