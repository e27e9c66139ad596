"""Thin-film interfaces (``film = { thickness, ior }``): the solver against the Monte Carlo walk,
and the reflectance spectrum against the angle.

Three filmed stacks at ``[stack] wavelengths = [650, 550, 450]`` (nm), each beside the same stack
without its film: a soap-bubble-like water film (350 nm, n = 1.33) on rough glass (alpha 0.15),
silica (300 nm, n = 1.46) on rough gold (alpha 0.2; gold's RGB indices of
examples/rgb_coated_gold.toml), and a rough lacquer (alpha 0.2, n = 1.5) carrying a 300 nm
film of n = 1.38 over an HG medium over a Lambertian base. For each incident elevation it prints
the solver's and the walk's albedos (R, T per channel, the difference in walk standard errors),
the fraction of populated bins (8 x 12 per side) within 3 and 4 standard errors, and the same
for the bare stack (the control: what the film changes, and the solver's own error there).
Incidence is at 0, 30 and 55 degrees (azimuth 20), and at the plan's ordinates nearest to 30
and 55 degrees ("node"): between ordinates the solver interpolates the incident elevation, and
a film's reflectance oscillates with the angle (the last block: the error there against n).

The figure (docs/images/thin_film_spectrum.png) shows the reflectance against wavelength
(400-700 nm) and incidence angle: the Airy reflectance of the smooth water film on glass and of
a smooth 300 nm silica film on a metal of constant index 1.5 + 3i (so that every colour is the
film's), from :func:`layersim.kernels.fresnel.fresnel` (the solver's smooth interfaces), and the
solver's directional albedo of the same film on that metal with roughness 0.2 (one solve per
wavelength, 61 wavelengths). Each panel's colour scale spans its values up to 75 degrees
(grazing reflectance, towards 1, saturates it).

Usage: python benchmarks/features/thin_film.py [paths] [backend] [--no-plot | --plot-only]
       (default 1e7 warp-cpu)
"""

from __future__ import annotations

import datetime
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import layersim
import layersim.montecarlo as mc
from layersim.kernels.fresnel import fresnel

ROOT = Path(__file__).resolve().parents[2]
MU_EDGES = np.linspace(0.0, 1.0, 9)
PHI_EDGES = np.linspace(0.0, 2 * np.pi, 13)
RGB = [650.0, 550.0, 450.0]
GOLD_RGB = [[0.143552, 3.98397], [0.377438, 2.38495], [1.43825, 1.60434]]
#: (elevation in degrees, at the plan's nearest ordinate)
INCIDENCE = ((0.0, False), (30.0, False), (30.0, True), (55.0, False), (55.0, True))

STACKS = {
    "water film (350 nm, 1.33) on rough glass": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.15,
         "film": {"thickness": 350.0, "ior": 1.33}}],
    "silica (300 nm, 1.46) on rough gold": [
        {"kind": "conductor", "ior": GOLD_RGB, "roughness": 0.2,
         "film": {"thickness": 300.0, "ior": 1.46}}],
    "filmed lacquer (300 nm, 1.38) over HG over diffuse": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.2,
         "film": {"thickness": 300.0, "ior": 1.38}},
        {"kind": "medium", "albedo": 0.9, "g": 0.5, "tau": 1.0},
        {"kind": "diffuse", "albedo": 0.5}],
}


def unit(theta_deg: float, phi_deg: float = 20.0) -> np.ndarray:
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def scene(layers, wavelengths=RGB) -> layersim.Scene:
    return layersim.Scene.from_dict({"stack": {"wavelengths": list(wavelengths)},
                                     "layer": layers})


def bare(layers) -> list:
    return [{k: v for k, v in layer.items() if k != "film"} for layer in layers]


def fmt(values) -> str:
    return "(" + ", ".join(f"{x:.5f}" for x in np.atleast_1d(values)) + ")"


