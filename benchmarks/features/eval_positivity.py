"""Negative values of ``BSDF.eval``: where they come from, and what keeping them away changes.

Four sections (all float64, fixed seeds):

``sources``
    Which candidate makes the spline interpolant negative, for a few scenes: the same solve with
    the Lanczos sigma factors ``sinc(l / m)`` on lobes cut in azimuth ('before'), with
    no taper (plain truncation), with the sigma factors and twice the orders, and with the
    Jackson kernel factors (:func:`layersim.operators.fourier.taper_factors`, the library's); each
    evaluated with the cubic interpolation in the elevations and with linear interpolation
    (non-negative weights). Lowest value over the BSDF's peak and the fraction of pairs below
    ``-1e-6`` of the peak.
``scenes``
    Per scene: per channel, the lowest value over the peak and the fraction of negative pairs
    (below ``-1e-6`` of the peak) of what ``eval`` returned before (the interpolant of the solve
    with sigma factors) and of the interpolant and ``eval`` now (the positive part of the
    interpolant of the solve with Jackson factors), on uniform pairs (both directions uniform on
    the hemisphere; on the sphere for transmissive stacks) and on grazing pairs (theta_i and
    theta_o uniform in 80-89.9 degrees, azimuths uniform); the mass that the positive part adds
    (cosine-weighted, relative to the whole, uniform pairs); and the change of the albedo and
    of the 18 x 36 bin energies (both sides) between the two solves at incidence 0, 30, 60, 80,
    85 and 89 degrees.
``walk``
    Top bin energies of both solves against the Monte Carlo walk at incidence 60, 80, 85 and
    89 degrees (relative L2, beside the walk's own noise in the same measure).
``exact``
    Single rough interfaces against the exact microfacet model they project
    (:func:`layersim.kernels.projection.microfacet_values`), on grazing reflection pairs: the
    relative L1 error of ``f |cos theta_o|`` over all grazing pairs, over those within 10
    degrees of the specular azimuth, and the relative L2 error near the peak (pairs with the
    model above 5 % of its maximum), for both tapers.

The 'before' reconstruction is made by substituting the sigma factors for
``layersim.operators.fourier.taper_factors`` during its solve, the only difference between the two
solves; linear interpolation (section ``sources``) by substituting
:func:`layersim.operators.interpolation.hat_weights` for the spline weights of ``eval``.

Usage: python benchmarks/features/eval_positivity.py [--pairs N] [--grazing N] [--sections S,...]
[--source-scenes A,B,...] [--walk-scenes A,B,...] [--paths N] [SCENE[:KEY=VALUE,...] ...] (section ``sources``: coated_gold and
car_paint by default, N grazing and N uniform pairs; the others: the SCENEs). SCENE is a name
in benchmarks/scenes or examples, in :data:`INLINE` (``rough_glass``, ``rotated_conductor``)
or a .toml path; KEY=VALUE set ``[discretization]`` fields over the planner's (default: every
scene of benchmarks/scenes, examples/car_paint, examples/lacquered_wood and rough_glass).
Output: benchmarks/features/eval_positivity.txt.
"""
import argparse
import contextlib
import datetime
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parents[1])]
from headline import commit, machine  # noqa: E402

