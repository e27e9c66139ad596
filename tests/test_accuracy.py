"""Error estimates and solves to a tolerance (layersim.plan.accuracy) against refined solves."""

import numpy as np
import pytest

import layersim
from layersim.plan import accuracy

GLASS_ON_WHITE = {"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
                            {"kind": "diffuse", "albedo": 0.5}]}


def _measured(scene, bsdf, scale=2.0) -> float:
    """Worst-angle relative L2 error of ``bsdf``'s bin energies against a solve at ``scale``
    times its n and md."""
    ref = layersim.solve(accuracy.scaled(scene, bsdf.info["n"], bsdf.info["md"], scale))
    return float(accuracy.relative_errors(accuracy.bin_table(bsdf),
                                          accuracy.bin_table(ref)).max())


def test_solve_to_tolerance_meets_it_and_the_estimate_bounds_the_error():
    """tol = 1e-2 on rough glass over a Lambertian base: the ladder stops at the first rung
    whose estimate is below tol; the error against a solve at twice its n and md is below
    the estimate (which is conservative) and so below tol."""
    scene = layersim.Scene.from_dict(GLASS_ON_WHITE)
    bsdf = layersim.solve(scene, tol=1e-2)
    acc = bsdf.info["accuracy"]
    assert acc["met"] and bsdf.error_estimate == acc["estimate"] <= 1e-2
    assert len(acc["ladder"]) >= 3 and acc["ladder"][-1]["n"] == bsdf.info["n"]
    # every earlier rung's estimate was above tol (the ladder stops at the first that meets it)
    assert all(step["estimate"] > 1e-2 for step in acc["ladder"][2:-1])
    err = _measured(scene, bsdf)
    assert err <= bsdf.error_estimate, (err, bsdf.error_estimate)


def test_error_estimate_of_a_plain_solve(tmp_path):
    """error_estimate=True keeps the planner's discretisation and adds the estimate, which
    survives saving; a plain solve has none."""
    scene = layersim.Scene.from_dict({**GLASS_ON_WHITE, "discretization": {"n": 64, "md": 128}})
    plain = layersim.solve(scene)
    assert plain.error_estimate is None
    bsdf = layersim.solve(scene, error_estimate=True)
    assert bsdf.info["n"] == 64 and bsdf.info["md"] == 128
    assert bsdf.info["accuracy"]["companions"] == [{"n": 46, "md": 91}, {"n": 32, "md": 64}]
    assert 0 < bsdf.error_estimate < 0.1
    assert np.allclose(bsdf.albedo([0, 0, 1])[0], plain.albedo([0, 0, 1])[0], atol=1e-14)
    assert _measured(scene, bsdf) <= bsdf.error_estimate
    back = layersim.BSDF.load(bsdf.save(tmp_path / "g.lsim"))
    assert back.error_estimate == bsdf.error_estimate


def test_tolerance_input_is_checked():
    with pytest.raises(layersim.SceneError, match="discretization.tol"):
        layersim.Scene.from_dict({**GLASS_ON_WHITE, "discretization": {"tol": 1e-3, "n": 64}})
    with pytest.raises(layersim.SceneError, match="discretization.tol"):
        layersim.Scene.from_dict({**GLASS_ON_WHITE, "discretization": {"tol": 0}})
    with pytest.raises(layersim.SceneError, match="discretization.theta_full"):
        layersim.Scene.from_dict({**GLASS_ON_WHITE, "discretization": {"theta_full": 90}})
    with pytest.raises(ValueError, match="tol"):
        layersim.solve(GLASS_ON_WHITE, tol=1.5)
    with pytest.raises(ValueError, match="like"):
        like = layersim.solve({**GLASS_ON_WHITE, "discretization": {"n": 32, "md": 16}})
        layersim.solve(GLASS_ON_WHITE, like=like, error_estimate=True)


def test_unreachable_tolerance_is_refused_with_the_best_estimate():
    """A tolerance below what the ladder can reach within the limits ends in a refusal that
    names the best estimate and its discretisation."""
    scene = layersim.Scene.from_dict(GLASS_ON_WHITE)
    with layersim.config.configure(max_memory=24 * 2**20):
        with pytest.raises(layersim.InfeasibleError, match="not reached.*best estimate"):
            layersim.solve(scene, tol=1e-9)


def test_meeting_names_the_angles_within_tolerance():
    """The refusal of an unreachable tol says at which incidence angles the best estimate
    meets it, from the per-angle estimates."""
    acc = {"angles": [0.0, 30.0, 60.0, 80.0], "per_angle": [4e-4, 6e-4, 9e-4, 3e-3]}
    assert accuracy.meeting(acc, 1e-3) == "within tol at 0, 30, 60 deg; 0.003 at 80 deg"
    assert accuracy.meeting(acc, 1e-4) == "over tol at every angle"


