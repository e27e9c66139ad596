"""Shared fixtures: small, fast scenes and solved stacks reused across test modules, and the
OpenCL device (tests that need one skip where there is none)."""

import numpy as np
import pytest

import layersim


def unit(theta_deg, phi_deg=0.0, below=False):
    """Unit direction at polar angle theta (degrees from +z) and azimuth phi; ``below`` mirrors
    it to the lower hemisphere."""
    th, ph = np.radians(theta_deg), np.radians(phi_deg)
    v = np.stack(np.broadcast_arrays(np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph),
                                     np.cos(th)), axis=-1)
    if below:
        v = v * np.array([1.0, 1.0, -1.0])
    return v


def random_directions(rng, n, lower=False, min_z=0.05):
    """Random unit vectors on the upper (or lower) hemisphere with |z| >= min_z."""
    z = rng.uniform(min_z, 1.0, n)
    ph = rng.uniform(0, 2 * np.pi, n)
    s = np.sqrt(1 - z * z)
    v = np.stack([s * np.cos(ph), s * np.sin(ph), -z if lower else z], axis=-1)
    return v


@pytest.fixture(scope="session")
def coated_gold():
    """Rough lacquer (eta 1.5, alpha 0.1) over rough gold (alpha 0.1) at the planner's
    discretisation (n = 196)."""
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.1},
        {"kind": "conductor", "ior": [0.143552, 3.98397], "roughness": 0.1}]})
    return layersim.solve(scene)


@pytest.fixture(scope="session")
def rough_glass():
    """A single rough dielectric interface (eta 1.5, alpha 0.3): all four blocks."""
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.3}]})
    return layersim.solve(scene)


@pytest.fixture(scope="session")
def cl_device():
    """The OpenCL device the walk runs on; the tests that need it skip, with the driver's reason,
    only where no device can build (layersim.montecarlo.opencl_device)."""
    from layersim.montecarlo import BackendUnavailableError
    from layersim.montecarlo.opencl_device import opencl_device
    try:
        return opencl_device()
    except BackendUnavailableError as exc:
        pytest.skip(str(exc))


def solved_vs_walk(bsdf, scene, thetas, seed, paths=1_000_000):
    """``(theta, albedo difference, max(4 se, 1e-3), z-scores of the populated 10 x 12 top
    bins)`` of ``bsdf`` against walks of ``scene`` (warp-cpu, ``paths`` each, seeds ``seed``,
    ``seed + 1``, ...) at incidences ``thetas`` (degrees, azimuth 0.35 rad)."""
    import layersim.montecarlo as mc
    mu, phi = np.linspace(0, 1, 11), np.linspace(0, 2 * np.pi, 13)
    out = []
    for k, theta in enumerate(thetas):
        t = np.radians(theta)
        wi = np.array([np.sin(t) * np.cos(0.35), np.sin(t) * np.sin(0.35), np.cos(t)])
        res = mc.simulate(scene, wi, paths, mu_edges=mu, phi_edges=phi, backend="warp-cpu",
                          seed=seed + k)
        d = float(bsdf.albedo(wi)[0]) - res.reflectance
        z = res.z_scores("top", bsdf.bin_energies(wi, mu, phi)["top"])
        out.append((theta, d, max(4 * res.reflectance_stderr, 1e-3), z))
    return out
