"""Belcour's statistical model (Belcour 2018, as used by Bati et al. 2021): the FGD table
against a direct quadrature of the solver's microfacet BSDF, the energy adding against the
Stokes adding equation (Bati et al. 2021 eq. 2), the variance adding against eq. 5-6, and the
model's BSDF against its own lobes and against the exact solve where the model is exact (one
interface)."""

import math

import numpy as np
import pytest
import warp as wp

import layersim
from layersim.kernels import physics
from layersim.kernels.runtime import device_for
from layersim.statistical import StatisticalBSDF, fgd, lobes
from layersim.statistical.atomic import Absorber, Interface
from layersim.statistical.forward import add_stack
from layersim.statistical.stack import UnsupportedStack
from layersim.statistical.variance import roughness, variance


@wp.kernel
def _bsdf(wi: wp.vec3d, wo: wp.array(dtype=wp.vec3d), eta: wp.float64, k: wp.float64,
          a: wp.float64, out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    out[i] = physics.microfacet_eval(wi, wo[i], eta, k, a, a, physics.GGX)


def direct_fgd(mu, alpha, eta, k=0.0, n=600, m=300):
    """Directional albedo by Gauss-Legendre quadrature over the outgoing hemisphere (theta_o,
    phi_o), independent of the half-vector parametrisation of the table's kernel."""
    x, w = np.polynomial.legendre.leggauss(n)
    th, wt = (x + 1) * np.pi / 4, w * np.pi / 4
    y, v = np.polynomial.legendre.leggauss(m)
    ph, vp = (y + 1) * np.pi / 2, v * np.pi / 2
    T, P = np.meshgrid(th, ph, indexing="ij")
    wo = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    dev = device_for("cpu")
    out = wp.zeros(wo.shape[0], dtype=wp.float64, device=dev)
    wp.launch(_bsdf, dim=wo.shape[0], inputs=[wp.vec3d(math.sqrt(1 - mu * mu), 0.0, mu),
                                               wp.array(wo, dtype=wp.vec3d, device=dev),
                                               eta, k, alpha, out], device=dev)
    f = out.numpy().reshape(T.shape)
    return 2.0 * np.sum(f * np.cos(T) * np.sin(T) * wt[:, None] * vp[None, :])


# table nodes (mu index, alpha index, log-eta index): eta > 1 and eta < 1 (total internal
# reflection) at normal and oblique incidence, moderate to large roughness; two in the fast set
NODES = [(31, 16, 60), (20, 28, 10)] + [pytest.param(*n, marks=pytest.mark.slow) for n in
                                        [(31, 8, 48), (15, 12, 40), (15, 24, 20), (8, 20, 44),
                                         (31, 10, 16)]]


@pytest.mark.parametrize("i,j,l", NODES)
def test_fgd_table_agrees_with_direct_quadrature(i, j, l):
    mu, alpha, eta = fgd.MU[i], fgd.ALPHA[j], math.exp(fgd.LOG_ETA[l])
    assert fgd.table()[i, j, l] == pytest.approx(direct_fgd(mu, alpha, eta), abs=1e-4)


def test_fgd_of_a_smooth_interface_is_fresnel_and_eta_one_reflects_nothing():
    for l in (0, 20, 40, 64):
        eta = math.exp(fgd.LOG_ETA[l])
        r0 = ((eta - 1) / (eta + 1)) ** 2
        assert fgd.table()[-1, 0, l] == pytest.approx(r0, abs=1e-12)
    assert np.all(np.abs(fgd.table()[:, :, 32]) < 1e-12)


@pytest.mark.slow
def test_conductor_fgd_agrees_with_direct_quadrature():
    assert fgd.conductor(0.8, 0.3, 0.2, 3.0) == pytest.approx(
        direct_fgd(0.8, 0.3, 0.2, 3.0), abs=1e-4)


def test_fgd_refuses_values_outside_the_table():
    with pytest.raises(ValueError, match="relative index"):
        fgd.dielectric(1.0, 0.1, 5.0)
    with pytest.raises(ValueError, match="roughness"):
        fgd.dielectric(1.0, 1.5, 1.5)


def test_roughness_variance_mapping_is_belcours_and_inverts():
    assert variance(0.5) == pytest.approx(0.5 ** 1.1 / (1 - 0.5 ** 1.1))
    for a in (0.0, 0.01, 0.3, 0.9):
        assert roughness(variance(a)) == pytest.approx(a, abs=1e-12)


def stokes(r01, r12, t1):
    """Bati et al. 2021 eq. 2 with R01 = R10, T = 1 - R and R'12 = exp(-2 tau / cos) R12."""
    rp = math.exp(-2.0 * t1) * r12
    return r01 + (1 - r01) ** 2 * rp / (1 - rp * r01)


def test_smooth_energies_follow_the_stokes_adding_equation():
    # eta1 = sqrt(2), eta2 = 2: table nodes, so the FGD is Fresnel to rounding
    e1, e2, tau = math.sqrt(2.0), 2.0, 0.3
    st = add_stack([Interface(e1, 0.0), Absorber(tau), Interface(e2, 0.0)], 1.0)
    r01 = ((e1 - 1) / (e1 + 1)) ** 2
    r12 = ((e2 - e1) / (e2 + e1)) ** 2
    assert st.lobes[0][0] == pytest.approx(r01, abs=1e-12)
    assert st.R0i == pytest.approx(stokes(r01, r12, tau), abs=1e-12)
    assert st.lobes[1][0] == pytest.approx(stokes(r01, r12, tau) - r01, abs=1e-12)
    # transmitted: T02 = T01 e^-tau T12 / (1 - R'12 R10)
    t02 = (1 - r01) * math.exp(-tau) * (1 - r12) / (1 - math.exp(-2 * tau) * r12 * r01)
    assert st.T0i == pytest.approx(t02, abs=1e-12)


def test_variances_of_two_rough_interfaces_follow_eq_5_and_6():
    e1, e2, a1, a2, tau = math.sqrt(2.0), 2.0, 0.25, 0.375, 0.2
    st = add_stack([Interface(e1, a1), Absorber(tau), Interface(e2, a2)], 1.0)
    f = variance
    s_t01, s_t10 = f(0.5 * (1 - 1 / e1) * a1), f(0.5 * abs(1 - e1) * a1)
    r01 = float(fgd.dielectric(1.0, a1, e1))
    r12 = float(fgd.dielectric(1.0, roughness(f(a2) + s_t01), e2 / e1))
    rp = math.exp(-2 * tau) * r12
    sigma02 = s_t10 + e1 * (s_t01 + (f(a2) + rp * r01 * f(a1)) / (1 - rp * r01))
    assert st.lobes[0][1] == pytest.approx(f(a1), rel=1e-12)
    assert st.lobes[1][1] == pytest.approx(sigma02, rel=1e-12)
    assert st.lobes[1][0] == pytest.approx((1 - r01) ** 2 * rp / (1 - rp * r01), rel=1e-12)


def test_a_conductor_ends_the_stack_and_total_internal_reflection_blocks_transmission():
    st = add_stack([Interface(1.5, 0.1), Interface(complex(0.2, 3.0), 0.2),
                    Interface(2.0, 0.1)], 1.0)
    assert len(st.lobes) == 2 and st.cos is None
    # from glass (1.5) into air at 60 degrees: beyond the critical angle
    st = add_stack([Interface(1.0, 0.1), Interface(1.2, 0.1)], 0.5, top_ior=1.5)
    assert len(st.lobes) == 1 and st.cos is None and st.T0i == 0.0


SCENE = {"layer": [
    {"kind": "dielectric", "ior": 1.5, "roughness": 0.2, "distribution": "ggx"},
    {"kind": "medium", "albedo": 0.0, "tau": [0.0, 0.2, 0.5]},
    {"kind": "conductor", "ior": [0.2, 3.0], "roughness": 0.3, "distribution": "ggx"}]}


def test_lobes_entry_point_gives_energy_and_roughness_per_channel():
    ls = lobes(SCENE, 0.0)
    assert [l.layer for l in ls] == [0, 2]
    assert ls[0].energy.shape == (3,) and ls[0].roughness == pytest.approx([0.2] * 3)
    assert np.all(np.diff(ls[1].energy) < 0)     # absorption in green and blue
    assert ls[1].roughness[0] > 0.3              # the coat spreads the base lobe


@pytest.mark.parametrize("theta, error, words", [
    (2.0, ValueError, ("theta_i = 2 rad", "[0, pi/2)", "in radians")),
    (30.0, ValueError, ("theta_i = 30 rad", "30 deg would be 0.5236 rad")),
    (-0.3, ValueError, ("theta_i = -0.3 rad", "[0, pi/2)")),
    (math.pi / 2, ValueError, ("horizon",)),
    (math.nan, ValueError, ("theta_i = nan",)),
    (math.inf, ValueError, ("theta_i = inf",)),
    ("0.5", TypeError, ("theta_i must be one angle in radians", "str")),
    (np.array([0.1, 0.2]), TypeError, ("one angle",)),
    (True, TypeError, ("one angle",)),
])
def test_lobes_refuse_an_angle_that_is_not_an_incidence_in_radians(theta, error, words):
    """theta_i is one real number in [0, pi/2) radians: past the horizon (2 rad), negative,
    non-finite or not a number is refused with the value and the range, before the model
    runs (2 rad used to give lobes, those of theta = pi - 2 mirrored by the cosine)."""
    for call in (lambda: lobes(SCENE, theta), lambda: StatisticalBSDF(SCENE).lobes(theta)):
        with pytest.raises(error) as exc:
            call()
        for w in words:
            assert w in str(exc.value), (w, str(exc.value))


def test_model_inputs_are_checked_like_the_solved_bsdf():
    """Directions are unit vectors (..., 3) above the surface, bins are increasing edges within
    their range, as layersim.BSDF takes them: no NaN or silent zero comes back."""
    b = StatisticalBSDF(SCENE)
    up = np.array([0.0, 0.0, 1.0])
    for wi, words in (([0.0, 0.0, 0.0], "unit vectors"), ([np.nan, 0.0, 1.0], "non-finite"),
                      ([0.0, 0.0, 1.0, 1.0], "shape"), ([0.0, 0.0, -1.0], "lit from above")):
        for call in (lambda: b.albedo(wi), lambda: b.eval(wi, up),
                     lambda: b.bin_energies(wi, [0.0, 1.0], [0.0, 2 * np.pi])):
            with pytest.raises(ValueError, match=words):
                call()
    for wo, words in (([0.0, 0.0, 0.0], "wo must be unit vectors"), ([np.nan, 0, 1], "wo")):
        with pytest.raises(ValueError, match=words):
            b.eval(up, wo)
    with pytest.raises(ValueError, match=r"mu_edges must lie within \[0, 1\]"):
        b.bin_energies(up, [0.0, 0.5, 2.0], [0.0, 6.0])
    with pytest.raises(ValueError, match="strictly increasing"):
        b.bin_energies(up, [0.5, 0.0], [0.0, 6.0])
    with pytest.raises(ValueError, match="alpha must be a GGX roughness > 0"):
        from layersim.statistical.lobes import lobe_bins
        lobe_bins(up, 0.0, [0.0, 1.0], [0.0, 6.0])


def test_lobes_near_grazing_say_where_the_model_has_no_finite_width():
    """Near grazing incidence the variance of light refracted back out through the coat
    diverges in Belcour's model and the base lobe's width is undefined: an InfeasibleError
    naming the layer and the angle, not a NaN roughness."""
    scene = {"layer": [SCENE["layer"][0], SCENE["layer"][2]]}
    assert np.all(np.isfinite(lobes(scene, math.radians(80.0))[1].roughness))
    with pytest.raises(layersim.errors.InfeasibleError, match="layer 1 at theta_i = 85 deg"):
        lobes(scene, math.radians(85.0))
    with pytest.raises(layersim.errors.InfeasibleError, match="no finite width"):
        StatisticalBSDF(scene).eval([math.sin(1.5), 0.0, math.cos(1.5)], [0.0, 0.0, 1.0])


def test_statistical_bsdf_bins_and_eval_carry_the_lobe_energies():
    b = StatisticalBSDF(SCENE)
    wi = np.array([math.sin(0.5), 0.0, math.cos(0.5)])
    R, T = b.albedo(wi)
    assert np.all(T == 0.0)
    bins = b.bin_energies(wi, np.linspace(0, 1, 11), np.linspace(0, 2 * np.pi, 13))
    assert bins["top"].sum(axis=(0, 1)) == pytest.approx(R, rel=5e-4)
    th = np.linspace(0, np.pi / 2, 300)[1:]
    ph = np.linspace(0, 2 * np.pi, 601)[:-1]
    Th, Ph = np.meshgrid(th, ph, indexing="ij")
    wo = np.stack([np.sin(Th) * np.cos(Ph), np.sin(Th) * np.sin(Ph), np.cos(Th)], -1)
    f = b.eval(wi, wo)
    integral = np.sum(f * (np.cos(Th) * np.sin(Th))[..., None], axis=(0, 1)) * (
        th[1] - th[0]) * (ph[1] - ph[0])
    assert integral == pytest.approx(R, rel=2e-3)


def test_one_rough_interface_matches_the_exact_solve():
    """For one interface the model's energy is the FGD, which the exact solve integrates too:
    they differ by the solver's discretisation and the table's interpolation only."""
    scene = {"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": 0.3,
                        "distribution": "ggx"}]}
    exact = layersim.solve(scene)
    model = StatisticalBSDF(scene)
    for theta in (0.0, 30.0, 60.0):
        wi = np.array([math.sin(math.radians(theta)), 0.0, math.cos(math.radians(theta))])
        assert model.albedo(wi)[0] == pytest.approx(float(exact.albedo(wi)[0]), abs=5e-4)


