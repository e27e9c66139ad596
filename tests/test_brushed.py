"""Brushed near-specular top coats (layersim.layers.brushed): the route, the exact lobe in place of
the coat's own reflection, energy, reciprocity, and the walk."""

import contextlib

import numpy as np
import pytest

import layersim
from conftest import solved_vs_walk
from layersim.config import configure
from layersim.layers import brushed
from layersim.plan import make_plan
from layersim.plan import cost
from layersim.plan.budget import extrapolated_coat
from layersim.solved.lobe import NearSpecularLobe

GOLD = [0.143552, 3.98397]
#: A coarse plan for the solves of the fast tests, with the floors raised to match it: what they
#: test (which blocks hold what, energy, reciprocity, the extrapolation's linearity) does not
#: depend on the floors.
COARSE = {"n": 32, "md": 12, "ms": 4}
COARSE_FLOORS = (0.28, 0.25)


@contextlib.contextmanager
def _floors(*floors):
    """The route's floors set to ``floors`` (read when a plan is made) for the block."""
    saved, brushed.BRUSHED_FLOORS = brushed.BRUSHED_FLOORS, tuple(floors)
    try:
        yield
    finally:
        brushed.BRUSHED_FLOORS = saved


def _scene(base=None, rough=(0.03, 0.3), rotation=0.0, disc=None):
    base = {"kind": "conductor", "ior": GOLD, "roughness": 0.2} if base is None else base
    d = {"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": list(rough),
                    "rotation": rotation}] + ([base] if base else [])}
    if disc:
        d["discretization"] = disc
    return layersim.Scene.from_dict(d)


def _dirs(n, seed, upper=True):
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.15, 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    s = np.sqrt(1 - z**2)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z if upper else -z], axis=1)


def _coarse(albedo: float, floors=COARSE_FLOORS):
    """A solve on :data:`COARSE` of the coat (rotated 25 deg) over a Lambertian base."""
    with _floors(*floors):
        return layersim.solve(_scene({"kind": "diffuse", "albedo": albedo}, rotation=25.0,
                                     disc=COARSE))


def test_plan_takes_the_route_and_prints_the_floors_weights_and_error():
    """Floors (0.12, 0.1) extrapolated to 0.03: w = ((v0 - v2) / (v1 - v2), (v1 - v0) / (v1 -
    v2)) with v = alpha^2, i.e. (-2.068, +3.068); the worst measured row in the line."""
    plan = make_plan(_scene(disc={"n": 64, "md": 16, "ms": 4}))
    v0, v1, v2 = 0.03**2, 0.12**2, 0.1**2
    assert plan.brushed["floors"] == (0.12, 0.1) and plan.brushed["floor"] == 0.1
    np.testing.assert_allclose(plan.brushed["weights"],
                               [(v0 - v2) / (v1 - v2), (v1 - v0) / (v1 - v2)], rtol=1e-14)
    assert (plan.brushed["alpha_u"], plan.brushed["alpha_v"]) == (0.03, 0.3)
    text = plan.report()
    assert "narrow roughness raised to 0.12, 0.1 on one discretisation" in text
    assert "weights -2.068, +3.068" in text and "beckmann alpha=(0.1, 0.3)" in text
    worst = max(r[1] for r in brushed.MEASURED_ERROR)
    assert f"albedo within {worst:.1e}" in text
    assert "exact microfacet lobe" in text and "benchmarks/features/brushed_coats.txt" in text


def test_the_coats_own_reflection_is_neither_planned_nor_projected():
    """The exact lobe replaces the coat's own reflection: its layer plan names the other three
    blocks, the pre-pass counts only their pairs (fewer than all four blocks'), and the
    solved coat's ``Rt`` block is empty."""
    from layersim.ingredients import aniso_microfacet
    from layersim.layers.base import OperatorJob
    from layersim.layers import kind_of
    with _floors(*COARSE_FLOORS):
        plan = make_plan(_scene(disc=COARSE))
        raised = brushed.projected_scene(_scene(disc=COARSE))[0].channel(0)
    lp = next(x for x in plan.layers if x.index == 0)
    assert lp.blocks == ("Rb", "Ttb", "Tbt")
    coat = raised.layers[0]
    full = aniso_microfacet.series_lengths(plan.grid, coat, 1.0, lp.ms, 1e-4)[0]
    part = aniso_microfacet.series_lengths(plan.grid, coat, 1.0, lp.ms, 1e-4, lp.blocks)[0]
    assert 0 < part.size < full.size
    job = OperatorJob(plan, plan.grid, raised, 0, aniso_microfacet.AnisoProjectionStats())
    op = kind_of(coat).operator(job)
    assert op.blocks["Rt"].nnz == 0 and op.blocks["Ttb"].nnz > 0


