"""The subtracting equations (Zeltner & Jakob 2018, eq. (13)-(16)): exact recovery without noise
(isotropic and anisotropic, known layer on top or at the bottom, all four blocks), automatic
regularisation with 1 % noise, refusal of ill-posed problems, BSDF-level use and the CLI."""

import numpy as np
import pytest

import layersim
from layersim.subtract import relative_error, with_noise as noisy
from layersim import adding
from layersim.aniso import AnisoOperator, adding as aniso_adding
from layersim.errors import InfeasibleError, OperatorError
from layersim.ingredients import interface_operator, medium_operator
from layersim.ingredients.aniso_microfacet import aniso_interface_operator
from layersim.operator import Grid
from layersim.scene import Conductor, Dielectric
from layersim.subtract import negativity as _negativity

G48 = Grid.make("gauss-lobatto", 48)
G32 = Grid.make("gauss-lobatto", 32)
M = 24


def energy_error(a, b):
    """Relative Frobenius error of all blocks in the energy basis (sqrt(w mu) scaling)."""
    return relative_error(a, b)


@pytest.fixture(scope="module")
def iso_layers():
    dust = medium_operator(G48, M, 0.9, 0.6, 0.2, 1.0)           # thin forward-scattering slab
    glass = interface_operator(G48, M, Dielectric(ior=1.5, alpha_u=0.3, alpha_v=0.3), 1.0)
    dust_in_glass = medium_operator(G48, M, 0.9, 0.6, 0.2, 1.5)
    metal = interface_operator(G48, M, Conductor(ior=complex(0.2, 3.0), alpha_u=0.2,
                                                 alpha_v=0.2), 1.0)
    return dust, glass, dust_in_glass, metal


def test_removing_a_known_top_layer_recovers_all_four_blocks(iso_layers):
    dust, glass, _, metal = iso_layers
    for bottom in (glass, metal):
        stack = adding.add(dust, bottom)
        got = layersim.subtract(stack, dust, side="top")
        assert energy_error(got, bottom) < 1e-5          # the brief asks for < 1 %
        info = got.info["subtract"]
        assert info["method"] == "discrepancy" and info["noise_source"] == "reciprocity"
        assert info["residual"] < 1e-8 and info["visible"] > 0.9
        assert (got.eta_top, got.eta_bottom) == (bottom.eta_top, bottom.eta_bottom)


def test_removing_a_known_bottom_layer_recovers_the_top_layer(iso_layers):
    _, glass, dust_in_glass, _ = iso_layers
    stack = adding.add(glass, dust_in_glass)
    got = layersim.subtract(stack, dust_in_glass, side="bottom")
    assert energy_error(got, glass) < 1e-5
    assert got.info["subtract"]["side"] == "bottom"


@pytest.mark.slow
def test_anisotropic_subtraction_recovers_the_hidden_layer():
    dust = medium_operator(G32, 16, 0.9, 0.6, 0.2, 1.0)
    brushed = aniso_interface_operator(G32, 16, 3, Conductor(ior=complex(0.2, 3.0), alpha_u=0.2,
                                                             alpha_v=0.4, rotation=0.5), 1.0)
    got = layersim.subtract(aniso_adding.add(dust, brushed), dust, side="top")
    assert isinstance(got, AnisoOperator)
    assert energy_error(got, brushed) < 1e-5
    glass = aniso_interface_operator(G32, 16, 3, Dielectric(ior=1.5, alpha_u=0.3,
                                                           alpha_v=0.15), 1.0)
    dust15 = medium_operator(G32, 16, 0.9, 0.6, 0.2, 1.5)
    got = layersim.subtract(aniso_adding.add(glass, dust15), dust15, side="bottom")
    assert energy_error(got, glass) < 1e-5


def test_automatic_eps_with_one_percent_noise_leaves_no_oscillation(iso_layers):
    """1 % multiplicative noise on every entry of the stack: the noise level is estimated from
    reciprocity, eps follows, and the result has no negative lobes deeper than the noise
    (Fejer means of the low orders) while a nearly unregularised inverse oscillates."""
    dust, glass, _, _ = iso_layers
    stack = noisy(adding.add(dust, glass), 0.01, seed=3)
    got = layersim.subtract(stack, dust, side="top")
    info = got.info["subtract"]
    assert info["noise"] == pytest.approx(0.01, rel=0.1)
    assert info["eps"] > 1e-3
    assert _negativity(got) <= 1.5 * 0.01 + 1e-12
    assert energy_error(got, glass) < 0.15                     # measured: 7.5 %
    raw = layersim.subtract(stack, dust, side="top", eps=1e-4)
    assert _negativity(raw) > 0.1 and energy_error(raw, glass) > 1.0
    again = layersim.subtract(stack, dust, side="top", noise=0.01)
    assert again.info["subtract"]["noise_source"] == "given"


def test_layers_that_hide_what_is_below_are_refused(iso_layers):
    _, glass, _, metal = iso_layers
    thick = medium_operator(G48, M, 0.9, 0.3, 10.0, 1.0)
    with pytest.raises(InfeasibleError, match="strongly diffusing.*ill-posed"):
        layersim.subtract(adding.add(thick, metal), thick, side="top")
    with pytest.raises(InfeasibleError, match="opaque.*hides"):
        layersim.subtract(adding.add(glass, interface_operator(
            G48, M, Conductor(ior=complex(0.2, 3.0), alpha_u=0.2, alpha_v=0.2), 1.5)),
            metal, side="top")
    with pytest.raises(OperatorError, match="different grids"):
        layersim.subtract(adding.add(glass, medium_operator(G48, M, 0.5, 0.0, 1.0, 1.5)),
                          medium_operator(G32, M, 0.5, 0.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="side"):
        layersim.subtract(glass, glass, side="middle")


@pytest.mark.slow
def test_subtract_on_solved_bsdfs_and_the_cli(tmp_path, capsys):
    from layersim.cli import main
    dust = {"kind": "medium", "albedo": 0.9, "g": 0.5, "tau": 0.2}
    base = {"kind": "conductor", "ior": [0.2, 3.0], "roughness": [0.3, 0.2]}
    disc = {"n": 32, "md": 16}
    stack = layersim.solve(layersim.Scene.from_dict({"layer": [dust, base],
                                                     "discretization": disc}))
    known = layersim.solve(layersim.Scene.from_dict({"layer": [dust]}), like=stack)
    truth = layersim.solve(layersim.Scene.from_dict({"layer": [base]}), like=stack)
    got = layersim.subtract(stack, known, side="top")
    assert isinstance(got, layersim.BSDF) and got.anisotropic
    assert energy_error(got.operators[0], truth.operators[0]) < 1e-5
    wi = np.array([0.5, 0.1, np.sqrt(0.74)])
    np.testing.assert_allclose(got.albedo(wi), truth.albedo(wi), rtol=1e-6)
    s, k = stack.save(tmp_path / "stack.lsim"), known.save(tmp_path / "known.lsim")
    out = tmp_path / "base.lsim"
    assert main(["subtract", str(s), str(k), "--side", "top", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "eps = " in text and "discrepancy" in text and "wrote" in text
    np.testing.assert_allclose(layersim.BSDF.load(out).albedo(wi), got.albedo(wi), rtol=1e-12)
    assert main(["subtract", str(s), str(k), "--side", "bottom"]) == 2
    assert "side='top'" in capsys.readouterr().err
