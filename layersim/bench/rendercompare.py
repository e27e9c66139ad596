"""Rendered comparison of a bench scene (``layersim bench --render``): the solver's bin energies
and the Monte Carlo walk's, at the same incidence angles and bins, rendered by the same
binned renderer (:mod:`layersim.bench.binrender`) on a sphere under the procedural sky of
``layersim render`` (:mod:`layersim.mitsuba.sky`), their signed difference, and beside them
the solver's continuous BSDF rendered by Mitsuba 3 (the ``layersim`` plug-in) from the same
orthographic view where mitsuba is installed.

The binned images show the material through its bins (a glossy lobe narrower than a bin is
blurred); their difference is the difference of the two tables only, which includes the
walk's noise: the figure states its standard error propagated to the image. Reflection only
(top side): light transmitted through the sphere is not rendered in the binned images (the
Mitsuba render includes it). Anisotropic stacks are skipped: their bins depend on the
incident azimuth too, which a table over incidence elevation alone does not hold.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from ..errors import LayersimError
from . import binrender

#: Direction toward the camera (world, y up): that of ``layersim render``'s perspective view.
VIEW = np.array([0.0, 0.8, 4.2]) / np.hypot(0.8, 4.2)
#: Largest tabulated incidence angle (degrees): beyond it the table is held constant.
MAX_ANGLE = 85.0
#: Points standing for the sun disc (:func:`layersim.mitsuba.sky.sun_samples`).
SUN_POINTS = 256
def table_angles(count: int) -> np.ndarray:
    """Incidence angles (degrees) of the tables: ``count`` from 0 to :data:`MAX_ANGLE`."""
    return np.linspace(0.0, MAX_ANGLE, count)


def _flat(x, shape) -> np.ndarray:
    """Top-side bins (n_mu, n_phi[, C]) as (n_bins, C)."""
    return np.asarray(x, float).reshape(shape[0] * shape[1], -1)


def tables(scene, bsdf, mc, s, direction) -> dict:
    """Bin energies of the top side at :func:`table_angles` (``s.render_angles``) in
    ``s.render_bins``: ``solver`` (K, n_bins, C) from ``bsdf.bin_energies``; ``montecarlo``,
    ``stderr`` from ``s.render_particles`` paths per angle (seed ``s.seed + k`` at the k-th
    angle, backend ``s.backends[0]``), with their wall times; ``montecarlo`` None without a
    walk. ``direction(theta_deg)`` gives the incident direction at azimuth 0."""
    n_mu, n_phi = s.render_bins
    mu, phi = np.linspace(0, 1, n_mu + 1), np.linspace(0, 2 * np.pi, n_phi + 1)
    angles = table_angles(s.render_angles)
    t0 = time.perf_counter()
    solver = np.array([_flat(bsdf.bin_energies(direction(a), mu, phi)["top"], (n_mu, n_phi))
                       for a in angles])
    out = {"angles": angles, "mu_edges": mu, "phi_edges": phi, "solver": solver,
           "solver_seconds": time.perf_counter() - t0, "montecarlo": None}
    if mc is None:
        return out
    t0 = time.perf_counter()
    runs = [mc.simulate(scene, direction(a), s.render_particles, mu_edges=mu, phi_edges=phi,
                        backend=s.backends[0], seed=s.seed + k) for k, a in enumerate(angles)]
    out["montecarlo"] = np.array([_flat(r.bins["top"], (n_mu, n_phi)) for r in runs])
    out["stderr"] = np.array([_flat(r.bins_stderr["top"], (n_mu, n_phi)) for r in runs])
    out["montecarlo_seconds"] = time.perf_counter() - t0
    out["backend"] = runs[0].backend
    return out


def images(tab: dict, resolution: int, env, sources=None, per_axis: int = 3) -> dict:
    """The binned renders of ``tab`` (:func:`tables`): linear RGB images (H, W, 3), NaN off
    the sphere, for ``solver`` and ``montecarlo``; ``difference``, the luminance of solver
    minus walk (H, W); ``sigma``, the walk's standard error of that luminance (H, W); and
    ``relative``, the RMS of the difference over the RMS of the walk's luminance on the
    sphere. ``env``, ``sources``, ``per_axis``: :func:`binrender.environment_bins`."""
    mask, normals = binrender.sphere_pixels(resolution, VIEW)
    lbar = binrender.environment_bins(normals, VIEW, tab["mu_edges"], tab["phi_edges"], env,
                                      sources, per_axis)
    lo, hi, w = binrender.interpolation(np.cos(np.radians(tab["angles"])), normals @ VIEW)
    out = {"solver": binrender.to_image(mask, binrender.shade(tab["solver"], lbar, lo, hi, w))}
    if tab["montecarlo"] is None:
        return out
    walk = binrender.shade(tab["montecarlo"], lbar, lo, hi, w)
    sigma = binrender.luminance_stderr(tab["stderr"], lbar, lo, hi, w)
    out["montecarlo"] = binrender.to_image(mask, walk)
    diff = binrender.luminance(out["solver"]) - binrender.luminance(out["montecarlo"])
    out["difference"] = diff
    out["sigma"] = binrender.to_image(mask, sigma[:, None])[..., 0]
    lum = binrender.luminance(walk)
    out["relative"] = float(np.sqrt(np.mean(diff[mask] ** 2) / np.mean(lum ** 2)))
    return out


def mitsuba_render(bsdf, resolution: int, spp: int):
    """The solved BSDF (continuous, not binned) rendered by Mitsuba 3 from the view of the
    binned images: ``(image (H, W, 3) linear RGB, variant)``, or ``(None, reason)`` where
    mitsuba is not installed or refuses."""
    try:
        from ..mitsuba.render import render_orthographic
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "stack.lsim"
            bsdf.save(path)
            return render_orthographic(path, resolution, spp, VIEW)
    except ImportError as exc:      # mitsuba is optional
        return None, f"mitsuba not installed ({exc})"
    except LayersimError as exc:
        return None, str(exc)


def run(scene, bsdf, mc, s, direction, log=print) -> tuple[dict, dict]:
    """The render step of one bench scene: ``(row, images)``, ``row`` for results.json
    (settings, times, the image-space difference; ``skipped`` with the reason for
    anisotropic stacks) and ``images`` for the figure (:mod:`layersim.bench.renderfigure`)."""
    from ..mitsuba.sky import sky_radiance, sun_samples
    row = {"angles": s.render_angles, "bins": list(s.render_bins),
           "particles": s.render_particles, "resolution": s.render_resolution}
    if bsdf.anisotropic:
        row["skipped"] = ("anisotropic stack: its bins depend on the incident azimuth, which "
                          "the binned renderer's table over incidence elevation does not hold")
        log(f"  render: skipped ({row['skipped']})")
        return row, {}
    tab = tables(scene, bsdf, mc, s, direction)
    t0 = time.perf_counter()
    img = images(tab, s.render_resolution, lambda d: sky_radiance(d, sun=False),
                 sun_samples(SUN_POINTS))
    row.update(solver_seconds=tab["solver_seconds"], render_seconds=time.perf_counter() - t0,
               montecarlo_seconds=tab.get("montecarlo_seconds"), backend=tab.get("backend"))
    if "relative" in img:
        row["relative_difference"] = img["relative"]
        row["sigma_rms"] = float(np.sqrt(np.nanmean(img["sigma"] ** 2)))
        on = ~np.isnan(img["difference"])
        # pixels share bins, so this is a picture of where the difference exceeds the
        # walk's noise, not a count of independent tests
        row["within_3sigma"] = float(np.mean(np.abs(img["difference"][on])
                                             <= 3 * img["sigma"][on]))
    t0 = time.perf_counter()
    img["mitsuba"], info = mitsuba_render(bsdf, s.render_resolution, s.render_spp)
    row["mitsuba" if img["mitsuba"] is not None else "mitsuba_note"] = info
    row.update(spp=s.render_spp, mitsuba_seconds=time.perf_counter() - t0)
    log(f"  render: walk {row.get('montecarlo_seconds') or 0:.1f} s, binned renders "
        f"{row['render_seconds']:.1f} s, Mitsuba ({info}) "
        f"{row['mitsuba_seconds']:.1f} s; solver - walk, relative RMS "
        f"{row.get('relative_difference', float('nan')):.2e}")
    return row, img
