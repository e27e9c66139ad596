"""BSDF.eval is never negative.

Lobes cut in azimuth are tapered with the Jackson kernel
(:func:`layersim.operators.fourier.taper_factors`), a non-negative kernel, so that the series at the
ordinates stay non-negative; ``eval`` returns the positive part of the cubic spline interpolant
between them, which may undershoot only slightly on the steep flank of a narrow lobe. The tests
check the kernel, the series at the ordinates of every projection path (with Lanczos sigma factors
as the taper, the counter-example that gives them their power), and scan random direction pairs of
the bench scenes and the example car paint and lacquered wood.
``benchmarks/features/eval_positivity.py`` measures the same with either taper, and
covers the anisotropic bench scenes, whose solves and evaluations at the default plans take
minutes on two cores.
"""

from pathlib import Path

import numpy as np
import pytest

import layersim
import layersim.operators.fourier
from layersim.ingredients.numeric import numeric_interface_operator
from layersim.operators.operator import Grid
from layersim.scene import Dielectric

ROOT = Path(__file__).resolve().parent.parent
GOLD = [0.143552, 3.98397]
#: Depth (of the BSDF's peak, per channel) that the interpolant may undershoot between
#: ordinates in the scanned scenes; measured at most 4.6e-6 (the blue channel of
#: examples/car_paint.toml, on the flank of the coat's lobe at 80-84 deg, 2.5 deg off the
#: specular azimuth; benchmarks/features/eval_positivity.txt).
UNDERSHOOT = 1e-5


def sigma_factors(m):
    """Lanczos sigma factors, a taper whose kernel has negative side lobes."""
    return np.sinc(np.arange(m) / m)


def kernel(factors, n=1 << 16):
    """``1 + 2 sum_{l > 0} g_l cos(l phi)`` (2 pi times the kernel of the factors ``g``) at
    ``phi = 2 pi j / n``, j = 0..n-1 (an inverse real FFT)."""
    return n * np.fft.irfft(factors, n)


def test_taper_kernel_is_non_negative():
    for m in (1, 2, 3, 8, 64, 247, 470, 1000, 5000):
        g = layersim.operators.fourier.taper_factors(m)
        assert g.shape == (m,) and g[0] == 1.0 and np.all(np.diff(g) < 0)
        k = kernel(g)
        assert k.min() >= -1e-12 * k.max(), m
        assert k[0] == pytest.approx(k.max())
    # the sigma factors' kernel dips to -4.8 % of its peak
    k = kernel(sigma_factors(247))
    assert k.min() < -0.04 * k.max()


def directions(mu, phi):
    """Unit vectors with z = mu (exactly an ordinate, so that the spline weights there are
    (1, 0, 0, 0)) at azimuth phi."""
    mu, phi = np.broadcast_arrays(np.asarray(mu, float), np.asarray(phi, float))
    s = np.sqrt(1.0 - mu * mu)
    return np.stack([s * np.cos(phi), s * np.sin(phi), mu], axis=-1)


def node_values(bsdf, transmit=False, phi_i=(0.0,), n_phi=1441):
    """The interpolant at every pair of ordinates (reflection, or transmission into the lower
    half), incident azimuths ``phi_i`` and ``n_phi`` outgoing azimuths: the series at the
    ordinates themselves, shape (pairs, azimuths)."""
    mu = bsdf.grid.mu
    i, o, a, b = np.meshgrid(np.arange(mu.size), np.arange(mu.size), np.asarray(phi_i),
                             np.linspace(0.0, 2.0 * np.pi, n_phi), indexing="ij")
    wi = directions(mu[i], a)
    wo = directions(mu[o], b)
    if transmit:
        wo[..., 2] *= -1.0
    f = bsdf.interpolant(wi, wo)
    return f.reshape(mu.size * mu.size, -1)


def lowest(f):
    return f.min() / f.max()


#: Single rough interfaces with far fewer orders than their lobes need, so that most pairs are
#: cut and tapered: (layer, [discretization]).
GRAZING_LAYERS = {
    "lacquer": ({"kind": "dielectric", "ior": 1.5, "roughness": 0.3}, {"n": 36, "md": 8}),
    "gold": ({"kind": "conductor", "ior": GOLD, "roughness": 0.05}, {"n": 36, "md": 24}),
}


@pytest.mark.parametrize("projection", ["numeric", "semi-analytic"])
@pytest.mark.parametrize("layer", sorted(GRAZING_LAYERS))
def test_tapered_series_are_non_negative_at_the_ordinates(monkeypatch, projection, layer):
    """Reflection (and, for the lacquer, transmission into it) at every pair of ordinates is
    >= -1e-9 of its peak; with the sigma factors it dips below -1e-3."""
    layer, disc = GRAZING_LAYERS[layer]
    scene = {"layer": [layer], "discretization": disc}
    solve = lambda: layersim.solve(scene, projection=projection)
    bsdf = solve()
    transmits = [False] if bsdf.opaque else [False, True]
    for transmit in transmits:
        assert lowest(node_values(bsdf, transmit)) >= -1e-9, transmit
    monkeypatch.setattr(layersim.operators.fourier, "taper_factors", sigma_factors)
    assert lowest(node_values(solve())) < -1e-3


