"""Monte Carlo walk against closed forms, tables and direct integrals of the physics (warp-cpu).

Statistical checks allow 4 standard errors (plus float32 rounding where an estimate has no
variance); the seeds are fixed, so every run is deterministic.
"""

import math

import numpy as np
import pytest

import layersim
import layersim.montecarlo as mc
from layersim.kernels import physics

from probes import ProbeSet

BACKEND = "warp-cpu"
F32 = 1e-6          # float32 rounding of weights (estimates without variance)


def scene(*layers, **stack):
    d = {"layer": list(layers)}
    if stack:
        d["stack"] = stack
    return layersim.Scene.from_dict(d)


def direction(theta_deg, phi_deg=0.0, below=False):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p),
                     -math.cos(t) if below else math.cos(t)])


def fresnel(c, eta):
    s2 = (1 - c * c) / eta ** 2
    if s2 >= 1:
        return 1.0
    ct = math.sqrt(1 - s2)
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return 0.5 * (rs * rs + rp * rp)


def within(x, want, err, k=4.0):
    return abs(x - want) <= k * err + F32


# ------------------------------------------------------------------------------------------------


def test_lambertian_base_reflectance_and_cosine_law():
    albedo = 0.63
    mu_edges = np.linspace(0, 1, 6)
    phi_edges = np.linspace(0, 2 * np.pi, 5)
    res = mc.simulate(scene({"kind": "diffuse", "albedo": albedo}), direction(35, 20), 200_000,
                      mu_edges=mu_edges, phi_edges=phi_edges, backend=BACKEND, seed=1)
    assert within(res.reflectance, albedo, res.reflectance_stderr)
    assert res.transmittance == 0 and res.bins["bottom"].sum() == 0
    assert within(res.absorbed, 1 - albedo, res.absorbed_stderr)
    want = albedo * np.outer(np.diff(mu_edges ** 2), np.diff(phi_edges) / (2 * np.pi))
    err = res.bins_stderr["top"]
    assert np.all(err > 0)
    assert np.all(np.abs(res.bins["top"] - want) <= 4 * err), (res.bins["top"] - want) / err
    assert abs(res.bins["top"].sum() - res.reflectance) < 1e-12      # bins cover everything


@pytest.mark.parametrize("theta, eta, below", [(0, 1.5, False), (53, 1.5, False),
                                                (80, 1.33, False), (30, 1.5, True),
                                                (50, 1.5, True)])
def test_smooth_dielectric_is_fresnel(theta, eta, below):
    wi = direction(theta, 40, below=below)
    res = mc.simulate(scene({"kind": "dielectric", "ior": eta}), wi, 200_000, backend=BACKEND,
                      seed=2)
    rel = 1 / eta if below else eta                      # index across, seen from wi's side
    F = fresnel(abs(wi[2]), rel)
    assert within(res.reflectance, F, res.reflectance_stderr)
    assert within(res.transmittance, 1 - F, res.transmittance_stderr)
    assert res.absorbed == 0.0 and res.absorbed_stderr == 0.0
    if F == 1.0:                                         # total internal reflection
        assert res.reflectance == 1.0 and res.reflectance_stderr == 0.0


def test_smooth_refraction_direction_lands_in_the_snell_bin():
    eta, theta = 1.5, 60
    st = math.sin(math.radians(theta)) / eta
    mu_t = math.sqrt(1 - st * st)
    mu_edges = np.sort(np.array([0.0, mu_t - 1e-3, mu_t + 1e-3, 1.0]))
    phi_edges = np.array([0, np.pi - 0.01, np.pi + 0.01, 2 * np.pi])
    res = mc.simulate(scene({"kind": "dielectric", "ior": eta}), direction(theta), 50_000,
                      mu_edges=mu_edges, phi_edges=phi_edges, backend=BACKEND)
    # refracted light propagates away from the source: phi_o = pi for wi at phi = 0
    assert res.bins["bottom"][1, 1] == pytest.approx(res.transmittance, abs=1e-12)
    # the specular reflection leaves at mu = cos(theta), phi_o = pi
    ref_bin = np.searchsorted(mu_edges, math.cos(math.radians(theta))) - 1
    assert res.bins["top"][ref_bin, 1] == pytest.approx(res.reflectance, abs=1e-12)


