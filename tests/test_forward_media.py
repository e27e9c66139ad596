"""Strongly forward-scattering media: delta-M scaling (Wiscombe 1977), linear-algebra failures
reported as clear errors, and the plan's time estimate."""

import math

import numpy as np
import pytest

import layersim
import layersim.montecarlo as mc
from layersim.stacking import adding
from layersim.config import Settings, configure
from layersim.errors import InfeasibleError
from layersim.ingredients import medium
from layersim.operators.operator import Grid


def _scene(g, albedo, tau=5.0, disc=None):
    data = {"layer": [{"kind": "medium", "tau": tau, "albedo": albedo, "g": g}]}
    if disc:
        data["discretization"] = disc
    return layersim.Scene.from_dict(data)


def test_grid_moments_follow_the_quadrature_exactness():
    # Gauss-Lobatto is exact to degree 2n - 3: P_k^2 integrates exactly for k <= n - 2
    assert medium.grid_moments(Grid.make("gauss-lobatto", 64)) == 63
    # Gauss-Legendre: degree 2n - 1, k <= n - 1
    assert medium.grid_moments(Grid.make("gauss-legendre", 64)) == 64


def _largest_eigenvalue(grid, same, opp):
    c = np.where(np.arange(same.shape[0]) == 0, 2 * np.pi, np.pi)
    return max(float(np.max(np.abs(np.linalg.eigvals(c[l] * (same[l] + s * opp[l])
                                                       * grid.w[None, :]))))
               for l in range(same.shape[0]) for s in (1.0, -1.0))


def test_delta_m_phase_matrices_do_not_amplify():
    """The whole HG(0.99) series aliased onto 33 ordinates per hemisphere gives discrete
    phase matrices with eigenvalues above one (the slab amplifies; the doubling of such a slab
    meets a singular I - R R); the delta-M scaled ones have eigenvalues chi_k' <= 1."""
    grid = Grid.make("gauss-lobatto", 66)
    same, opp = medium.hg_components(grid.mu, 0.99, 3)
    assert _largest_eigenvalue(grid, same, opp) > 1.5
    sc = medium.hg_scaling(grid, 0.99, 1.0, 5.0)
    assert sc.scaled and sc.moments == 65 and sc.f == pytest.approx(0.99 ** 65)
    same, opp = medium.hg_components(grid.mu, 0.99, sc.moments, chi=sc.chi(0.99))
    assert _largest_eigenvalue(grid, same, opp) <= 1.0 + 1e-10


def test_delta_m_scaled_values_and_threshold():
    grid = Grid.make("gauss-lobatto", 64)
    sc = medium.hg_scaling(grid, 0.99, 0.95, 5.0)
    f = 0.99 ** 63
    assert (sc.moments, sc.f) == (63, pytest.approx(f))
    assert sc.tau == pytest.approx((1 - 0.95 * f) * 5.0)
    assert sc.albedo == pytest.approx(0.95 * (1 - f) / (1 - 0.95 * f))
    # scattering optical depth of the diffuse part: omega' tau' = omega (1 - f) tau
    assert sc.albedo * sc.tau == pytest.approx(0.95 * (1 - f) * 5.0)
    assert not medium.hg_scaling(grid, medium.G_EXACT_MAX, 0.95, 5.0).scaled
    with pytest.raises(InfeasibleError, match="backward"):
        medium.hg_scaling(grid, -0.99, 0.95, 5.0)
    assert not medium.hg_scaling(grid, medium.G_BACKWARD_MIN, 0.95, 5.0).scaled


def test_strong_backward_scattering_is_refused_in_the_plan():
    with pytest.raises(InfeasibleError, match=r"layer 0 \(medium\): field 'g'.*g >= -0.95"):
        layersim.make_plan(_scene(-0.99, 0.95))


@pytest.mark.parametrize("g", [0.95, 0.99])
def test_delta_m_conservative_slab_conserves_energy(g):
    alb = layersim.solve(_scene(g, 1.0)).operators[0].albedo_nodes()
    assert np.max(np.abs(alb["Rt"] + alb["Ttb"] - 1.0)) < 1e-10
    assert np.max(np.abs(alb["Rb"] + alb["Tbt"] - 1.0)) < 1e-10


def test_plan_reports_delta_m_and_follows_the_scaled_phase_function():
    plan = layersim.make_plan(_scene(0.99, 0.95))
    assert (plan.n, plan.md) == (64, 63)          # not 3092 orders
    detail = plan.layers[0].detail
    assert "delta-M" in detail and "N = 63" in detail and "f = 0.5309" in detail
    assert "scaled tau = 2.478" in detail
    report = plan.report()
    assert "estimated time:" in report
    plain = layersim.make_plan(_scene(0.5, 0.95))
    assert "delta-M" not in plain.layers[0].detail


