"""Checking a design: per target lobe, the target, what Belcour's statistical model gives and
what exact transport gives, and the statistical BSDF's error against the exact solve.

Exact lobes follow Bati et al. 2021's definition of a lobe (sec. 6.1: ``R_k = R_{0,n+l} -
R_{0,n}``, the light that reaches the lobe's interfaces) with exact transport: the stack is cut
below the last interface of each lobe (the medium under it extends to infinity) and solved
with :func:`layersim.solve`; lobe ``k`` is the difference of the reflected distributions of
the cuts ``k`` and ``k - 1`` at normal incidence. Its energy is that difference's total, its
width the GGX roughness whose normalised lobe fits the difference best (least squares over
1-degree rings of the outgoing elevation).
"""

from __future__ import annotations

import math
import time

import numpy as np

from .lobes import StatisticalBSDF


def direction(theta_deg: float) -> np.ndarray:
    t = math.radians(theta_deg)
    return np.array([math.sin(t), 0.0, math.cos(t)])


def group_lobes(model: StatisticalBSDF, groups, theta_deg: float = 0.0):
    """Per target lobe (``groups``: interface indices), the model's energy (per channel) and
    roughness (of the energy-weighted variance, per channel)."""
    from .variance import roughness
    by_layer = {l.layer: l for l in model.lobes(math.radians(theta_deg))}
    out = []
    for g in groups:
        ls = [by_layer[i] for i in g if i in by_layer]
        e = np.sum([l.energy for l in ls], axis=0)
        v = np.sum([l.energy * l.variance for l in ls], axis=0) / np.maximum(e, 1e-300)
        out.append((e, np.array([roughness(x) for x in np.atleast_1d(v)])))
    return out


#: Rings of the outgoing elevation (1 degree) in which exact lobes are compared at normal
#: incidence (increasing cos theta edges).
RING_EDGES = np.cos(np.radians(np.arange(90.0, -0.5, -1.0)))


def cut(design, k: int):
    """The scene of ``design`` down to the last interface of lobe ``k`` (0-based), on the
    design's ``[discretization]`` where it has one."""
    from ..scene import Scene
    last = max(design.groups[k])
    data = {**design.data, "layer": design.data["layer"][:last + 1]}
    return Scene.from_dict(data)


def fit_roughness(rings: np.ndarray) -> float:
    """GGX roughness whose unit lobe at normal incidence best fits the ring energies
    ``rings`` (shape (len(RING_EDGES) - 1,), any scale): least squares on the normalised
    distributions, over alpha in [0.005, 1)."""
    from scipy.optimize import minimize_scalar
    from .lobes import lobe_bins
    target = rings / rings.sum()
    wi = np.array([0.0, 0.0, 1.0])
    edges = np.array([0.0, 2.0 * np.pi])
    cost = lambda la: float(np.sum((lobe_bins(wi, math.exp(la), RING_EDGES, edges,
                                              nodes=8)[:, 0] - target) ** 2))
    res = minimize_scalar(cost, bounds=(math.log(0.005), math.log(0.999)), method="bounded",
                          options={"xatol": 1e-4})
    return math.exp(res.x)


def exact_ring_energies(design, solve) -> list:
    """Per target lobe, the energy of exact transport's lobe in each 1-degree ring of
    :data:`RING_EDGES` at normal incidence, shape (rings, channels): the difference of the
    reflected rings of the cut stacks (see the module docstring)."""
    wi = np.array([0.0, 0.0, 1.0])
    edges = np.array([0.0, 2.0 * np.pi])
    previous, out = 0.0, []
    for k in range(len(design.groups)):
        rings = np.asarray(solve(cut(design, k)).bin_energies(wi, RING_EDGES, edges)["top"])
        rings = rings.reshape(rings.shape[0], -1)      # (rings, channels)
        # a cut above the coloured layers has one channel: shared by all
        rings = np.broadcast_to(rings, (rings.shape[0], design.scene.channels))
        out.append(rings - previous)
        previous = rings
    return out


def exact_lobes(design, solve) -> list:
    """Per target lobe: ``(energy per channel, fitted roughness per channel)`` of exact
    transport at normal incidence (see the module docstring)."""
    out = []
    for diff in exact_ring_energies(design, solve):
        energy = diff.sum(axis=0)
        alpha = np.array([fit_roughness(diff[:, c]) if energy[c] > 0 else math.nan
                          for c in range(diff.shape[1])])
        out.append((energy, alpha))
    return out


