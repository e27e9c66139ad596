"""The binned renderer of ``layersim bench --render`` (layersim/bench/binrender.py) against
closed forms: energy (a uniform sky gives the albedo), a Lambertian sphere (rho / pi times the
irradiance, integrated here without bins), the mirror direction (the azimuth convention), and
the comparison's difference image (zero for identical tables)."""

import numpy as np
import pytest

import layersim
from layersim.bench import binrender, rendercompare
from layersim.bench.runner import direction
from layersim.mitsuba.sky import sky_radiance, sun_samples

VIEW = rendercompare.VIEW
MU = np.linspace(0.0, 1.0, 10)
PHI = np.linspace(0.0, 2 * np.pi, 19)
ANGLES = np.array([0.0, 30.0, 60.0, 85.0])


def _render(table, env, sources=None, resolution=24, per_axis=3, mu=MU, phi=PHI,
            angles=ANGLES):
    mask, normals = binrender.sphere_pixels(resolution, VIEW)
    lbar = binrender.environment_bins(normals, VIEW, mu, phi, env, sources, per_axis)
    lo, hi, w = binrender.interpolation(np.cos(np.radians(angles)), normals @ VIEW)
    return normals, binrender.shade(table, lbar, lo, hi, w)


def _fibonacci_sphere(count):
    """Directions (count, 3) spread evenly over the sphere, each of solid angle 4 pi / count."""
    k = np.arange(count) + 0.5
    z = 1 - 2 * k / count
    r = np.sqrt(1 - z * z)
    p = np.pi * (3 - np.sqrt(5)) * k
    return np.stack([r * np.cos(p), z, r * np.sin(p)], -1)


def test_uniform_sky_of_radiance_one_renders_the_albedo():
    """Any table under L = 1: each pixel's radiance is the table's albedo (sum over bins)
    interpolated linearly in cos theta_v, computed here with np.interp."""
    rng = np.random.default_rng(3)
    table = rng.random((len(ANGLES), 9 * 18))
    albedo = np.array([0.9, 0.7, 0.5, 0.2])
    table *= (albedo / table.sum(axis=1))[:, None]
    normals, L = _render(table, lambda d: np.ones(d.shape[:-1] + (1,)))
    mu_v = normals @ VIEW
    cos = np.cos(np.radians(ANGLES))
    expected = np.interp(np.clip(mu_v, cos[-1], 1), cos[::-1], albedo[::-1])
    np.testing.assert_allclose(L[:, 0], expected, rtol=1e-12, atol=1e-14)


def test_white_lambertian_sphere_under_the_sky_is_albedo_over_pi_times_irradiance():
    """A solved diffuse base (albedo 0.7) under the sky with its sun: rho / pi times the
    irradiance, integrated over 2e5 evenly spread directions (the sun as its point sources),
    within 1 % (the bins' 6 x 6 samples of the smooth sky; the horizon is a step)."""
    rho = 0.7
    bsdf = layersim.solve(layersim.Scene.from_dict({"layer": [{"kind": "diffuse",
                                                               "albedo": rho}]}))
    table = np.array([bsdf.bin_energies(direction(a), MU, PHI)["top"].ravel()
                      for a in ANGLES])
    sources = sun_samples(64)
    normals, L = _render(table, lambda d: sky_radiance(d, sun=False), sources, resolution=16,
                         per_axis=6)
    d = _fibonacci_sphere(200_000)
    sky = sky_radiance(d, sun=False)
    pick = normals[::3]
    cos = np.maximum(pick @ d.T, 0.0)
    irradiance = 4 * np.pi / len(d) * cos @ sky + np.maximum(pick @ sources[0].T, 0) @ sources[1]
    np.testing.assert_allclose(L[::3], rho / np.pi * irradiance, rtol=0.01)


def test_lambertian_under_a_linear_sky_matches_the_closed_form():
    """L_env(d) = 1 + a.d: a Lambertian sphere has radiance rho (1 + 2/3 a.n) exactly; the
    renderer's stratified bins reach it within 2e-3."""
    a = np.array([0.3, 0.5, -0.2])
    rho = 0.6
    table = np.tile(rho * binrender.projected_solid_angles(MU, PHI) / np.pi, (4, 1))
    normals, L = _render(table, lambda d: 1.0 + (d @ a)[..., None], per_axis=4)
    np.testing.assert_allclose(L[:, 0], rho * (1 + 2 / 3 * normals @ a), rtol=2e-3)


