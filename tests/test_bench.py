"""The benchmark report and the stability suite (small sizes)."""

import json

import pytest

from layersim import bench
from layersim.bench import stability


@pytest.mark.slow
@pytest.mark.parametrize("case", stability.cases(), ids=lambda c: c.name)
def test_stability_case_passes_or_is_refused_clearly(case):
    result = stability.run_case(case, small=True)
    assert result["outcome"] in ("pass", "refused"), result["detail"]
    if result["outcome"] == "refused":
        # a refusal names the limit and what to change
        detail = result["detail"]
        assert any(w in detail for w in ("increase", "lower", "raise", "ill-posed", "hides")), \
            detail


def test_stability_checks_can_fail():
    """A solver that returns energy-creating results must be reported as a failure."""
    import layersim

    def broken_solve(scene):
        bsdf = layersim.solve(scene)
        for op in bsdf.operators:
            op.blocks["Rt"] = [1.5 * m for m in op.blocks["Rt"]]
        return bsdf

    case = stability.Case("broken", [{"kind": "medium", "albedo": 1.0, "tau": 1.0}],
                          "deliberately broken", conservative=True)
    result = stability.run_case(case, solve=broken_solve)
    assert result["outcome"] == "fail" and "R + T" in result["detail"]


def test_stability_monte_carlo_check_allows_stopped_walks_only_upwards():
    """Walks stopped at max_steps take their energy out of the estimate: the solver may lie above
    it by the stopped fraction, never below it (beyond the standard errors)."""
    from types import SimpleNamespace
    import layersim

    case = stability.Case("slab", [{"kind": "medium", "albedo": 1.0, "tau": 1.0}],
                          "conservative slab", conservative=True, angles=(0.0,))
    wi = stability._direction(0.0, 30.0)
    R, T = (float(x) for x in layersim.solve(case.scene()).albedo(wi))

    def fake_mc(shift, stopped):
        return lambda scene, wi, n: SimpleNamespace(
            reflectance=R - shift, transmittance=T - shift, reflectance_stderr=1e-5,
            transmittance_stderr=1e-5, truncated=int(stopped * 1000), particles=1000)

    assert stability.run_case(case, mc=fake_mc(0.01, 0.02))["outcome"] == "pass"
    result = stability.run_case(case, mc=fake_mc(0.01, 0.0))
    assert result["outcome"] == "fail" and "Monte Carlo" in result["detail"]
    result = stability.run_case(case, mc=fake_mc(-0.01, 0.02))      # solver below: no excuse
    assert result["outcome"] == "fail" and "Monte Carlo" in result["detail"]


@pytest.mark.slow
def test_quick_bench_writes_results_report_and_plots(tmp_path):
    results = bench.run(tmp_path, quick=True, scenes=["vandehulst_slab"], log=lambda *a: None)
    data = json.loads((tmp_path / "results.json").read_text())
    assert data["machine"]["cores"] >= 1 and "command" in data["machine"]
    (scene,) = data["scenes"]
    assert scene["name"] == "vandehulst_slab" and scene["reference"]["kind"] == "solver"
    errors = [row["error"] for row in scene["solver"]]
    assert len(errors) == 2 and errors[1] < errors[0] < 1e-2   # converges with n
    for row in scene["solver"]:
        assert {"n", "md", "ms", "seconds", "error"} <= set(row)
    (tol,) = scene["tolerance"]
    assert tol["tol"] == 1e-2 and tol["estimate"] <= 1e-2 and tol["error"] <= tol["estimate"]
    report = (tmp_path / "report.md").read_text()
    assert "vandehulst_slab" in report and "![vandehulst_slab_error_time.png]" in report
    assert "| tol | n | md |" in report
    assert (tmp_path / "vandehulst_slab_error_time.png").stat().st_size > 1000
    assert results["stability"] == []
    # --render is off by default: the default bench's cost and outputs are unchanged
    assert data["settings"]["render"] is None and not list(tmp_path.glob("*_render.png"))
    assert "render" not in scene


@pytest.mark.slow
def test_bench_render_writes_the_rendered_comparison(tmp_path):
    """``--render`` on a quick scene (2e4 paths per angle): SCENE_render.png is written and
    named in report.md, and the solver's and the walk's binned renders agree within a few
    times the walk's noise (relative RMS of the difference)."""
    bench.run(tmp_path, quick=True, scenes=["coated_gold"], log=lambda *a: None,
              render=True, render_particles=20_000)
    data = json.loads((tmp_path / "results.json").read_text())
    row = data["scenes"][0]["render"]
    assert data["settings"]["render"]["particles"] == 20_000 and row["angles"] == 16
    assert 0 < row["relative_difference"] < 0.05 and row["sigma_rms"] > 0
    assert row["within_3sigma"] > 0.9
    assert (tmp_path / "coated_gold_render.png").stat().st_size > 5000
    report = (tmp_path / "report.md").read_text()
    assert "![coated_gold_render.png](coated_gold_render.png)" in report
    assert "Rendered comparison" in report


