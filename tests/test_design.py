"""Inverse design (Bati et al. 2021): the paper's bounds and equivalence classes, designs that
reproduce their targets in the forward model, refusals of unreachable targets, and designed
scenes that the exact solver and the Monte Carlo reference accept."""

import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

import layersim
from layersim.statistical import StatisticalBSDF, TargetError, designs, parse_targets
from layersim.statistical.design.invert import (CONDUCTOR_R_MIN, conductor_index,
                                                dielectric_root)
from layersim.statistical.verify import group_lobes

ROOT = Path(__file__).resolve().parents[1]
SETS = tomllib.loads((ROOT / "examples" / "design_targets.toml").read_text())["set"]


def fresnel_normal(eta0, eta, k=0.0):
    """Bati et al. 2021 eq. 1."""
    return ((eta0 - eta) ** 2 + k ** 2) / ((eta0 + eta) ** 2 + k ** 2)


def test_there_are_at_least_twenty_target_sets_of_one_to_three_coloured_lobes():
    assert len(SETS) >= 20
    assert {len(s["lobe"]) for s in SETS} == {1, 2, 3}
    assert sum(any(isinstance(l["energy"], list) for l in s["lobe"]) for s in SETS) >= 10


# 1-layer one-lobe sets in the fast set; the 2-layer and multi-lobe searches take 1-4 s each
CASES = [pytest.param(s, id=s["name"], marks=() if len(s["lobe"]) == 1 and s["lobe"][0].get(
    "layers") != 2 else pytest.mark.slow) for s in SETS]


@pytest.mark.parametrize("case", CASES)
def test_designs_reproduce_their_targets_in_the_forward_model(case):
    """Energies to 1e-3 in every channel; roughness to 1e-2 relative in the channel whose
    variance the inversion matches (the largest attenuated energy, Bati et al. 2021 sec.
    5.2.3); the other channels of a coloured lobe differ by the spread of their own bounces."""
    targets = parse_targets(case["lobe"])
    d = designs(case["lobe"])[0]
    model = StatisticalBSDF(d.scene)
    for t, (energy, alpha) in zip(targets.lobes, group_lobes(model, d.groups)):
        np.testing.assert_allclose(energy, np.broadcast_to(t.energy, energy.shape), atol=1e-3)
        if t.roughness == 0.0:
            assert np.all(alpha < 1e-6)
        else:
            assert np.min(np.abs(alpha / t.roughness - 1)) < 1e-2
            assert np.max(np.abs(alpha / t.roughness - 1)) < 0.05


def test_one_layer_dielectric_in_air_reaches_0_36_and_two_layers_0_53():
    """Bati et al. 2021 sec. 5.2.1: with eta_max = 4 the highest normal reflectance is 0.36 for
    a 1-layer and 0.53 for a 2-layer (smooth) dielectric lobe (base given: left out, a
    conductor would be inferred beyond them)."""
    assert fresnel_normal(1.0, 4.0) == pytest.approx(0.36)
    d = designs([{"energy": 0.359, "roughness": 0.0, "layers": 1}])[0]
    assert d.scene.layers[0].ior.real == pytest.approx(4.0, rel=2e-2)
    with pytest.raises(TargetError, match=r"lobe 1: field 'energy'.*reaches at most 0\.36"):
        designs([{"energy": 0.37, "roughness": 0.0, "layers": 1, "base": "dielectric"}])
    d = designs([{"energy": 0.52, "roughness": 0.0, "layers": 2}])[0]
    assert group_lobes(StatisticalBSDF(d.scene), d.groups)[0][0] == pytest.approx(0.52, abs=1e-6)
    with pytest.raises(TargetError, match="lobe 1"):
        designs([{"energy": 0.54, "roughness": 0.0, "layers": 2, "base": "dielectric"}])


def test_eq_7_gives_two_roots_under_a_coat():
    """Below a medium of index 1.5, a smooth interface of reflectance 0.01 has the roots
    1.5 (1 +- 0.1) / (1 -+ 0.1); in air only the one above 1 exists (eq. 7)."""
    assert dielectric_root(0.01, 0.0, 1.5, 4.0, "above") == pytest.approx(1.5 * 1.1 / 0.9,
                                                                          rel=1e-3)
    assert dielectric_root(0.01, 0.0, 1.5, 4.0, "below") == pytest.approx(1.5 * 0.9 / 1.1,
                                                                          rel=1e-3)
    assert dielectric_root(0.04, 0.0, 1.0, 4.0, "below") == pytest.approx(1.5, rel=1e-3)