def test_smooth_coating_over_lambertian_closed_form():
    """Smooth dielectric over a Lambertian base: R = F + (1-F) rho (1-Fi) / (1 - rho Fi), Fi the
    internal diffuse (cosine-weighted) Fresnel reflectance."""
    eta, rho, theta = 1.5, 0.5, 40
    res = mc.simulate(scene({"kind": "dielectric", "ior": eta},
                            {"kind": "diffuse", "albedo": rho}), direction(theta), 300_000,
                      backend=BACKEND, seed=3)
    x, w = np.polynomial.legendre.leggauss(400)
    mu = 0.5 * (x + 1)
    Fi = sum(0.5 * wk * 2 * m * fresnel(m, 1 / eta) for m, wk in zip(mu, w))
    # TIR makes the integrand kink at the critical cosine; refine with adaptive quadrature
    from scipy.integrate import quad
    Fi = quad(lambda m: 2 * m * fresnel(m, 1 / eta), 0, 1, points=[math.sqrt(1 - 1 / eta ** 2)],
              epsabs=1e-13)[0]
    F = fresnel(math.cos(math.radians(theta)), eta)
    want = F + (1 - F) * rho * (1 - Fi) / (1 - rho * Fi)
    assert within(res.reflectance, want, res.reflectance_stderr)


def test_index_matched_slab_van_de_hulst():
    """Isotropic slab, albedo 0.9, tau 2, mu_i = 0.9: reflected flux 0.38040 (van de Hulst 1980,
    Vol. 1, Table 12)."""
    res = mc.simulate(scene({"kind": "medium", "albedo": 0.9, "g": 0.0, "tau": 2.0}),
                      direction(math.degrees(math.acos(0.9))), 400_000, backend=BACKEND,
                      seed=4)
    assert within(res.reflectance, 0.38040, res.reflectance_stderr)
    assert res.reflectance_stderr < 8e-4


def hg_slab_reference(albedo, g, tau, n=48, nphi=256, k=26):
    """Independent reference for an index-matched HG slab: azimuth-averaged discrete ordinates
    (Gauss-Legendre, ``n`` per hemisphere) and doubling from a first-order thin layer of
    thickness tau / 2^k. Returns the nodes mu and the directional R(mu), T(mu)."""
    x, w = np.polynomial.legendre.leggauss(n)
    mu, w = 0.5 * (x + 1), 0.5 * w
    phi = (np.arange(nphi) + 0.5) * 2 * np.pi / nphi

    def p0(m_out, m_in):                    # azimuth average of HG between propagation cosines
        s = np.sqrt(1 - m_out[:, None, None] ** 2) * np.sqrt(1 - m_in[None, :, None] ** 2)
        c = m_out[:, None, None] * m_in[None, :, None] + s * np.cos(phi)
        return ((1 - g * g) / (4 * np.pi * (1 + g * g - 2 * g * c) ** 1.5)).mean(axis=2)

    same = 2 * np.pi * w[:, None] * p0(mu, mu)          # down -> down, probability per node
    opp = 2 * np.pi * w[:, None] * p0(-mu, mu)          # down -> up
    norm = same.sum(0) + opp.sum(0)
    same, opp = same / norm, opp / norm
    t0 = tau / 2 ** k
    R = (t0 / mu)[None, :] * albedo * opp
    T = np.diag(1 - t0 / mu) + (t0 / mu)[None, :] * albedo * same
    eye = np.eye(n)
    for _ in range(k):
        X = np.linalg.solve((eye - R @ R).T, T.T).T    # T (I - R R)^-1
        R, T = R + X @ R @ T, X @ T
    return mu, R.sum(axis=0), T.sum(axis=0)


def test_hg_slab_reference_reproduces_van_de_hulst():
    mu, R, _ = hg_slab_reference(0.9, 0.0, 2.0)
    assert abs(np.interp(0.9, mu, R) - 0.38040) < 2e-5


@pytest.mark.parametrize("albedo, g, tau, mu_i", [(0.95, 0.5, 2.0, 0.6), (0.8, -0.5, 1.0, 0.35),
                                                   (0.99, 0.85, 3.0, 0.8)])
def test_hg_slab_matches_adding_doubling(albedo, g, tau, mu_i):
    mu, R, T = hg_slab_reference(albedo, g, tau)
    j = int(np.argmin(np.abs(mu - mu_i)))
    wi = direction(math.degrees(math.acos(mu[j])), 70)
    res = mc.simulate(scene({"kind": "medium", "albedo": albedo, "g": g, "tau": tau}), wi,
                      200_000, backend=BACKEND, seed=9)
    assert within(res.reflectance, R[j], res.reflectance_stderr)
    assert within(res.transmittance, T[j], res.transmittance_stderr)
    # lit from below, the slab is the same by symmetry
    res_b = mc.simulate(scene({"kind": "medium", "albedo": albedo, "g": g, "tau": tau}),
                        wi * np.array([1, 1, -1]), 200_000, backend=BACKEND, seed=10)
    assert within(res_b.reflectance, R[j], res_b.reflectance_stderr)


