"""The plan's route to specular paths (layersim.plan.route): the rows of issue 33's table it
takes, what it leaves to the Fourier basis, its report, and the command line."""

import time
import tracemalloc

import pytest

import layersim
from layersim.cli import main
from layersim.plan import make_plan
from layersim.specular_paths import SpecularPathsBSDF

GOLD = [[0.143552, 3.98397], [0.374967, 2.38489], [1.44248, 1.60319]]
ROWS = {
    "frosted glass": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.02}],
    "tinted lacquer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.02},
                       {"kind": "medium", "albedo": 0.0, "tau": [0.1, 0.4, 1.2]}],
    "glass pane": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.01},
                   {"kind": "dielectric", "ior": 1.0, "roughness": 0.01}],
    "coat over gold": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.0},
                       {"kind": "conductor", "ior": GOLD, "roughness": 0.01}],
    "Bati one lobe": [{"kind": "dielectric", "ior": 1.78916, "roughness": 0.02,
                       "distribution": "ggx"}],
}


def _scene(layers, **extra):
    return layersim.Scene.from_dict({"layer": layers, **extra})


@pytest.mark.slow
@pytest.mark.parametrize("name", list(ROWS))
def test_the_table_rows_are_routed_and_solve_within_60_s_and_4_gib(name):
    """Each row of issue 33's table but the brushed coat: routed to specular paths, the
    report names the paths and the pruned energy, and the solve (plan included) takes under
    60 s and under 4 GiB of Python-tracked memory."""
    scene = _scene(ROWS[name])
    plan = make_plan(scene)
    assert plan.representation == "specular-paths"
    text = plan.report()
    assert "specular paths" in text and "pruned energy at most" in text
    tracemalloc.start()
    t0 = time.perf_counter()
    bsdf = layersim.solve(scene)
    bsdf.albedo([0.0, 0.0, 1.0])
    seconds = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    print(f"{name}: {seconds:.1f} s, peak {peak / 2**20:.0f} MiB")
    assert isinstance(bsdf, SpecularPathsBSDF) and seconds < 60 and peak < 4 * 2**30


def test_stacks_outside_the_class_are_not_routed():
    """A brushed coat (0.03, 0.3), a scattering medium and a diffuse base stay with the
    Fourier basis (refused or not, as before); so does a scene whose [discretization] sets
    n."""
    from layersim.specular_paths import why_not
    brushed = _scene([{"kind": "dielectric", "ior": 1.5, "roughness": [0.03, 0.3]},
                      {"kind": "conductor", "ior": GOLD, "roughness": 0.2}])
    assert "rougher than 0.03" in why_not(brushed)
    milky = _scene([{"kind": "dielectric", "ior": 1.5, "roughness": 0.02},
                    {"kind": "medium", "albedo": 0.5, "tau": 1.0}])
    assert "scatters" in why_not(milky)
    base = _scene([{"kind": "dielectric", "ior": 1.5, "roughness": 0.02},
                   {"kind": "diffuse", "albedo": 0.5}])
    assert "not a flat interface" in why_not(base)
    fixed = _scene(ROWS["frosted glass"], discretization={"n": 64, "md": 64})
    assert make_plan(fixed).representation == "isotropic"


def test_a_fourier_plan_that_fits_is_kept():
    """A smooth coat over a conductor of alpha 0.03 plans within 1 GiB in the Fourier basis
    (249 MiB) and keeps it: the route takes over only where that plan is refused or over
    1 GiB."""
    plan = make_plan(_scene([{"kind": "dielectric", "ior": 1.5, "roughness": 0.0},
                             {"kind": "conductor", "ior": [0.2, 3.0], "roughness": 0.03}]))
    assert plan.representation == "isotropic" and plan.memory_bytes <= 2**30


@pytest.mark.slow
def test_command_line_plan_solve_and_export(tmp_path, capsys):
    scene = tmp_path / "frosted.toml"
    scene.write_text('[[layer]]\nkind = "dielectric"\nior = 1.5\nroughness = 0.02\n')
    assert main(["plan", str(scene)]) == 0
    assert "representation: specular paths" in capsys.readouterr().out
    out = tmp_path / "frosted.lsim"
    assert main(["solve", str(scene), "-o", str(out)]) == 0
    assert isinstance(layersim.BSDF.load(out), SpecularPathsBSDF)
    capsys.readouterr()
    assert main(["export", str(out), "-o", str(tmp_path / "x.bsdf")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "specular paths" in err[0] and "Traceback" not in err[0]


@pytest.mark.slow
def test_a_stack_whose_paths_multiply_is_refused_with_the_reason():
    """The design of Bati et al.'s Fig. 14b in its clear channel (a smooth coat over a 2.47
    face, a clear slab and a face into 1.02: near its critical angle the light bounces back
    and forth; 15 s, the Fourier plan weighed twice) has over 1000 paths
    above the pruning: the plan gives the reason in a note and falls back to the Fourier
    plan's refusal (in one raised line with both reasons) instead of building them."""
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.50007, "roughness": 0.0},
        {"kind": "dielectric", "ior": 2.46809, "roughness": 0.0279721, "distribution": "ggx"},
        {"kind": "medium", "albedo": 0.0, "tau": 0.0},
        {"kind": "dielectric", "ior": 1.01918, "roughness": 0.0107202, "distribution": "ggx"}]})
    plan = make_plan(scene, refuse=False)
    assert plan.representation != "specular-paths" and plan.refused
    assert any("1000 paths" in n for n in plan.notes)
    with pytest.raises(layersim.LayersimError, match="specular paths: light entering"):
        make_plan(scene)
