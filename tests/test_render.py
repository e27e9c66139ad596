"""``layersim render``: a tiny material-test image through the Mitsuba 3 plug-in, and its
input checks (skipped where mitsuba is not installed)."""

import numpy as np
import pytest

from layersim.cli import main

pytest.importorskip("mitsuba")


@pytest.mark.slow
def test_render_writes_a_lit_coloured_sphere(tmp_path):
    """A 24 x 24 image of RGB gold under a lacquer: the PNG exists, the sphere is lit (the
    centre is brighter than black) and gold (red above blue), the background is the sky."""
    import matplotlib.image
    scene = tmp_path / "gold.toml"
    scene.write_text('[[layer]]\nkind = "dielectric"\nior = 1.5\nroughness = 0.2\n'
                     '[discretization]\nn = 40\n'
                     '[[layer]]\nkind = "conductor"\nroughness = 0.3\n'
                     'ior = [[0.143552, 3.98397], [0.377438, 2.38495], [1.43825, 1.60434]]\n')
    out = tmp_path / "gold.png"
    assert main(["render", str(scene), "-o", str(out), "--spp", "4", "--resolution",
                 "24,24", "-q"]) == 0
    img = matplotlib.image.imread(out)[..., :3]
    assert img.shape == (24, 24, 3)
    centre = img[8:16, 8:16].reshape(-1, 3).mean(0)
    assert centre.sum() > 0.3 and centre[0] > 1.2 * centre[2]


@pytest.mark.parametrize("argv, message", [
    (["--spp", "0"], "--spp 0"),
    (["--resolution", "10,a"], "--resolution"),
    (["--resolution", "0,10"], "whole numbers in 1..4096"),
    (["-o", "x.jpg"], "PNG"),
])
def test_render_refuses_bad_options_in_one_line(tmp_path, capsys, argv, message):
    """Bad options exit with status 2 and one line, before any solve or render."""
    scene = tmp_path / "s.toml"
    scene.write_text('[[layer]]\nkind = "conductor"\nior = [0.2, 3.0]\nroughness = 0.3\n')
    argv = [a if a != "x.jpg" else str(tmp_path / a) for a in argv]
    assert main(["render", str(scene)] + argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err and "Traceback" not in err