def test_the_weights_follow_the_floor_the_narrow_axis_reaches():
    """A floor above the wide roughness raises the narrow axis only to the wide one: its
    variance in the weights is the wide one's."""
    plan = make_plan(_scene(rough=(0.02, 0.11), disc={"n": 32, "md": 12, "ms": 2}))
    v0, v1, v2 = 0.02**2, 0.11**2, 0.1**2
    np.testing.assert_allclose(plan.brushed["weights"],
                               [(v0 - v2) / (v1 - v2), (v1 - v0) / (v1 - v2)], rtol=1e-14)


def test_the_plan_counts_a_projection_per_floor_and_one_adding():
    """Two floors on one plan: twice one floor's projection time, the adding's once, and its
    memory with the raised operators held while they are combined."""
    scene = _scene(disc={"n": 64, "md": 16, "ms": 4})
    with _floors(0.1):
        one = make_plan(scene)
    two = make_plan(scene)
    assert (one.n, one.md, one.ms) == (two.n, two.md, two.ms)
    assert two.seconds["projection"] == pytest.approx(2 * one.seconds["projection"], rel=1e-12)
    assert two.seconds["adding"] == pytest.approx(one.seconds["adding"], rel=1e-12)
    assert one.memory_bytes < two.memory_bytes


def test_extrapolated_coat_cost_closed_form():
    work = {"coupled_coefficients": 1e6, "coupled_entries": 1e6, "solve": 1.0}
    mem, sec, out = extrapolated_coat(1000, work, 3, 10)
    assert out == {"coupled_coefficients": 3e6, "coupled_entries": 1e6, "solve": 3.0}
    assert sec == cost.seconds(out) and mem == 1000 + 4 * 10
    assert extrapolated_coat(1000, work, 1, 10) == (1000, cost.seconds(work), work)


@pytest.mark.slow
def test_the_coat_operator_is_the_weighted_sum_of_the_floors_operators():
    """The operator the stack adds once is ``w1 A1 + w2 A2`` of the raised coat's operators at
    each floor (each energy-matched, its own reflection left out), block by block; the floors
    do differ, so the sum is not one floor's."""
    from dataclasses import replace
    from layersim.ingredients.aniso_microfacet import AnisoProjectionStats
    from layersim.layers import kind_of
    from layersim.layers.base import OperatorJob
    with _floors(*COARSE_FLOORS):
        plan = make_plan(_scene(disc=COARSE))
        raised = brushed.projected_scene(_scene(disc=COARSE))[0].channel(0)
    kind = kind_of(raised.layers[0])
    job = OperatorJob(plan, plan.grid, raised, 0, AnisoProjectionStats())
    combined = kind.operator(job)
    b = plan.brushed
    singles = [kind.operator(replace(job, plan=replace(plan, brushed=dict(
        b, floors=(f,), weights=(1.0,))))) for f in b["floors"]]
    for name in ("Rt", "Rb", "Ttb", "Tbt"):
        expect = sum(w * one.blocks[name] for w, one in zip(b["weights"], singles))
        assert abs(combined.blocks[name] - expect).max() <= 1e-12 * max(abs(expect).max(), 1.0)
    assert abs(singles[0].blocks["Ttb"] - singles[1].blocks["Ttb"]).max() > 1e-3