def relative_l2(a, ref) -> float:
    """``||a - ref|| / ||ref||`` over all bins and channels."""
    den = float(np.sum(np.asarray(ref) ** 2))
    return float(np.sqrt(np.sum((np.asarray(a) - ref) ** 2) / den)) if den > 0 else math.nan


def bsdf_errors(model, exact, angles=(0.0, 30.0, 60.0), n_mu=18, n_phi=36) -> dict:
    """Relative L2 error over the top bins (``n_mu`` x ``n_phi`` in cos theta and phi) of the
    statistical BSDF against the exact one, per incidence angle (degrees), and the albedos."""
    mu_edges = np.linspace(0.0, 1.0, n_mu + 1)
    phi_edges = np.linspace(0.0, 2.0 * np.pi, n_phi + 1)
    out = {}
    for theta in angles:
        wi = direction(max(theta, 1e-3))
        a = model.bin_energies(wi, mu_edges, phi_edges)["top"]
        b = exact.bin_energies(wi, mu_edges, phi_edges)["top"]
        out[theta] = {"l2": relative_l2(a, b), "R_model": np.atleast_1d(model.albedo(wi)[0]),
                      "R_exact": np.atleast_1d(exact.albedo(wi)[0])}
    return out


def verify(design, angles=(0.0, 30.0, 60.0), solve=None) -> dict:
    """Solve ``design.scene`` exactly (:func:`layersim.solve`) and compare it with the model.

    Returns
    -------
    dict with ``lobes`` (per target lobe: model energy and roughness at normal incidence),
    ``exact_lobes`` (the same from exact transport, :func:`exact_lobes`),
    ``errors`` (:func:`bsdf_errors`), ``exact_R0`` (the exact albedo at normal incidence),
    ``model_seconds`` and ``exact_seconds`` (wall-clock, the model's including its lobe
    integration into bins at one angle).
    """
    from ..solver import solve as exact_solve
    solve = _memo(solve or exact_solve)
    t0 = time.perf_counter()
    model = StatisticalBSDF(design.scene)
    lobes = group_lobes(model, design.groups)
    model.bin_energies(direction(30.0), np.linspace(0, 1, 19), np.linspace(0, 2 * np.pi, 37))
    t_model = time.perf_counter() - t0
    t0 = time.perf_counter()
    exact = solve(design.scene)
    t_exact = time.perf_counter() - t0
    errors = bsdf_errors(model, exact, angles)
    # a Monte Carlo reference simulates when asked for bins: count the walks of its 3 angles
    t_exact += getattr(exact, "seconds", 0.0)
    return {"lobes": lobes, "exact_lobes": exact_lobes(design, solve), "errors": errors,
            "exact_R0": np.atleast_1d(exact.albedo(direction(1e-3))[0]),
            "model_seconds": t_model, "exact_seconds": t_exact, "exact": exact, "model": model,
            "exact_solve": solve}


def _memo(solve):
    """``solve`` remembering its results per scene (the cut stacks repeat the full one)."""
    cache = {}

    def run(scene):
        key = repr(scene.stacks)
        if key not in cache:
            cache[key] = solve(scene)
        return cache[key]
    return run


class MonteCarloReference:
    """The Monte Carlo reference (:func:`layersim.montecarlo.simulate`) of a scene behind the
    two methods :func:`verify` reads (``bin_energies``, ``albedo``), for stacks the Fourier
    solver refuses (near-specular interfaces inside a stack need more memory than it may
    plan). Each call simulates ``paths`` particles; ``seconds`` adds up the walks' time."""

    def __init__(self, scene, paths: int, backend: str = "warp-cpu", seed: int = 0):
        self.scene, self.paths, self.backend, self.seed = scene, int(paths), backend, seed
        self.seconds = 0.0

    def _run(self, wi, mu_edges, phi_edges):
        from ..montecarlo import simulate
        t0 = time.perf_counter()
        self.seed += 1
        res = simulate(self.scene, wi, self.paths, mu_edges=mu_edges, phi_edges=phi_edges,
                       backend=self.backend, seed=self.seed)
        self.seconds += time.perf_counter() - t0
        return res

    def bin_energies(self, wi, mu_edges, phi_edges) -> dict:
        return dict(self._run(wi, mu_edges, phi_edges).bins)

    def albedo(self, wi):
        res = self._run(wi, (0.0, 1.0), (0.0, 2.0 * np.pi))
        return res.reflectance, res.transmittance


def montecarlo_solve(paths: int, backend: str = "warp-cpu", seed: int = 0):
    """A ``solve`` for :func:`verify` that returns :class:`MonteCarloReference` objects."""
    return lambda scene: MonteCarloReference(scene, paths, backend, seed)