@pytest.mark.parametrize("r", [0.2, 0.6, 0.9])
def test_conductor_equivalence_class_follows_eq_8_to_10(r):
    for choice in ("centre", "edge"):
        ior = conductor_index(r, 0.0, 1.0, choice, 1)
        assert fresnel_normal(1.0, ior.real, ior.imag) == pytest.approx(r, abs=1e-9)
        assert ior.imag >= ior.real * (1 - 1e-9)          # kappa >= eta
    edge = conductor_index(r, 0.0, 1.0, "edge", 1)
    assert edge.real == pytest.approx((1 - r) / (1 + r))   # eq. 10
    # eq. 9: at the upper end of the class kappa == eta
    eta_hi = (1 + r + math.sqrt(6 * r - 1 - r * r)) / (2 * (1 - r))
    k_hi = math.sqrt((r * (eta_hi + 1) ** 2 - (eta_hi - 1) ** 2) / (1 - r))     # eq. 8
    assert k_hi == pytest.approx(eta_hi, rel=1e-9)
    # under a clear coat (eta0 = 1.5) the class scales with eta0 (Fig. 4c)
    coated = conductor_index(r, 0.0, 1.5, "centre", 1)
    assert coated == pytest.approx(1.5 * conductor_index(r, 0.0, 1.0, "centre", 1), rel=1e-9)


@pytest.mark.parametrize("lobes,match", [
    ([{"energy": 0.15, "roughness": 0.1, "base": "conductor"}],
     rf"lobe 1: field 'energy'.*\({CONDUCTOR_R_MIN:.4f}, 1\)"),
    ([{"energy": [0.04, 0.05, 0.06], "roughness": 0.1, "layers": 1}],
     "lobe 1: field 'energy'.*1-layer dielectric lobe in air"),
    # a perfectly specular lobe underneath a rough one (Bati et al. 2021 sec. 1)
    ([{"energy": 0.04, "roughness": 0.3}, {"energy": 0.1, "roughness": 0.0}],
     "lobe 2: field 'roughness'.*spread the layers above"),
    # base given: no conductor is inferred (a conductor reaches this lobe)
    ([{"energy": 0.3, "roughness": 0.45, "layers": 2, "base": "dielectric"}],
     "lobe 1: field 'energy'.*N1"),
    ([{"energy": 0.6, "roughness": 0.1}, {"energy": 0.5, "roughness": 0.2}],
     "field 'energy'.*add up to 1.1"),
    ([{"energy": 0.1, "roughness": 0.1, "base": "conductor"}, {"energy": 0.1,
                                                              "roughness": 0.1}],
     "lobe 1: field 'base'.*bottom lobe"),
    ([{"energy": 0.1}], "lobe 1: field 'roughness'"),
    ([{"energy": 0.1, "roughness": 0.1, "colour": 1}], "lobe 1: field 'colour'"),
    ([{"energy": 0.1, "roughness": 1.2}], "lobe 1: field 'roughness'.*<= 1"),
])
def test_unreachable_or_malformed_targets_are_refused_naming_lobe_and_bound(lobes, match):
    with pytest.raises(TargetError, match=match):
        layersim.design(lobes)
    assert issubclass(TargetError, ValueError)


def test_design_entry_point_returns_scenes_preferred_first():
    scenes = layersim.design([{"energy": [0.04, 0.04, 0.04], "roughness": 0.05},
                              {"energy": [0.5, 0.4, 0.3], "roughness": 0.3,
                               "base": "conductor"}])
    assert all(isinstance(s, layersim.Scene) for s in scenes) and len(scenes) >= 2
    top, base = scenes[0].channel(0).layers[0], scenes[0].channel(0).layers[-1]
    assert top.distribution == "ggx" and base.kind == "conductor"


@pytest.mark.slow
def test_a_designed_scene_is_solved_and_simulated():
    import layersim.montecarlo as mc
    d = designs([{"energy": 0.04, "roughness": 0.2},
                 {"energy": [0.5, 0.4, 0.3], "roughness": 0.4, "base": "conductor"}])[0]
    wi = np.array([0.0, 0.0, 1.0])
    exact = layersim.solve(d.scene)
    res = mc.simulate(d.scene, wi=wi, particles=100_000, mu_edges=np.linspace(0, 1, 5),
                      phi_edges=np.linspace(0, 2 * np.pi, 5), backend="warp-cpu", seed=1)
    R = np.asarray(exact.albedo(wi)[0])
    assert np.all(np.abs(res.reflectance - R) < 4 * res.reflectance_stderr + 1e-3)


def test_cli_design_writes_a_scene_that_layersim_reads(tmp_path, capsys):
    from layersim.cli import main
    out = tmp_path / "stack.toml"
    assert main(["design", str(ROOT / "examples" / "design_coated_copper.toml"), "--no-verify",
                 "-o", str(out), "--candidates", "1"]) == 0
    text = capsys.readouterr().out
    assert "candidate 1" in text and "conductor" in text
    scene = layersim.Scene.from_toml(out)
    assert scene.channels == 3 and scene.channel(0).layers[0].distribution == "ggx"