@pytest.mark.slow
def test_the_default_plan_fits():
    """The issue's coat (0.03, 0.3) over gold (0.2): exact, n = 650, ms = 26, 14 GiB; raised,
    n = 196, ms = 8, both floors' projections and the adding under 2 GiB and (estimated)
    60 s."""
    plan = make_plan(_scene())
    assert plan.brushed is not None and plan.refused is None
    assert plan.n == 196 and plan.ms == 8
    assert plan.memory_bytes < 2 * 2**30 and plan.seconds["total"] < 60


def test_plan_projects_the_raised_coat_and_keeps_the_wide_axis():
    proj, taken, hints = brushed.projected_scene(_scene(rough=(0.3, 0.001), rotation=40.0))
    top = proj.layers[0]
    assert taken and hints == []
    assert (top.alpha_u, top.alpha_v) == (0.3, min(brushed.BRUSHED_FLOORS))
    assert top.rotation == pytest.approx(np.radians(40.0))
    # not brushed: near-specular on both axes (the smooth split), or rough on both
    for rough in ((0.03, 0.1), (0.05, 0.3), (0.03, 0.6)):
        assert not brushed.projected_scene(_scene(rough=rough))[1]


@pytest.mark.parametrize("base, why", [
    ({"kind": "conductor", "ior": GOLD, "roughness": 0.01}, "layer 1 (conductor) below it"),
    ({"kind": "conductor", "ior": GOLD, "roughness": 0.0}, "layer 1 (conductor) below it"),
    (False, "nothing opaque below it")])
def test_a_base_that_does_not_blur_keeps_the_exact_projection_and_says_why(base, why):
    proj, taken, hints = brushed.projected_scene(_scene(base))
    assert not taken and proj.layers[0].alpha_u == 0.03
    assert len(hints) == 1 and "brushed near-specular coat" in hints[0] and why in hints[0]
    assert "use layersim.montecarlo" in hints[0]


def test_the_refusal_of_such_a_coat_carries_the_reason():
    """Refused here at the plan's lower bound (a small memory limit keeps the test fast; on
    this machine the exact projection needs n = 650, ms = 26 and 14 GiB)."""
    with configure(max_memory=2**20):
        plan = make_plan(_scene({"kind": "conductor", "ior": GOLD, "roughness": 0.01}),
                         refuse=False)
    assert plan.brushed is None and "layer 1 (conductor) below it" in plan.refused


def test_the_lobe_replaces_the_coats_reflection_exactly():
    """Over a black base nothing that enters the coat returns: the BSDF is the exact
    anisotropic microfacet reflection of the coat alone (not its raised projection, whose own
    reflection block is left out), its albedo the lobe's reflected energy."""
    bsdf = _coarse(0.0)
    assert abs(bsdf.operators[0].blocks["Rt"]).max() == 0.0
    lobe = NearSpecularLobe(1.5, 0.03, 0.3, "beckmann", np.radians(25.0))
    wi = _dirs(200, 1)
    wo = np.array([-1.0, -1.0, 1.0]) * wi + 0.02 * _dirs(200, 2)
    wo /= np.linalg.norm(wo, axis=1)[:, None]
    f = bsdf.eval(wi, wo)
    assert f.max() > 1.0
    np.testing.assert_allclose(f, lobe.eval(wi, wo), rtol=1e-12, atol=0)
    np.testing.assert_allclose(bsdf.albedo(wi[:20])[0], lobe.energies(wi[:20])[0], rtol=1e-12)


@pytest.mark.slow
def test_inside_light_keeps_the_exact_coats_energy():
    """The raised coat's inside energy ``E_Rb + E_Tbt`` per elevation is the exact coat's (from
    its lobe seen from inside), never above 1; its own reflection is left out and it stays
    reciprocal."""
    scene = _scene({"kind": "diffuse", "albedo": 1.0}, rotation=25.0, disc=COARSE)
    with _floors(COARSE_FLOORS[-1]):
        plan = make_plan(scene)
        from layersim.solver import _layer_operator   # the solver's own construction
        from layersim.ingredients.aniso_microfacet import AnisoProjectionStats
        op = _layer_operator(plan, plan.grid, brushed.projected_scene(scene)[0], 0,
                             AnisoProjectionStats())
    r_in, t_in = NearSpecularLobe(1.5, 0.03, 0.3, "beckmann", np.radians(25.0)) \
        .inside_energies(plan.grid.mu)
    alb = op.albedo()
    kept = alb["Rb"] + alb["Tbt"]
    assert np.all(kept <= 1.0 + 1e-9)
    np.testing.assert_allclose(kept, r_in + t_in, atol=2e-3)
    assert abs(op.blocks["Rt"]).max() == 0.0 and op.reciprocity_error() < 1e-12