def test_delta_m_albedo_matches_monte_carlo():
    """g = 0.99, tau 5, albedo 0.95 at 40 deg: the delta-M solve within 4 standard errors
    (1e-4 solver allowance) of 1e6 Monte Carlo paths of the exact phase function."""
    scene = _scene(0.99, 0.95)
    wi = np.array([math.sin(math.radians(40)), 0.0, math.cos(math.radians(40))])
    R, T = (float(x) for x in layersim.solve(scene).albedo(wi))
    res = mc.simulate(scene, wi=wi, particles=1_000_000, backend="warp-cpu", seed=5)
    for ours, est, err in ((R, res.reflectance, res.reflectance_stderr),
                           (T, res.transmittance, res.transmittance_stderr)):
        est, err = float(np.ravel(est)[0]), float(np.ravel(err)[0])
        assert err < 5e-4
        assert abs(ours - est) < 4 * err + 1e-4, (ours, est, err)


def test_singular_doubling_is_reported_with_the_layer(monkeypatch):
    def singular(R, T, times):
        raise np.linalg.LinAlgError("Singular matrix")
    monkeypatch.setattr(medium, "_double", singular)
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
        {"kind": "medium", "tau": 5.0, "albedo": 1.0, "g": 0.5}],
        "discretization": {"n": 64, "md": 16}})
    with pytest.raises(InfeasibleError, match=r"layer 1 \(medium\).*singular.*albedo"):
        layersim.solve(scene)


def test_singular_adding_is_reported_with_the_layer(monkeypatch):
    def singular(top, bottom, threads=None):
        raise np.linalg.LinAlgError("Singular matrix")
    monkeypatch.setattr(adding, "add", singular)
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
        {"kind": "medium", "tau": 1.0, "albedo": 1.0, "g": 0.0}],
        "discretization": {"n": 64, "md": 4}})
    with pytest.raises(InfeasibleError, match=r"adding layer 0 \(dielectric\).*singular"):
        layersim.solve(scene)


def test_time_estimate_refuses_before_work():
    scene = _scene(0.99, 0.95, disc={"n": 400})
    plan = layersim.make_plan(scene)
    assert plan.seconds["media"] > 0 and plan.seconds["total"] >= plan.seconds["media"]
    with configure(max_seconds=plan.seconds["total"] / 10):
        with pytest.raises(InfeasibleError,
                           match=r"LAYERSIM_MAX_SECONDS.*media part is the largest.*n"):
            layersim.solve(scene)
        # `layersim plan` shows a refused plan with its estimate
        shown = layersim.make_plan(scene, refuse=False)
        assert "LAYERSIM_MAX_SECONDS" in shown.refused and shown.seconds == plan.seconds
    # a larger grid costs more: n^3 per order and more delta-M moments
    assert layersim.make_plan(_scene(0.99, 0.95, disc={"n": 200})).seconds["media"] \
        < plan.seconds["media"]


def test_max_seconds_setting():
    assert Settings.from_env({"LAYERSIM_MAX_SECONDS": "30"}).max_seconds == 30.0
    assert Settings.from_env({"LAYERSIM_MAX_SECONDS": "off"}).max_seconds is None
    assert Settings().max_seconds == 600.0
    with pytest.raises(layersim.config.ConfigError, match="LAYERSIM_MAX_SECONDS"):
        Settings.from_env({"LAYERSIM_MAX_SECONDS": "-1"})


def test_small_grids_check_the_whole_series_before_using_it():
    """On n = 8 (scene override) the whole series of g = 0.9 amplifies (largest eigenvalue
    1.46): the forward peak is delta-M scaled instead, and a backward one is refused."""
    grid = Grid.make("gauss-lobatto", 8)
    assert medium.hg_scaling(grid, 0.9, 0.95, 5.0).scaled
    assert not medium.hg_scaling(Grid.make("gauss-lobatto", 16), 0.9, 0.95, 5.0).scaled
    with pytest.raises(InfeasibleError, match=r"layer 0 \(medium\): field 'g'.*n >= 64"):
        layersim.make_plan(_scene(-0.9, 0.95, disc={"n": 8}))
    alb = layersim.solve(_scene(0.9, 1.0, disc={"n": 8})).operators[0].albedo_nodes()
    assert np.max(np.abs(alb["Rt"] + alb["Ttb"] - 1.0)) < 1e-10