def test_clear_slab_transmits_everything_straight():
    res = mc.simulate(scene({"kind": "medium", "albedo": 0.3, "tau": 0.0}), direction(30, 10),
                      1000, backend=BACKEND)
    assert res.transmittance == 1.0 and res.reflectance == 0.0 and res.events == 0


def test_slab_unscattered_transmission_is_beer_lambert():
    """Albedo-0 slab: T = exp(-tau / mu) exactly in expectation (binomial error)."""
    tau, mu = 0.7, 0.6
    res = mc.simulate(scene({"kind": "medium", "albedo": 0.0, "tau": tau}),
                      direction(math.degrees(math.acos(mu))), 200_000, backend=BACKEND)
    assert within(res.transmittance, math.exp(-tau / mu), res.transmittance_stderr)
    assert res.reflectance == 0.0


def test_conservation_with_smooth_interfaces_and_white_media():
    s = scene({"kind": "dielectric", "ior": 1.5},
              {"kind": "medium", "albedo": 1.0, "g": 0.6, "tau": 1.0},
              {"kind": "dielectric", "ior": 1.2},
              {"kind": "dielectric", "ior": 1.0},
              {"kind": "medium", "albedo": 1.0, "g": -0.3, "tau": 0.5},
              {"kind": "medium", "albedo": 1.0, "tau": 0.2}, top_ior=1.1)
    for wi in (direction(20, 30), direction(70, 200, below=True)):
        res = mc.simulate(s, wi, 50_000, backend=BACKEND, seed=5)
        assert res.absorbed == 0.0 and res.absorbed_stderr == 0.0 and res.truncated == 0
        assert res.reflectance + res.transmittance == pytest.approx(1.0, abs=1e-12)
        assert 0.05 < res.reflectance < 0.95


# ------------------------------------------------------------------------------------------------
# Rough interfaces against quadrature of physics.microfacet_eval
# ------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def eval_probe(tmp_path_factory):
    ps = ProbeSet([(physics.microfacet_eval,
                    ["double3", "double3", "double", "double", "double", "double", "int"])],
                  tmp_path_factory.mktemp("mceval"), name="layersim_test_mc_eval")
    return lambda wi, wo, eta, k, au, av, dist: ps.warp(
        0, np.broadcast_to(wi, wo.shape), wo, *[np.full(len(wo), v) for v in
                                                (eta, k, au, av, dist)])[0]


def bin_integrals(f, wi, rot, mu_edges, phi_edges, side, n=20):
    """E_b = integral over bin b of f(wi, wo) |wo.z| dwo, Gauss-Legendre n x n per bin, with the
    directions rotated into the interface frame (rotation ``rot``)."""
    x, w = np.polynomial.legendre.leggauss(n)
    c, s = math.cos(rot), math.sin(rot)
    to_frame = lambda v: np.stack([c * v[..., 0] + s * v[..., 1], c * v[..., 1] - s * v[..., 0],
                                   v[..., 2]], axis=-1)
    out = np.zeros((len(mu_edges) - 1, len(phi_edges) - 1))
    for a in range(out.shape[0]):
        m0, m1 = mu_edges[a], mu_edges[a + 1]
        mu = 0.5 * (m1 - m0) * x + 0.5 * (m1 + m0)
        for b in range(out.shape[1]):
            p0, p1 = phi_edges[b], phi_edges[b + 1]
            ph = 0.5 * (p1 - p0) * x + 0.5 * (p1 + p0)
            M, P = np.meshgrid(mu, ph, indexing="ij")
            st = np.sqrt(1 - M * M)
            wo = np.stack([st * np.cos(P), st * np.sin(P), M if side == "top" else -M], axis=-1)
            vals = f(to_frame(wi), to_frame(wo.reshape(-1, 3))).reshape(M.shape)
            out[a, b] = np.sum(np.outer(w, w) * vals * M) * 0.25 * (m1 - m0) * (p1 - p0)
    return out