def test_render_skips_anisotropic_stacks_and_says_why():
    """An anisotropic stack's bins depend on the incident azimuth: the render step skips it
    with the reason, before any walk or render."""
    import layersim
    from layersim.bench import rendercompare, runner
    scene = layersim.Scene.from_dict({"layer": [{"kind": "conductor", "ior": [0.2, 3.0],
                                                 "roughness": [0.2, 0.4]}],
                                      "discretization": {"n": 24}})
    bsdf = layersim.solve(scene)
    assert bsdf.anisotropic
    row, img = rendercompare.run(scene, bsdf, None, runner.Settings(), runner.direction,
                                 log=lambda *a: None)
    assert "anisotropic" in row["skipped"] and img == {}


@pytest.mark.slow
def test_quick_bench_errors_fall_from_the_cheapest_to_the_dearest_run(tmp_path):
    """Each quick scene's error falls from the cheapest to the most expensive run of each
    method, by a margin (solver: 3x, from 3.8x measured on coated gold; Monte Carlo: 3x,
    from 5.6x measured over seeds 1-10), so that neither a lucky n nor Monte Carlo noise can
    reverse it. A different seed than the default checks that it is not one draw's luck."""
    results = bench.run(tmp_path, quick=True, log=lambda *a: None, seed=5)
    assert {s["name"] for s in results["scenes"]} == set(bench.QUICK_SCENES)
    for s in results["scenes"]:
        solver = [r["error"] for r in s["solver"]]
        mc = [r["error"] for r in s["montecarlo"]]
        assert len(solver) == 2 and solver[0] > 3.0 * solver[-1], (s["name"], solver)
        assert len(mc) == 3 and mc[0] > 3.0 * mc[-1], (s["name"], mc)
        assert s["reference"]["n"] >= 1.9 * max(r["n"] for r in s["solver"])


def _scene_entry():
    """A scene entry of results.json as the runner writes it: two solver rungs, a solve to a
    tolerance that is the slowest point (the rightmost, where its label was cut), and a
    Monte Carlo ladder."""
    return {"name": "demo", "reference": {"kind": "solver", "n": 294, "md": 370},
            "solver": [{"n": 98, "md": 124, "seconds": 0.3, "error": 2e-4, "albedo_error": 0},
                       {"n": 196, "md": 247, "seconds": 0.9, "error": 2.4e-4,
                        "albedo_error": 0}],
            "tolerance": [{"tol": 1e-2, "n": 138, "md": 175, "seconds": 1.2, "error": 6.7e-4,
                           "estimate": 4.7e-3}],
            "montecarlo": [{"backend": "warp-cpu", "particles": p, "seconds": t, "error": e,
                            "stderr": e, "paths_per_second": p / t, "within_3sigma": 1.0,
                            "albedo_error": 0.0}
                           for p, t, e in ((10_000, 0.008, 4e-2), (100_000, 0.1, 1.4e-2))]}


def test_error_time_plot_keeps_its_labels_inside_and_names_the_reference():
    """Labels of the rightmost points (the solve to a tolerance) lie inside the figure, and
    the title says what the errors are measured against: the reference solve and how much
    finer it is than the finest rung (1.5x here: the last rung's error is partly the
    reference's own)."""
    from layersim.bench import report
    fig = report.error_time_figure(_scene_entry())
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    (ax,) = fig.axes
    texts = {t.get_text(): t for t in ax.texts}
    assert set(texts) == {"n=98", "n=196", "tol 0.01"}
    frame = fig.bbox
    for t in texts.values():
        box = t.get_window_extent(renderer)
        assert frame.x0 <= box.x0 and box.x1 <= frame.x1, (t.get_text(), box, frame)
    assert "reference: solve at n = 294, md = 370, 1.5x the finest rung's n" in ax.get_title()
    import matplotlib.pyplot as plt
    plt.close(fig)


def test_report_states_the_reference_and_its_distance_to_the_finest_rung(tmp_path):
    from layersim.bench import report, runner
    machine = {"cpu": "x", "cores": 2, "command": "layersim bench --quick"}
    report.write(tmp_path, machine, [_scene_entry()], [], runner.Settings.quick())
    text = (tmp_path / "report.md").read_text()
    assert ("Reference: solver at n = 294, md = 370 (1.5x the n of the finest solver rung "
            "below; each rung's error includes the reference's own") in text