def against_walk(s, wi, paths, backend, seed, bsdf):
    """The solver's (``bsdf``) albedos and bins against the walk's: (R, T, walk result, z of R,
    z of T, bin z-scores, walk seconds)."""
    t0 = time.perf_counter()
    res = mc.simulate(s, wi, paths, MU_EDGES, PHI_EDGES, backend=backend, seed=seed)
    t_walk = time.perf_counter() - t0
    R, T = (x[0] for x in bsdf.albedo(wi[None]))
    zR = (R - res.reflectance) / np.maximum(res.reflectance_stderr, 1e-15)
    zT = (T - res.transmittance) / np.maximum(res.transmittance_stderr, 1e-15)
    bins = bsdf.bin_energies(wi, MU_EDGES, PHI_EDGES)
    z = np.concatenate([res.z_scores(side, bins[side]).ravel() for side in ("top", "bottom")])
    return R, T, res, zR, zT, z, t_walk


def report(label: str, R, T, res, zR, zT, z) -> None:
    print(f"    {label:5s} R {fmt(R)} walk {fmt(res.reflectance)} "
          f"({', '.join(f'{x:+.2f}' for x in zR)} se)")
    if np.any(T > 0) or np.any(res.transmittance > 0):
        print(f"          T {fmt(T)} walk {fmt(res.transmittance)} "
              f"({', '.join(f'{x:+.2f}' for x in zT)} se)")
    print(f"          bins {z.size}: {100 * np.mean(z <= 3):5.1f} % <= 3 sigma, "
          f"{100 * np.mean(z <= 4):5.1f} % <= 4, max {z.max():.2f}", flush=True)


def compare(name: str, layers: list, theta: float, node: bool, paths: int, backend: str,
            seed: int):
    s = scene(layers)
    t0 = time.perf_counter()
    bsdf = layersim.solve(s)
    t_solve = time.perf_counter() - t0
    if node:
        mu = bsdf.grid.mu
        theta = float(np.degrees(np.arccos(mu[np.argmin(np.abs(mu - np.cos(np.radians(theta))))])))
    wi = unit(theta)
    film = against_walk(s, wi, paths, backend, seed, bsdf)
    plain_bsdf = layersim.solve(scene(bare(layers)))
    plain = against_walk(scene(bare(layers)), wi, paths, backend, seed, plain_bsdf)
    where = "node" if node else "    "
    print(f"{name:52s} {theta:6.2f} deg {where}  n={bsdf.grid.n:3d} md={bsdf.operators[0].m:3d} "
          f"(bare: md={plain_bsdf.operators[0].m:3d}) solve {t_solve:4.2f} s walk {film[6]:5.1f} s")
    report("film", *film[:6])
    report("bare", *plain[:6])
    out = []
    for zR, zT, z in ((film[3], film[4], film[5]), (plain[3], plain[4], plain[5])):
        out.append((float(np.max(np.abs(np.concatenate([zR, zT])))), float(np.mean(z <= 3))))
    return out


def interpolation(paths: int, backend: str) -> None:
    """Between ordinates the solver interpolates the incident elevation linearly in ``mu``; a
    film's reflectance oscillates with the angle, so the error there falls with ``n``: the
    silica on gold at 30 degrees at the plan's n and finer grids."""
    layers = STACKS["silica (300 nm, 1.46) on rough gold"]
    wi = unit(30.0)
    res = mc.simulate(scene(layers), wi, paths, backend=backend, seed=3000)
    print(f"# between ordinates: silica on gold at 30 deg, walk R {fmt(res.reflectance)} "
          f"(standard errors {fmt(res.reflectance_stderr)})")
    for n in (None, 128, 256):
        data = {"stack": {"wavelengths": RGB}, "layer": layers}
        if n:
            data["discretization"] = {"n": n}
        bsdf = layersim.solve(layersim.Scene.from_dict(data))
        R = bsdf.albedo(wi[None])[0][0]
        print(f"    n = {bsdf.grid.n:3d}: R {fmt(R)}, solver - walk "
              f"({', '.join(f'{x:+.1e}' for x in R - res.reflectance)})", flush=True)