ROUGH_CASES = [
    # id, layer, wi (theta, phi, below), mu edges (bins), phi bins
    ("beckmann dielectric", {"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
     (40, 0, False)),
    ("ggx dielectric from below", {"kind": "dielectric", "ior": 1.5, "roughness": 0.25,
                                   "distribution": "ggx"}, (25, 30, True)),
    ("anisotropic rotated dielectric", {"kind": "dielectric", "ior": 1.33,
                                        "roughness": [0.15, 0.45], "rotation": 30.0},
     (55, 60, False)),
    ("anisotropic rotated ggx conductor", {"kind": "conductor", "ior": [0.143552, 3.98397],
                                           "roughness": [0.4, 0.12], "rotation": -50.0,
                                           "distribution": "ggx"}, (60, 100, False)),
    ("beckmann conductor", {"kind": "conductor", "ior": [1.2, 2.5], "roughness": 0.2},
     (70, 0, False)),
]


@pytest.mark.parametrize("layer, wi_spec", [c[1:] for c in ROUGH_CASES],
                         ids=[c[0] for c in ROUGH_CASES])
def test_rough_interface_matches_quadrature_of_eval(eval_probe, layer, wi_spec):
    s = scene(layer, top_ior=1.0)
    wi = direction(*wi_spec)
    lay = s.layers[0]
    eta = s.relative_ior(0)
    k = eta.imag if lay.kind == "conductor" else 0.0
    dist = physics.DISTRIBUTION_CODES[lay.distribution]
    f = lambda a, b: eval_probe(a, b, eta.real, k, lay.alpha_u, lay.alpha_v, dist)
    mu_edges = np.array([0.0, 0.3, 0.55, 0.75, 0.9, 1.0])
    phi_edges = np.linspace(0, 2 * np.pi, 9)
    res = mc.simulate(s, wi, 300_000, mu_edges=mu_edges, phi_edges=phi_edges, backend=BACKEND,
                      seed=6)
    incident = "bottom" if wi[2] < 0 else "top"
    for side in ("top", "bottom"):
        want = bin_integrals(f, wi, lay.rotation, mu_edges, phi_edges, side)
        got, err = res.bins[side], res.bins_stderr[side]
        assert np.all(np.abs(got - want) <= 4 * err + 2e-5), (side, (got - want) / (err + 1e-9))
        total = res.reflectance if side == incident else res.transmittance
        total_err = (res.reflectance_stderr if side == incident else
                     res.transmittance_stderr)
        assert within(total, want.sum(), total_err)
    # the model loses energy (single scattering) but never creates it
    assert res.absorbed > 0 and res.reflectance + res.transmittance < 1


def test_rough_interface_generalized_reciprocity():
    """Radiance-convention reciprocity f(wi, wo) / eta_o^2 = f(wo, wi) / eta_i^2 implies that the
    diffuse (cosine-weighted hemispherical) transmittance from inside is 1/eta^2 times the one
    from outside. Directional transmittances T(mu) from both sides, integrated with a 6-point
    Gauss-Legendre rule in mu (1 % quadrature allowance for the rough lobes)."""
    eta = 1.4
    s = scene({"kind": "dielectric", "ior": eta, "roughness": 0.35})
    x, w = np.polynomial.legendre.leggauss(6)
    mus = 0.5 * (x + 1)
    tt = [mc.simulate(s, direction(math.degrees(math.acos(m))), 40_000, backend=BACKEND,
                      seed=7) for m in mus]
    tb = [mc.simulate(s, direction(math.degrees(math.acos(m)), below=True), 40_000,
                      backend=BACKEND, seed=8) for m in mus]
    # hemispherical-hemispherical transmittance: t = integral T(mu) 2 mu dmu
    t_top = sum(0.5 * wk * 2 * m * r.transmittance for m, wk, r in zip(mus, w, tt))
    t_bot = sum(0.5 * wk * 2 * m * r.transmittance for m, wk, r in zip(mus, w, tb))
    e_top = math.sqrt(sum((0.5 * wk * 2 * m * r.transmittance_stderr) ** 2
                          for m, wk, r in zip(mus, w, tt)))
    e_bot = math.sqrt(sum((0.5 * wk * 2 * m * r.transmittance_stderr) ** 2
                          for m, wk, r in zip(mus, w, tb)))
    # reciprocity: the diffuse transmittance from inside is (1/eta^2) of that from outside.
    # The 6-point quadrature in mu is not exact for the rough lobes; allow 1 % plus noise.
    assert abs(t_bot * eta ** 2 - t_top) <= 4 * math.hypot(e_top, eta ** 2 * e_bot) + 0.01 * t_top


@pytest.mark.slow
@pytest.mark.parametrize("theta_deg", [0.3, 0.5])
def test_rough_conductor_sampling_near_normal_incidence(theta_deg):
    """A smooth coating over rough gold (alpha 0.2) lit within a degree of the normal: the
    Beckmann visible-normal sampling sees a stretched incident direction a few 1e-3 rad from
    the normal, where a sine taken as sqrt(1 - cos^2) in float32 distorted the sampled normals
    and the walk's albedo fell 24 standard errors below the solver's (exact here: smooth coat,
    rough base projected on the Snell-matched grid)."""
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.0},
        {"kind": "conductor", "ior": [0.143552, 3.98397], "roughness": 0.2}]})
    t, p = math.radians(theta_deg), math.radians(20.0)
    wi = np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])
    res = mc.simulate(scene, wi, 2_000_000, backend="warp-cpu", seed=11)
    R = float(layersim.solve(scene).albedo(wi)[0])
    assert abs(R - res.reflectance) < 4 * res.reflectance_stderr, (R, res.reflectance)