def test_cli_design_refuses_unreachable_targets_in_one_line(tmp_path, capsys):
    from layersim.cli import main
    bad = tmp_path / "bad.toml"
    bad.write_text("[[lobe]]\nenergy = 0.15\nroughness = 0.1\nbase = \"conductor\"\n")
    assert main(["design", str(bad), "--no-verify"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "lobe 1" in err[0] and "0.1716" in err[0]


@pytest.mark.slow
def test_smooth_two_layer_class_is_bounded_by_the_one_layer_configurations():
    """Bati et al. 2021 Fig. 7a: for R02 = 0.15 in air the upper index eta1 of a smooth 2-layer
    lobe spans [1, D], D = (1 + sqrt(0.15)) / (1 - sqrt(0.15)) the 1-layer root of eq. 7 (the
    lower interface vanishes there); near eta1 = 1 the lower interface alone gives R02."""
    root = (1 + math.sqrt(0.15)) / (1 - math.sqrt(0.15))
    found = {d.choice: [layer["ior"] for layer in d.data["layer"]]
             for d in designs([{"energy": 0.15, "roughness": 0.0, "layers": 2}])}
    step = 3.0 / 47                                   # the N1 scan over [1, 4]
    assert root - step <= found[1.0][0] <= root
    assert found[0.0][0] == pytest.approx(1.0, abs=step)
    # the lower interface from eq. 11 (R'12 from R02 and R01) and eq. 7
    eta1 = found[0.0][0]
    r01 = ((eta1 - 1) / (eta1 + 1)) ** 2
    r12 = (0.15 - r01) / (1 + (0.15 - 2) * r01)
    assert found[0.0][1] == pytest.approx(eta1 * (1 + math.sqrt(r12)) / (1 - math.sqrt(r12)),
                                          rel=1e-4)


@pytest.mark.slow
def test_a_design_the_fourier_basis_refuses_is_solved_as_specular_paths():
    """Fig. 10c of Bati et al. 2021 (R = 0.15, sigma = 0.02, two layers): its lower interface
    (alpha 0.01) needs ~16 GiB in the Fourier basis; it is solved as specular paths
    (layersim.specular_paths) within 4 GiB, and its verified lobe agrees with Monte Carlo's."""
    from layersim.specular_paths import SpecularPathsBSDF
    from layersim.statistical.verify import montecarlo_solve, verify
    d = designs([{"energy": 0.15, "variance": 0.02, "layers": 2}])[0]
    with layersim.config.configure(max_memory=4 * 2 ** 30):
        assert isinstance(layersim.solve(d.scene), SpecularPathsBSDF)
        (energy, alpha), = verify(d, angles=(0.0,))["exact_lobes"]
    (mc_energy, mc_alpha), = verify(d, angles=(0.0,),
                                    solve=montecarlo_solve(200_000))["exact_lobes"]
    assert float(mc_energy[0]) == pytest.approx(0.15, abs=3e-3)      # se ~ 8e-4
    assert float(energy[0]) == pytest.approx(float(mc_energy[0]), abs=3e-3)
    assert 0.02 < float(alpha[0]) < 0.03 and 0.02 < float(mc_alpha[0]) < 0.03


def test_lobe_plot_legend_names_the_channel_colours_and_line_styles():
    """design --plot: each channel has its own colour in every panel, and the legend shows
    those colours (R, G, B) and the two line styles (exact solid, target dashed) in a neutral
    grey, so that no legend entry claims a colour for what is a line style."""
    from matplotlib.colors import to_rgba
    from layersim.statistical.report import CHANNEL_COLOURS, lobes_figure
    targets = parse_targets(ROOT / "examples" / "design_coated_copper.toml")
    rng = np.random.default_rng(3)
    rings = [rng.random((90, 3)) * 1e-3 for _ in targets.lobes]
    fig = lobes_figure(targets, rings)
    panels = [ax for ax in fig.axes if ax.get_title().startswith("lobe")]
    assert len(panels) == len(targets.lobes)
    for ax in panels:
        lines = ax.get_lines()
        assert {to_rgba(l.get_color()) for l in lines} == {to_rgba(c) for c in CHANNEL_COLOURS}
        assert {l.get_linestyle() for l in lines} == {"-", "--"}
        legend = {t.get_text(): h for t, h in zip(ax.get_legend().get_texts(),
                                                  ax.get_legend().legend_handles)}
        assert list(legend) == ["exact transport", "target", "R channel", "G channel",
                                "B channel"]
        for name, colour in zip("RGB", CHANNEL_COLOURS):
            assert to_rgba(legend[f"{name} channel"].get_color()) == to_rgba(colour)
        for style in ("exact transport", "target"):
            assert to_rgba(legend[style].get_color()) not in {to_rgba(c)
                                                              for c in CHANNEL_COLOURS}
        assert legend["target"].get_linestyle() == "--"