def spectrum_figure(path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lam = np.linspace(400.0, 700.0, 61)
    theta = np.arange(0.0, 89.5, 1.0)
    c = np.cos(np.radians(theta))
    metal = [1.5, 3.0]

    def airy(eta, k, n_film, d):
        return np.stack([fresnel(c, eta, k, (n_film, 4 * np.pi * n_film * d / x)) for x in lam],
                        axis=1)

    water = airy(1.5, 0.0, 1.33, 350.0)
    silica = airy(*metal, 1.46, 300.0)
    rough = np.zeros((theta.size, lam.size))
    wi = np.stack([np.sin(np.radians(theta)), 0 * theta, c], axis=1)
    t0 = time.perf_counter()
    for j, x in enumerate(lam):
        s = scene([{"kind": "conductor", "ior": metal, "roughness": 0.2,
                    "film": {"thickness": 300.0, "ior": 1.46}}], [x])
        rough[:, j] = np.asarray(layersim.solve(s).albedo(wi)[0]).reshape(theta.size)
    print(f"# figure: {lam.size} solves of the rough filmed metal in "
          f"{time.perf_counter() - t0:.1f} s")
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2), constrained_layout=True)
    panels = ((water, "water film 350 nm (n 1.33) on smooth glass"),
              (silica, "silica 300 nm (n 1.46) on a smooth metal 1.5+3i"),
              (rough, "the same on the metal, roughness 0.2 (solver albedo)"))
    for ax, (R, title) in zip(axes, panels):
        # the scale of the angles below 75 degrees: grazing reflectance would wash them out
        low = R[theta <= 75.0]
        im = ax.pcolormesh(lam, theta, R, shading="nearest", cmap="magma", vmin=low.min(),
                           vmax=low.max())
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("wavelength (nm)")
        fig.colorbar(im, ax=ax, label="reflectance", extend="max")
    axes[0].set_ylabel("incidence (degrees)")
    fig.savefig(path, dpi=110)
    print(f"# wrote {path.relative_to(ROOT)}")


def main() -> None:
    if "--plot-only" in sys.argv:
        spectrum_figure(ROOT / "docs" / "images" / "thin_film_spectrum.png")
        return
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    paths = int(float(args[0])) if args else 10_000_000
    backend = args[1] if len(args) > 1 else "warp-cpu"
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                            capture_output=True, text=True).stdout.strip() or "not recorded"
    print(f"# {paths:.3g} paths per direction and channel, backend {backend}, "
          f"{platform.node()} ({platform.processor() or platform.machine()}), "
          f"{datetime.date.today()}, commit {commit}")
    # [film, bare] -> {at an ordinate: largest |z| of the albedos}, and bin fractions
    worst = [{False: 0.0, True: 0.0}, {False: 0.0, True: 0.0}]
    fractions = [[], []]
    seed = 2000
    for name, layers in STACKS.items():
        for theta, node in INCIDENCE:
            # normal incidence is an ordinate (Gauss-Lobatto includes mu = 1)
            at_node = node or theta == 0.0
            for k, (z, f3) in enumerate(compare(name, layers, theta, node, paths, backend,
                                                seed)):
                worst[k][at_node] = max(worst[k][at_node], z)
                fractions[k].append(f3)
            seed += 1
    for k, label in enumerate(("filmed", "bare")):
        print(f"# {label}: albedos within {worst[k][True]:.2f} walk standard errors at "
              f"ordinates, {worst[k][False]:.2f} between them; bins within 3 sigma: "
              f"{100 * min(fractions[k]):.1f}-{100 * max(fractions[k]):.1f} %")
    interpolation(paths, backend)
    if "--no-plot" not in sys.argv:
        spectrum_figure(ROOT / "docs" / "images" / "thin_film_spectrum.png")


if __name__ == "__main__":
    main()