def test_a_mirror_table_reflects_the_environment_about_the_normal():
    """All energy in the bin of the mirror direction (phi_o = pi, mu_o = mu_i): the sphere
    shows the linear sky at 2 (n.v) n - v, within the bins' width (a retro-reflection, the
    sign error this checks, would show it at v)."""
    angles = np.linspace(0.0, 80.0, 41)
    mu, phi = np.linspace(0, 1, 65), np.linspace(0, 2 * np.pi, 129)
    table = np.zeros((len(angles), 64 * 128))
    i = np.clip(np.searchsorted(mu, np.cos(np.radians(angles))) - 1, 0, 63)
    table[np.arange(len(angles)), i * 128 + 64] = 1.0       # phi bin [pi, pi + 2 pi / 128)
    a = np.array([0.2, 0.6, 0.3])
    normals, L = _render(table, lambda d: 1.0 + (d @ a)[..., None], resolution=16, mu=mu,
                         phi=phi, angles=angles, per_axis=1)
    mu_v = normals @ VIEW
    keep = mu_v > np.cos(np.radians(75))
    r = 2 * mu_v[:, None] * normals - VIEW
    err = np.abs(L[keep, 0] - (1 + r[keep] @ a))
    assert err.max() < 0.05
    assert np.abs(L[keep, 0] - (1 + VIEW @ a)).max() > 0.3


def test_difference_of_identical_tables_is_zero():
    """The comparison's images from one table as both the solver's and the walk's: the
    difference image is exactly 0 on the sphere and the relative difference 0."""
    rng = np.random.default_rng(1)
    table = rng.random((4, 9 * 18, 1)) / 200
    tab = {"angles": ANGLES, "mu_edges": MU, "phi_edges": PHI, "solver": table,
           "montecarlo": table.copy(), "stderr": table / 10}
    img = rendercompare.images(tab, 20, lambda d: sky_radiance(d, sun=False), sun_samples(16))
    on = ~np.isnan(img["difference"])
    assert on.sum() > 200 and np.all(img["difference"][on] == 0.0)
    assert img["relative"] == 0.0 and np.all(img["sigma"][on] > 0)


def test_sun_samples_carry_the_discs_irradiance():
    """The sun's point sources sum to SUN_RADIANCE times the disc's solid angle and lie on it."""
    from layersim.mitsuba import sky
    dirs, w = sun_samples(100)
    omega = 2 * np.pi * (1 - np.cos(sky.SUN_RADIUS))
    np.testing.assert_allclose(w.sum(axis=0), sky.SUN_RADIANCE * omega)
    assert np.all(dirs @ sky.sun_direction() >= np.cos(sky.SUN_RADIUS) - 1e-12)
    assert np.all(sky_radiance(dirs).min(axis=1) > sky.SUN_RADIANCE)


@pytest.mark.parametrize("argv, message", [
    (["--render-paths", "0"], "--render-paths 0"),
    (["--render-paths", "100"], "add --render"),
])
def test_bench_refuses_bad_render_options_in_one_line(tmp_path, capsys, argv, message):
    from layersim.cli import main
    assert main(["bench", "--quick", "--out", str(tmp_path / "o")] + argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err and "Traceback" not in err


def test_report_text_says_what_is_missing():
    """The report's paragraph names a skipped scene's reason, a missing walk and a missing
    Mitsuba render instead of leaving them out silently."""
    from layersim.bench import renderfigure
    (skip, _) = renderfigure.markdown({"skipped": "anisotropic stack: azimuth"})
    assert "skipped (anisotropic stack: azimuth)" in skip
    row = {"bins": [18, 36], "angles": 16, "particles": 1_000_000,
           "mitsuba_note": "mitsuba not installed (No module named 'mitsuba')"}
    (text, _) = renderfigure.markdown(row)
    assert "16 incidence angles" in text and "1e+06 paths per angle" in text
    assert "no Monte Carlo backend" in text and "No Mitsuba render: mitsuba not installed" in text