def test_estimate_weights_an_accidental_agreement():
    """The estimate is SAFETY x d1 while the coarser companion agrees as convergence of up to
    fourth order explains (d2 <= 5 d1), SAFETY x d2 / 5 beyond, and SINGLE x SAFETY x d1 with
    one companion."""
    d1, d2 = np.array([1e-3, 1e-3]), np.array([3e-3, 1e-2])
    est = accuracy.estimate_from_distances([d1, d2])
    assert np.allclose(est, accuracy.SAFETY * np.array([1e-3, 2e-3]))
    assert np.allclose(accuracy.estimate_from_distances([d1]),
                       accuracy.SINGLE * accuracy.SAFETY * d1)


def _fresnel_conductor(c, eta, k):
    n2 = complex(eta, k) ** 2
    s = np.sqrt(n2 - (1.0 - c ** 2))
    rs = (c - s) / (c + s)
    rp = (n2 * c - s) / (n2 * c + s)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def _fresnel_dielectric(c, eta):
    ct = np.sqrt(1.0 - (1.0 - c ** 2) / eta ** 2)
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return 0.5 * (rs ** 2 + rp ** 2)


def _beckmann_reflection(wi, wo, fresnel, alpha):
    """Float64 reference of the reflection of a rough interface (Beckmann, isotropic; Walter
    et al. 2007 eq. 20 with the Smith G1 of eq. 27; ``fresnel(cos)`` the exact Fresnel term),
    written independently of kernels/physics.py: f = F(wi.h) D(h) G1(wi) G1(wo) /
    (4 cos_i cos_o)."""
    from scipy.special import erf
    h = wi + wo
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    ch = h[..., 2]
    tan2 = (1.0 - ch ** 2) / ch ** 2
    D = np.exp(-tan2 / alpha ** 2) / (np.pi * alpha ** 2 * ch ** 4)

    def g1(w):
        c = w[..., 2]
        a = c / (alpha * np.sqrt(1.0 - c ** 2))
        lam = (erf(a) - 1.0) / 2.0 + np.exp(-a * a) / (2.0 * a * np.sqrt(np.pi))
        return 1.0 / (1.0 + lam)

    F = fresnel(np.sum(wi * h, axis=-1))
    return F * D * g1(wi) * g1(wo) / (4.0 * wi[..., 2] * wo[..., 2])


GOLD = [0.143552, 3.98397]


@pytest.mark.slow
@pytest.mark.parametrize("layer, fresnel", [
    ({"kind": "conductor", "ior": GOLD, "roughness": 0.1},
     lambda c: _fresnel_conductor(c, *GOLD)),
    ({"kind": "dielectric", "ior": 1.5, "roughness": 0.1},
     lambda c: _fresnel_dielectric(c, 1.5))], ids=["gold", "glass"])
def test_grazing_peaks_are_kept_when_asked(layer, fresnel):
    """A rough interface (alpha 0.1; gold, and the reflection of glass) lit at 85 and 88
    degrees: BSDF values near the reflection peak (f > 5 % of its maximum) within 1e-2
    relative L2 of an independent float64 evaluation of the same microfacet model, with
    [discretization] theta_full = 89 and n = 400; the default plan tapers those orders (51-77 %
    off)."""
    scene = {"layer": [layer]}
    sharp = layersim.solve({**scene, "discretization": {"theta_full": 89, "n": 400}})
    default = layersim.solve(scene)
    for theta in (85.0, 88.0):
        t = np.radians(theta)
        wi = np.array([np.sin(t), 0.0, np.cos(t)])
        dth, dph = np.meshgrid(np.linspace(-0.15, 0.15, 7), np.linspace(-0.4, 0.4, 9))
        tt = np.minimum(t + dth.ravel(), np.radians(89.7))
        wo = np.stack([-np.sin(tt) * np.cos(dph.ravel()), -np.sin(tt) * np.sin(dph.ravel()),
                       np.cos(tt)], axis=1)
        wis = np.repeat(wi[None], wo.shape[0], 0)
        ref = _beckmann_reflection(wis, wo, fresnel, 0.1)
        sel = ref > 0.05 * ref.max()
        err = lambda f: np.linalg.norm(f[sel] - ref[sel]) / np.linalg.norm(ref[sel])
        assert err(sharp.eval(wis, wo)) < 1e-2, theta
        assert err(default.eval(wis, wo)) > 0.1, theta