@pytest.mark.slow
def test_the_split_stack_is_reciprocal():
    """f(wi, wo) = f(wo, wi): the lobe is, and the rescaling keeps the operator reciprocal."""
    bsdf = _coarse(1.0)
    wi, wo = _dirs(300, 4), _dirs(300, 5)
    a, b = bsdf.eval(wi, wo), bsdf.eval(wo, wi)
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)


@pytest.mark.slow
def test_over_a_white_base_the_stack_returns_at_most_what_arrives_to_70_degrees():
    """Lobe energy (exact coat) plus what the extrapolated raised coat lets in and out stays
    <= 1 up to 70 deg. Beyond, along the coat's narrow axis, the single floor 0.1 was not (1.03
    at 85 deg: the exact lobe's reflected energy depends on the azimuth there, the raised coat's
    transmission much less); this test does not look there."""
    bsdf = layersim.solve(_scene({"kind": "diffuse", "albedo": 1.0}, rotation=25.0))
    for z in (1.0, 0.8, 0.5, np.cos(np.radians(70.0))):
        phi = np.linspace(0.0, np.pi, 13)
        s = np.sqrt(1 - z * z)
        wi = np.stack([s * np.cos(phi), s * np.sin(phi), np.full_like(phi, z)], axis=1)
        R = bsdf.albedo(wi)[0]
        assert np.all(R <= 1.0) and R.min() > 0.85


@pytest.mark.slow
def test_the_issues_coat_over_gold_agrees_with_the_walk():
    """(0.03, 0.3) eta 1.5 over gold (0.2), the route as built (floors 0.12 and 0.1
    extrapolated), against 1e6 paths at 0 and 60 deg: albedos within max(4 se, 1e-3) and >= 95 %
    of populated 10 x 12 bins within 3 sigma. At 1e7 paths (benchmarks/features/
    brushed_coats.txt) the route is within 5.9e-4 (6.9 se at 60 deg) with 98.3-100 % of bins;
    one floor alone (0.1) was 1.5e-3 off at 0 deg (23 % of bins at 60 deg), which fails here."""
    sc = _scene()
    bsdf = layersim.solve(sc)
    assert bsdf.plan.brushed["floors"] == (0.12, 0.1)
    for theta, d, tol, z in solved_vs_walk(bsdf, sc, (0.0, 60.0), 41):
        assert abs(d) <= tol, (theta, d)
        assert np.mean(z <= 3.0) >= 0.95, (theta, np.mean(z <= 3.0))


@pytest.mark.slow
def test_sampling_and_the_saved_file_carry_the_lobe(tmp_path):
    """``sample`` draws the exact lobe mixed with the rest (its mean weight is the albedo, to
    about 4 standard errors of 20000 samples; lobe samples below the horizon are invalid, weight
    0), and a saved BSDF evaluates the same after loading."""
    bsdf = _coarse(0.6)
    path = bsdf.save(tmp_path / "brushed.lsim") or tmp_path / "brushed.lsim"
    loaded = layersim.BSDF.load(path)
    assert loaded.lobes == bsdf.lobes
    wi = np.tile(_dirs(1, 6), (20000, 1))
    s = loaded.sample(wi, np.random.default_rng(7).random((20000, 2)))
    v = s.valid
    assert v.mean() > 0.95
    np.testing.assert_allclose(s.pdf[v], loaded.pdf(wi[v], s.wo[v]), rtol=1e-6)
    assert abs(s.weight.mean() - float(loaded.albedo(wi[0])[0])) < 1e-2
    wo = _dirs(50, 8)
    np.testing.assert_array_equal(loaded.eval(wi[:50], wo), bsdf.eval(wi[:50], wo))