import layersim  # noqa: E402
import layersim.operators.fourier  # noqa: E402
import layersim.operators.interpolation  # noqa: E402
from layersim.kernels.projection import microfacet_values  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "benchmarks" / "scenes"
EXAMPLES = ROOT / "examples"
#: Scenes given inline: a single rough dielectric interface (all four blocks), whose interpolant
#: undershoots next to the critical angle, and a rotated anisotropic conductor, whose coupled
#: modes (|s| <= ms) are cut without taper.
INLINE = {"rough_glass": {"stack": {"name": "rough_glass"},
                          "layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.3}]},
          "rotated_conductor": {"stack": {"name": "rotated_conductor"},
                                "layer": [{"kind": "conductor", "ior": [0.2, 3.0],
                                           "roughness": [0.15, 0.45], "rotation": 20.0}]}}
DEFAULT_SCENES = (sorted(p.stem for p in SCENES.glob("*.toml"))
                  + ["car_paint", "lacquered_wood", "rough_glass"])
SOURCE_SCENES = ("coated_gold", "car_paint")
WALK_SCENES = ("coated_gold", "rotated_conductor", "additive_validation")
ANGLES = (0.0, 30.0, 60.0, 80.0, 85.0, 89.0)
MU_EDGES = np.linspace(0.0, 1.0, 19)
PHI_EDGES = np.linspace(0.0, 2.0 * np.pi, 37)
#: Relative depth below which a value counts as negative (per channel, of the BSDF's peak).
NEGATIVE = 1e-6
GOLD = (0.143552, 3.98397)


def sigma_factors(m: int) -> np.ndarray:
    """Lanczos sigma factors, the taper before the Jackson kernel."""
    return np.sinc(np.arange(m) / m)


def untapered(m: int) -> np.ndarray:
    return np.ones(m)


@contextlib.contextmanager
def substituted(module, name: str, value):
    """``module.name`` replaced by ``value`` inside the block."""
    saved = getattr(module, name)
    setattr(module, name, value)
    try:
        yield
    finally:
        setattr(module, name, saved)


def solve(scene, taper=None):
    """The BSDF of ``scene`` and its solve time; ``taper`` (a function of m) replaces the
    library's taper factors during the solve."""
    t0 = time.perf_counter()
    if taper is None:
        bsdf = layersim.solve(scene)
    else:
        with substituted(layersim.operators.fourier, "taper_factors", taper):
            bsdf = layersim.solve(scene)
    return bsdf, time.perf_counter() - t0


def interpolant(bsdf, wi, wo, linear=False) -> np.ndarray:
    """The spline interpolant (cubic, or linear in both elevations), shape (Q, channels)."""
    if linear:
        with substituted(layersim.operators.interpolation, "spline_weights",
                         layersim.operators.interpolation.hat_weights):
            f = bsdf.interpolant(wi, wo)
    else:
        f = bsdf.interpolant(wi, wo)
    return f.reshape(wi.shape[0], -1)


def directions(theta, phi) -> np.ndarray:
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)],
                    axis=-1)


def uniform_pairs(rng, n: int, sphere: bool):
    """``n`` pairs, both directions uniform on the upper hemisphere (on the sphere)."""
    def draw():
        z = rng.random(n) * (2.0 if sphere else 1.0) - (1.0 if sphere else 0.0)
        return directions(np.arccos(z), 2.0 * np.pi * rng.random(n))
    return draw(), draw()


def grazing_pairs(rng, n: int):
    """``n`` pairs with theta_i, theta_o uniform in [80, 89.9] degrees, azimuths uniform."""
    th = lambda: np.radians(rng.uniform(80.0, 89.9, n))
    ph = lambda: rng.uniform(0.0, 2.0 * np.pi, n)
    return directions(th(), ph()), directions(th(), ph())


def depth(f: np.ndarray, peak: np.ndarray):
    """Lowest value over the peak and the fraction below ``-NEGATIVE`` of it, per channel."""
    return f.min(axis=0) / peak, np.mean(f < -NEGATIVE * peak, axis=0)