def test_device_assembly_tapers_with_the_same_kernel(monkeypatch):
    """The numeric projection built wholly on a Warp device (the CPU here) multiplies the
    series of cut pairs by the factors it is given: non-negative reflection at every pair of
    ordinates with the Jackson factors, ringing with the sigma factors."""
    grid, m = Grid.make("gauss-lobatto", 36), 24
    layer = Dielectric(ior=1.5, alpha_u=0.05, alpha_v=0.05)

    def reflection():
        op = numeric_interface_operator(grid, m, layer, 1.0, device="cpu", on_device=True)
        return node_values(layersim.BSDF([op]))

    assert lowest(reflection()) >= -1e-9
    monkeypatch.setattr(layersim.operators.fourier, "taper_factors", sigma_factors)
    assert lowest(reflection()) < -1e-3


def test_coupled_series_ring_far_less_at_the_ordinates(monkeypatch):
    """Anisotropic gold (alpha (0.05, 0.2)) in coupled modes (n = 24, md = 24, the planner's
    ms = 11): the series in (phi_d, phi_s) at every pair of ordinates, for incident azimuths 0,
    40 and 90 deg, is >= -1e-3 of its peak (measured -3.7e-4); with the sigma factors it dips
    to -4.2e-2. What remains is the coupled projection's own, at the most grazing ordinate
    (86 deg): -2.5e-4 with md = 1500, where that pair is not cut; eval's positive part removes
    it."""
    scene = {"layer": [{"kind": "conductor", "ior": GOLD, "roughness": [0.05, 0.2]}],
             "discretization": {"n": 24, "md": 24}}
    phi_i = np.radians([0.0, 40.0, 90.0])
    assert lowest(node_values(layersim.solve(scene), phi_i=phi_i, n_phi=361)) >= -1e-3
    monkeypatch.setattr(layersim.operators.fourier, "taper_factors", sigma_factors)
    assert lowest(node_values(layersim.solve(scene), phi_i=phi_i, n_phi=361)) < -1e-2


# ---- random direction pairs ------------------------------------------------------------------

def uniform_pairs(rng, n, sphere=False):
    def draw():
        z = rng.uniform(-1.0 if sphere else 0.0, 1.0, n)
        return directions(z, rng.uniform(0.0, 2.0 * np.pi, n))
    return draw(), draw()


def grazing_pairs(rng, n):
    """theta_i and theta_o uniform in [80, 89.9] degrees, azimuths uniform."""
    z = lambda: np.cos(np.radians(rng.uniform(80.0, 89.9, n)))
    return (directions(z(), rng.uniform(0.0, 2.0 * np.pi, n)),
            directions(z(), rng.uniform(0.0, 2.0 * np.pi, n)))


def check_pairs(bsdf, n_uniform, n_grazing, seed=0, n_eval=20_000):
    """Interpolant >= -UNDERSHOOT of the peak per channel on uniform and grazing pairs, and
    eval its positive part (checked on the first ``n_eval`` grazing pairs)."""
    rng = np.random.default_rng(seed)
    wi, wo = uniform_pairs(rng, n_uniform, sphere=not bsdf.opaque)
    gi, go = grazing_pairs(rng, n_grazing)
    f = bsdf.interpolant(wi, wo).reshape(n_uniform, -1)
    g = bsdf.interpolant(gi, go).reshape(n_grazing, -1)
    peak = np.maximum(f.max(axis=0), g.max(axis=0))
    assert np.all(peak > 0)
    assert np.all(f.min(axis=0) >= -UNDERSHOOT * peak), f.min(axis=0) / peak
    assert np.all(g.min(axis=0) >= -UNDERSHOOT * peak), g.min(axis=0) / peak
    e = bsdf.eval(gi[:n_eval], go[:n_eval]).reshape(-1, g.shape[1])
    np.testing.assert_array_equal(e, np.maximum(g[:n_eval], 0.0))
    assert np.all(e >= 0.0)


def test_coated_gold_is_non_negative_on_random_pairs(coated_gold):
    """The planner's default for lacquer over gold: with the sigma factors its interpolant went
    down to -3.6e-2 of the peak on 2 % of such pairs (benchmarks/features/eval_positivity.txt)."""
    check_pairs(coated_gold, 50_000, 50_000)


#: Isotropic bench scenes and the examples of the report of negative eval values. The
#: anisotropic bench scenes (additive_validation, gold_under_hg: 25-60 s to solve and minutes to
#: evaluate 1e6 pairs on two cores; gold_blue_hg_coated: 29 GiB at its default plan) are
#: covered by benchmarks/features/eval_positivity.py instead.
SCAN_SCENES = ["benchmarks/scenes/coated_gold.toml", "benchmarks/scenes/coated_hg_diffuse.toml",
               "benchmarks/scenes/dusty_gold.toml", "benchmarks/scenes/ggx_coated_gold.toml",
               "benchmarks/scenes/vandehulst_slab.toml", "examples/car_paint.toml",
               "examples/lacquered_wood.toml"]


@pytest.mark.slow
@pytest.mark.parametrize("path", SCAN_SCENES, ids=[Path(p).stem for p in SCAN_SCENES])
def test_scenes_are_non_negative_on_a_million_pairs(path):
    """1e6 uniform pairs and 2e5 grazing pairs of each scene at its default plan."""
    bsdf = layersim.solve(layersim.Scene.from_toml(ROOT / path))
    check_pairs(bsdf, 1_000_000, 200_000)