@pytest.mark.parametrize("layer,field", [
    ({"kind": "dielectric", "ior": 1.5, "roughness": 0.1}, "distribution"),
    ({"kind": "medium", "albedo": 0.5, "tau": 1.0}, "albedo"),
    ({"kind": "diffuse", "albedo": 0.5}, "kind"),
    ({"kind": "dielectric", "ior": 1.5, "roughness": [0.1, 0.2], "distribution": "ggx"},
     "roughness"),
])
def test_stacks_outside_the_model_are_refused_naming_layer_and_field(layer, field):
    with pytest.raises(UnsupportedStack, match=f"layer 0.*'{field}'"):
        StatisticalBSDF({"layer": [layer]})


def test_bench_reports_the_statistical_model_where_it_applies():
    from layersim.bench.runner import Settings, _albedo_error, _error, _solver_bins
    from layersim.bench.statistical import markdown, statistical_row
    s = Settings(angles=(0.0, 30.0), n_mu=9, n_phi=18)
    glass = layersim.Scene.from_dict({"layer": [{"kind": "dielectric", "ior": 1.5,
                                                 "roughness": 0.3, "distribution": "ggx"}]})
    ref_bins, ref_alb = _solver_bins(layersim.solve(glass), s)
    row = statistical_row(glass, s, ref_bins, ref_alb, _solver_bins, _error, _albedo_error)
    # one interface: the model's reflected energy is exact; its transmitted energy 1 - R
    # ignores the shadowing loss of single-scattering GGX, and has no distribution
    assert row["albedo_error"] < 0.05 and row["top_error"] < 0.1 and row["error"] > 0.5
    beckmann = layersim.Scene.from_dict({"layer": [{"kind": "dielectric", "ior": 1.5,
                                                    "roughness": 0.3}]})
    row = statistical_row(beckmann, s, ref_bins, ref_alb, _solver_bins, _error, _albedo_error)
    assert "distribution" in row["skipped"]
    assert "not applicable" in markdown(row, str)[0]


def test_per_channel_tau_is_coloured_beer_lambert_absorption_in_the_solver():
    """A medium's ``tau`` per channel (what designs use for colour): a channel with tau = 0
    solves exactly as the stack without the medium, and the plan keeps the medium."""
    coat = {"kind": "dielectric", "ior": 1.5, "roughness": 0.3, "distribution": "ggx"}
    base = {"kind": "conductor", "ior": [0.2, 3.0], "roughness": 0.3, "distribution": "ggx"}
    medium = {"kind": "medium", "albedo": 0.0, "tau": [0.0, 0.2, 0.5]}
    disc = {"n": 64, "md": 64}
    tinted = layersim.Scene.from_dict({"layer": [coat, medium, base], "discretization": disc})
    assert [tinted.channel(c).layers[1].tau for c in range(3)] == [0.0, 0.2, 0.5]
    assert "tau=0/0.2/0.5" in layersim.make_plan(tinted).report()
    normal = np.array([0.0, 0.0, 1.0])
    R = layersim.solve(tinted).albedo(normal)[0]
    clear = layersim.solve({"layer": [coat, base], "discretization": disc}).albedo(normal)[0]
    assert R[0] == pytest.approx(float(clear), abs=1e-9)
    assert R[0] > R[1] > R[2]