def negative_mass(f: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Cosine-weighted mass of the negative part relative to the whole, per channel."""
    fc = f * np.abs(wo[:, 2:3])
    return np.maximum(-fc, 0.0).sum(axis=0) / np.abs(fc).sum(axis=0)


def incident(theta: float) -> np.ndarray:
    t = np.radians(theta)
    return np.array([np.sin(t), 0.0, np.cos(t)])


def energies(bsdf):
    """Albedo (R, T) and bin energies (2, 18, 36, channels) at each of :data:`ANGLES`."""
    out = []
    for theta in ANGLES:
        wi = incident(theta)
        R, T = (np.atleast_1d(x).reshape(-1) for x in bsdf.albedo(wi))
        e = bsdf.bin_energies(wi, MU_EDGES, PHI_EDGES)
        bins = np.stack([np.asarray(e[s]).reshape(18, 36, -1) for s in ("top", "bottom")])
        out.append((R, T, bins))
    return out


def fmt(a, spec=".2g") -> str:
    return "/".join(format(float(x), spec) for x in np.atleast_1d(a))


def load(spec: str):
    """Label and scene of ``NAME[:KEY=VALUE,...]``: NAME in benchmarks/scenes, examples or
    :data:`INLINE`, or a .toml path; KEY=VALUE set ``[discretization]`` fields (integers)."""
    name, _, fields = spec.partition(":")
    if name in INLINE:
        scene = layersim.Scene.from_dict(INLINE[name])
    else:
        path = Path(name)
        if path.suffix != ".toml":
            path = SCENES / f"{name}.toml"
            if not path.exists():
                path = EXAMPLES / f"{name}.toml"
        scene = layersim.Scene.from_toml(path)
    if fields:
        values = {k: int(v) for k, v in (f.split("=") for f in fields.split(","))}
        scene = replace(scene, discretization=replace(scene.discretization, **values))
    return spec, scene


# ---- sections -----------------------------------------------------------------------------

def section_sources(names, n: int, seed: int) -> None:
    print("## sources: lowest interpolant / peak and fraction of pairs below -1e-6 peak "
          f"({n} uniform + {n} grazing pairs; per channel)")
    for name in names:
        _, scene = load(name)
        rng = np.random.default_rng(seed)
        wi, wo = uniform_pairs(rng, n, sphere=False)
        gi, go = grazing_pairs(rng, n)
        wi, wo = np.concatenate([wi, gi]), np.concatenate([wo, go])
        base, _ = solve(scene)
        plan = base.plan
        more = replace(scene, discretization=replace(scene.discretization, n=plan.n,
                                                     md=2 * plan.md))
        variants = (("Jackson (library)", base),
                    ("sigma factors (before)", solve(scene, sigma_factors)[0]),
                    ("no taper (truncated)", solve(scene, untapered)[0]),
                    (f"sigma factors, md = {2 * plan.md}", solve(more, sigma_factors)[0]))
        print(f"{name}: n = {plan.n}, md = {plan.md}")
        for label, bsdf in variants:
            cubic = interpolant(bsdf, wi, wo)
            linear = interpolant(bsdf, wi, wo, linear=True)
            peak = cubic.max(axis=0)
            (cmin, cfrac), (lmin, lfrac) = depth(cubic, peak), depth(linear, peak)
            print(f"  {label:28s} peak {fmt(peak, '.5g')} 1/sr | cubic: min {fmt(cmin)}, "
                  f"negative {fmt(cfrac)} | linear in mu: min {fmt(lmin)}, negative "
                  f"{fmt(lfrac)}", flush=True)


def section_scenes(names, n: int, n_grazing: int, seed: int) -> None:
    print(f"## scenes: {n} uniform pairs (u) and {n_grazing} grazing pairs (g); per channel "
          "(R/G/B); 'before' = sigma factors, eval = interpolant; 'after' = Jackson factors")
    for name in names:
        label, scene = load(name)
        try:
            after, t_after = solve(scene)
        except layersim.InfeasibleError as exc:
            print(f"{label}: not solved on this machine: {exc}")
            continue
        before, t_before = solve(scene, sigma_factors)
        rng = np.random.default_rng(seed)
        wi, wo = uniform_pairs(rng, n, sphere=not after.opaque)
        gi, go = grazing_pairs(rng, n_grazing)
        fb = [interpolant(before, a, b) for a, b in ((wi, wo), (gi, go))]
        fa = [interpolant(after, a, b) for a, b in ((wi, wo), (gi, go))]
        ev = [after.eval(a, b).reshape(a.shape[0], -1) for a, b in ((wi, wo), (gi, go))]
        pb = np.maximum(fb[0].max(axis=0), fb[1].max(axis=0))
        pa = np.maximum(fa[0].max(axis=0), fa[1].max(axis=0))
        print(f"{label}: {after!r}; solve {t_before:.1f} s before, {t_after:.1f} s after")
        print(f"  peak (1/sr)          before {fmt(pb, '.5g')}  after {fmt(pa, '.5g')}")
        for tag, k in (("u", 0), ("g", 1)):
            (bmin, bfrac), (amin, afrac) = depth(fb[k], pb), depth(fa[k], pa)
            print(f"  {tag}: before min/peak {fmt(bmin)} negative {fmt(bfrac)} | after "
                  f"interpolant min/peak {fmt(amin)} negative {fmt(afrac)} | eval min "
                  f"{fmt(ev[k].min(axis=0))}")
        print(f"  mass added by eval's positive part (u): {fmt(negative_mass(fa[0], wo))}; "
              f"before, the negative mass was {fmt(negative_mass(fb[0], wo))}")
        for theta, (Rb, Tb, Bb), (Ra, Ta, Ba) in zip(ANGLES, energies(before), energies(after)):
            l2 = np.sqrt(np.sum((Ba - Bb) ** 2, axis=(0, 1, 2)) / np.sum(Bb ** 2, axis=(0, 1, 2)))
            print(f"  {theta:4.0f} deg: |dR| {fmt(np.abs(Ra - Rb))} |dT| {fmt(np.abs(Ta - Tb))}"
                  f" | bins: rel L2 {fmt(l2)}, max |dE| {fmt(np.abs(Ba - Bb).max(axis=(0, 1, 2)))}"
                  f", |d sum| {fmt(np.abs((Ba - Bb).sum(axis=(0, 1, 2))))}")
        print(flush=True)


def section_walk(names, paths: int, seed: int) -> None:
    """Bin energies of both solves against the Monte Carlo walk (first channel) at grazing
    incidence, where the tapers differ."""
    import layersim.montecarlo as mc
    print(f"## walk: top bin energies (18 x 36) against the walk at {paths:.0e} paths (warp-cpu; "
          "first channel): relative L2 to the walk for both solves, and the walk's own noise in "
          "the same measure (sqrt(sum var) / sqrt(sum E^2))")
    for name in names:
        label, scene = load(name)
        after, _ = solve(scene)
        before, _ = solve(scene, sigma_factors)
        mono = scene.channel(0) if scene.channels > 1 else scene
        for k, theta in enumerate((60.0, 80.0, 85.0, 89.0)):
            wi = incident(theta)
            res = mc.simulate(mono, wi, paths, mu_edges=MU_EDGES, phi_edges=PHI_EDGES,
                              backend="warp-cpu", seed=seed + k)
            est = np.asarray(res.bins["top"]).reshape(18, 36, -1)[..., 0]
            var = np.asarray(res.bins_stderr["top"]).reshape(18, 36, -1)[..., 0] ** 2
            norm = np.sqrt(np.sum(est ** 2))
            l2 = {}
            for tag, bsdf in (("before", before), ("after", after)):
                e = np.asarray(bsdf.bin_energies(wi, MU_EDGES, PHI_EDGES)["top"])
                l2[tag] = np.sqrt(np.sum((e.reshape(18, 36, -1)[..., 0] - est) ** 2)) / norm
            print(f"  {label} {theta:3.0f} deg: before {l2['before']:.2e}, after "
                  f"{l2['after']:.2e}, walk noise {np.sqrt(var.sum()) / norm:.2e}", flush=True)


def exact_reflection(layer: dict, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """The microfacet model of a single interface (in vacuum) for reflection pairs."""
    ior = layer["ior"]
    eta = complex(*ior) if isinstance(ior, (list, tuple)) else complex(ior)
    dphi = np.arctan2(wo[:, 1], wo[:, 0]) - np.arctan2(wi[:, 1], wi[:, 0]) - np.pi
    alpha = layer["roughness"]
    return microfacet_values(wi[:, 2], -wo[:, 2], dphi[:, None], eta, alpha, alpha)[:, 0]


def section_exact(n: int, seed: int) -> None:
    layers = (("gold, alpha 0.1", {"kind": "conductor", "ior": list(GOLD), "roughness": 0.1}),
              ("dielectric 1.5, alpha 0.1", {"kind": "dielectric", "ior": 1.5, "roughness": 0.1}),
              ("dielectric 1.5, alpha 0.05", {"kind": "dielectric", "ior": 1.5,
                                              "roughness": 0.05}))
    print(f"## exact: single interfaces against the microfacet model, {n} grazing reflection "
          "pairs (theta 80-89.9 deg); relative L1 of f |cos theta_o| over all pairs and over "
          "those within 10 deg of the specular azimuth, relative L2 where the model > 5 % of its "
          "maximum; lowest value / the model's maximum")
    rng = np.random.default_rng(seed)
    wi, wo = grazing_pairs(rng, n)
    dphi = np.angle(np.exp(1j * (np.arctan2(wo[:, 1], wo[:, 0]) - np.arctan2(wi[:, 1], wi[:, 0])
                                 - np.pi)))
    near = np.abs(dphi) < np.radians(10.0)
    cos_o = np.abs(wo[:, 2])
    for label, layer in layers:
        scene = layersim.Scene.from_dict({"layer": [layer]})
        ref = exact_reflection(layer, wi, wo)
        peak = ref >= 0.05 * ref.max()
        rows = []
        for tag, taper, positive in (("sigma factors (before)", sigma_factors, False),
                                     ("sigma factors, positive part", sigma_factors, True),
                                     ("no taper, positive part", untapered, True),
                                     ("Jackson (library)", None, False),
                                     ("Jackson, positive part (eval)", None, True)):
            bsdf, _ = solve(scene, taper)
            f = bsdf.interpolant(wi, wo)
            f = np.maximum(f, 0.0) if positive else f
            l1 = lambda sel: np.sum(np.abs(f - ref)[sel] * cos_o[sel]) / np.sum(ref[sel] *
                                                                                cos_o[sel])
            l2 = np.linalg.norm((f - ref)[peak]) / np.linalg.norm(ref[peak])
            rows.append(f"    {tag:30s} L1 {l1(slice(None)):.3f}, near specular "
                        f"{l1(near):.3f}, L2 near the peak {l2:.3f}; min / model's max "
                        f"{f.min() / ref.max():+.2g}, max / model's max {f.max() / ref.max():.3f}")
        print(f"  {label} (n = {bsdf.plan.n}, md = {bsdf.plan.md}):")
        print("\n".join(rows), flush=True)


def header(argv: str) -> None:
    """The command, machine, date and commit of this output (``benchmarks/headline.py``)."""
    device = os.environ.get("LAYERSIM_DEVICE", "cpu")
    print(f"# python benchmarks/features/eval_positivity.py {argv}")
    print(f"# machine: {machine(device != 'cpu')}")
    print(f"# date: {datetime.date.today().isoformat()}; commit: {commit()}; "
          f"LAYERSIM_DEVICE={device}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=float, default=1e6)
    ap.add_argument("--grazing", type=float, default=2e5)
    ap.add_argument("--sections", default="sources,scenes,exact,walk")
    ap.add_argument("--source-scenes", default=",".join(SOURCE_SCENES))
    ap.add_argument("--walk-scenes", default=",".join(WALK_SCENES))
    ap.add_argument("--paths", type=float, default=1e7)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("scenes", nargs="*")
    args = ap.parse_args()
    header(" ".join(sys.argv[1:]))
    sections = args.sections.split(",")
    if "sources" in sections:
        section_sources(args.source_scenes.split(","), int(args.grazing), args.seed)
    if "scenes" in sections:
        section_scenes(args.scenes or DEFAULT_SCENES, int(args.pairs), int(args.grazing),
                       args.seed)
    if "exact" in sections:
        section_exact(int(args.grazing), args.seed)
    if "walk" in sections:
        section_walk(args.walk_scenes.split(","), int(args.paths), args.seed)


if __name__ == "__main__":
    main()
