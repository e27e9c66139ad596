"""Thin-film interfaces (``film = { thickness, ior }``, ``[stack] wavelengths``): the Airy
reflectance against an independent transfer-matrix computation, its limits, reciprocity and
energy; the solver against the closed form and against the walk; a zero thickness is the bare
interface; bad input is refused with one line naming the layer and the field.

Reference: Belcour & Barla 2017, "A practical extension to microfacet theory for the modeling
of varying iridescence", ACM TOG 36(4); Born & Wolf, Principles of Optics, sec. 1.6 (the
characteristic matrix of a film, used here as the independent reference).
"""

import numpy as np
import pytest

import layersim
import layersim.montecarlo as mc
from layersim.errors import InfeasibleError, SceneError
from layersim.ingredients.microfacet import interface_operator
from layersim.ingredients.numeric import numeric_interface_operator
from layersim.kernels import physics, sampling, walk
from layersim.kernels.fresnel import fresnel
from layersim.layers.dielectric import Dielectric
from layersim.layers.interface import Film
from layersim.montecarlo.backends import opencl_source
from layersim.montecarlo.stack import flatten
from layersim.operators.operator import Grid
from layersim.statistical.stack import statistical_stacks

from conftest import unit
from probes import ProbeSet

GOLD = [0.143552, 3.98397]
RGB = [650.0, 550.0, 450.0]
ANGLES = np.radians(np.arange(0.0, 85.5, 1.0))


# ------------------------------------------------------------------------------------------------
# The independent reference: the characteristic matrix of one film (Born & Wolf, sec. 1.6.2)
# ------------------------------------------------------------------------------------------------


def transfer_matrix(cos_1, n1, n2, n3, thickness, wavelength):
    """Unpolarised reflectance of a film of index ``n2`` and ``thickness`` between media
    ``n1`` (incident, real) and ``n3`` (complex allowed), by the characteristic matrix
    ``[[cos d, -i sin d / Y2], [-i Y2 sin d, cos d]]`` with ``d = 2 pi n2 d cos(theta_2) /
    lambda`` and the tilted admittances ``Y = n cos(theta)`` (s) and ``n / cos(theta)`` (p)."""
    cos_1 = np.asarray(cos_1, float)
    s2 = (n1 ** 2) * (1.0 - cos_1 ** 2)
    q = [np.sqrt(np.asarray(n, complex) ** 2 - s2 + 0j) for n in (n1, n2, n3)]
    q = [np.where(x.imag < 0, -x, x) for x in q]
    delta = 2.0 * np.pi * thickness / wavelength * q[1]
    out = 0.0
    for pol in "sp":
        y = q if pol == "s" else [np.asarray(n, complex) ** 2 / x for n, x in zip((n1, n2, n3), q)]
        m11 = m22 = np.cos(delta)
        m12 = -1j * np.sin(delta) / y[1]
        m21 = -1j * y[1] * np.sin(delta)
        num = y[0] * m11 + y[0] * y[2] * m12 - m21 - y[2] * m22
        den = y[0] * m11 + y[0] * y[2] * m12 + m21 + y[2] * m22
        out = out + 0.5 * np.abs(num / den) ** 2
    return out


def film(thickness, n, wavelength, eta_above=1.0):
    """Kernel parameters of a film: (relative index, phase scale)."""
    return n / eta_above, 4.0 * np.pi * n * thickness / wavelength


# ------------------------------------------------------------------------------------------------
# (a) the Airy reflectance
# ------------------------------------------------------------------------------------------------

# (name, eta, k, film index, side): a film on glass, seen from the air and from inside the glass
# (total internal reflection, and an evanescent film beyond its own critical angle), a film
# denser than its substrate, and films on gold and on a lossy dielectric-like conductor
SUBSTRATES = [("water on glass", 1.5, 0.0, 1.33, "above"),
              ("water on glass, from inside", 1.5, 0.0, 1.33, "below"),
              ("low-index film, from inside", 1.5, 0.0, 1.05, "below"),
              ("titania on glass", 1.5, 0.0, 2.4, "above"),
              ("oxide on gold", GOLD[0], GOLD[1], 1.4, "above"),
              ("film on a weak absorber", 2.0, 0.5, 1.6, "above")]


@pytest.mark.parametrize("name, eta, k, n_film, side", SUBSTRATES,
                         ids=[s[0] for s in SUBSTRATES])
@pytest.mark.parametrize("thickness", [100.0, 300.0, 700.0])
def test_airy_reflectance_is_the_transfer_matrix_one(name, eta, k, n_film, side, thickness):
    c = np.cos(ANGLES)
    for lam in RGB:
        got = fresnel(c if side == "above" else -c, eta, k, film(thickness, n_film, lam))
        if side == "above":
            want = transfer_matrix(c, 1.0, n_film, complex(eta, k), thickness, lam)
        else:
            want = transfer_matrix(c, eta, n_film, 1.0, thickness, lam)
        assert np.max(np.abs(got - want)) < 1e-10, (lam, np.max(np.abs(got - want)))
        assert np.all((got >= 0.0) & (got <= 1.0))


def test_the_film_changes_the_colour_and_a_thin_or_matched_film_vanishes():
    """Interference is there (the reflectance of water on glass changes several-fold across
    the spectrum), and the film disappears exactly where it should: phase scale -> 0 gives the
    bare Fresnel reflectance (r13 = (r12 + r23) / (1 + r12 r23)), and so does a film whose
    index matches the medium above (r12 = 0), whatever its thickness."""
    c = np.concatenate([np.cos(ANGLES), -np.cos(ANGLES)])
    for eta, k in ((1.5, 0.0), (GOLD[0], GOLD[1]), (0.7, 0.0)):
        if k:
            c = np.abs(c)
        bare = fresnel(c, eta, k)
        np.testing.assert_allclose(fresnel(c, eta, k, (1.4, 1e-13)), bare, rtol=0, atol=1e-12)
        np.testing.assert_allclose(fresnel(c, eta, k, (1.0, 37.0)), bare, rtol=0, atol=1e-12)
    R = [fresnel([1.0], 1.5, 0.0, film(300.0, 1.33, lam))[0] for lam in np.linspace(400, 700, 31)]
    assert max(R) > 3 * min(R)


def test_total_internal_reflection_is_exactly_one_with_a_film():
    """From inside the glass beyond the critical angle nothing leaves, film or not: exactly 1,
    as the bare Fresnel factor (the walk then never refracts)."""
    c = -np.cos(np.radians(np.linspace(42.0, 89.9, 50)))
    assert np.all(fresnel(c, 1.5, 0.0, film(300.0, 1.33, 550.0)) == 1.0)
    assert np.all(fresnel(c, 1.5, 0.0) == 1.0)


V, T, F, I = "double3", "double", "float", "int"
PROBES = [
    (physics.fresnel_interface, [T] * 5),                                     # 0
    (physics.fresnel_interface, [F] * 5),                                     # 1
    (physics.microfacet_eval_film, [V, V, T, T, T, T, T, T, I]),              # 2
    (sampling.sample_microfacet_film, [V, T, T, T, T, T, T, I, T, T, T, T]),  # 3
    (sampling.microfacet_pdf_film, [V, V, T, T, T, T, T, T, I]),              # 4
]


@pytest.fixture(scope="module")
def probes(tmp_path_factory):
    return ProbeSet(PROBES, tmp_path_factory.mktemp("film"), name="layersim_test_film_probes")


def _unit(r, n, upper=False):
    v = r.normal(size=(n, 3))
    if upper:
        v[:, 2] = np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_the_walk_precision_of_the_airy_reflectance(probes):
    """The walk evaluates the film in float32. Against float64: within 5e-6 for round-trip
    phases up to 25 radians (400 nm of n = 2 at 400 nm) and 2e-5 up to 160 radians (the
    rounding of the phase grows with it), away from the critical angle of a dielectric seen
    from its dense side; near it (where the reflectance has a square-root edge that amplifies
    the rounding of the cosine) no worse than twice the bare Fresnel factor's own float32
    error."""
    r = np.random.default_rng(3)
    n = 50000
    conductor = r.random(n) < 0.5
    c = np.where(conductor, r.uniform(0.02, 1, n), r.uniform(-1, 1, n))
    eta = np.where(conductor, r.uniform(0.1, 2.0, n), r.uniform(1.1, 2.0, n))
    k = np.where(conductor, r.uniform(0.5, 5.0, n), 0.0)
    n_film = r.uniform(1.0, 2.5, n)
    ps = 4 * np.pi * n_film * r.uniform(0, 2000, n) / r.uniform(400, 700, n)

    def error(phase):
        args = [c, eta, k, n_film, phase]
        want = probes.warp(0, *args)[0]
        return np.abs(probes.warp(1, *[a.astype(np.float32) for a in args])[0] - want)

    film_err, bare_err = error(ps), error(np.zeros(n))
    # (n cos theta)^2 in the medium the light leaves into and in the film (0 at their
    # critical angles)
    s2 = np.where(c < 0, eta ** 2, 1.0) * (1 - c ** 2)
    exit_gap = np.where(conductor, 1.0, np.where(c < 0, 1.0, eta ** 2) - s2)
    film_gap = n_film ** 2 - s2
    far = (np.abs(exit_gap) > 0.02) & (np.abs(film_gap) > 0.02)
    assert np.max(film_err[far & (ps <= 25.0)]) < 5e-6
    assert np.max(film_err[far]) < 2e-5
    assert np.max(film_err[~far]) < 2 * np.max(bare_err[~far]) + 1e-5


# ------------------------------------------------------------------------------------------------
# The filmed microfacet BSDF: reciprocity, energy, sampling
# ------------------------------------------------------------------------------------------------


def test_the_filmed_microfacet_bsdf_is_reciprocal(probes):
    """f(wi, wo) / eta_o^2 == f(wo, wi) / eta_i^2 pointwise: the film's transmittance 1 - R is
    the same from both sides at Snell-related angles."""
    r = np.random.default_rng(11)
    n = 20000
    wi, wo = _unit(r, n), _unit(r, n)
    eta = np.where(r.random(n) < 0.5, r.uniform(1.1, 2.0, n), r.uniform(0.5, 0.9, n))
    zero = np.zeros(n)
    ef, ps = r.uniform(1.0, 2.5, n), r.uniform(1.0, 60.0, n)
    a, d = r.uniform(0.05, 0.8, n), r.integers(0, 2, n)
    f_io = probes.warp(2, wi, wo, eta, zero, ef, ps, a, a, d)[0]
    f_oi = probes.warp(2, wo, wi, eta, zero, ef, ps, a, a, d)[0]
    eta_i = np.where(wi[:, 2] < 0, eta, 1.0)
    eta_o = np.where(wo[:, 2] < 0, eta, 1.0)
    assert np.count_nonzero(f_io) > n // 3
    # (rtol: near the critical angle the square-root edge of the reflectance amplifies the
    # rounding of the facet cosines, as for the bare Fresnel factor)
    np.testing.assert_allclose(f_io / eta_o ** 2, f_oi / eta_i ** 2, rtol=1e-6, atol=1e-300)
    close = np.isclose(f_io / eta_o ** 2, f_oi / eta_i ** 2, rtol=1e-10, atol=1e-300)
    assert close.mean() > 0.999


@pytest.mark.parametrize("conductor", [False, True])
def test_the_walk_samples_the_filmed_bsdf(probes, conductor):
    """weight == f(wi, wo) |wo.z| / pdf(wo) pointwise for the filmed sampler, and no weight
    exceeds 1: the filmed interface never creates energy (reflection and transmission share
    the Airy split R + (1 - R), or a conductor keeps R <= 1)."""
    r = np.random.default_rng(5 + conductor)
    n = 4000
    wi = _unit(r, n, upper=conductor)
    eta = r.uniform(1.1, 2.0, n) if not conductor else r.uniform(0.1, 2.0, n)
    k = r.uniform(1, 4, n) if conductor else np.zeros(n)
    ef, ps = r.uniform(1.0, 2.5, n), r.uniform(1.0, 60.0, n)
    au, av, d = r.uniform(0.05, 0.8, n), r.uniform(0.05, 0.8, n), r.integers(0, 2, n)
    us = [r.uniform(1e-9, 1 - 1e-9, n) for _ in range(4)]
    wo, weight = probes.warp(3, wi, eta, k, ef, ps, au, av, d, *us)
    pdf = probes.warp(4, wi, wo, eta, k, ef, ps, au, av, d)[0]
    f = probes.warp(2, wi, wo, eta, k, ef, ps, au, av, d)[0]
    live = weight > 0
    assert live.mean() > 0.8
    assert np.max(weight) <= 1.0
    np.testing.assert_allclose(weight[live], f[live] * np.abs(wo[live, 2]) / pdf[live],
                               rtol=1e-7)


def test_the_filmed_rough_dielectric_operator_is_reciprocal():
    """(e) Projected without the reciprocity shortcut, every block independently: the filmed
    rough dielectric's operator is reciprocal (f(wi, wo) / eta_o^2 = f(wo, wi) / eta_i^2 in
    every Fourier order) to 1e-12 of its largest coefficient, as the bare one (8e-14)."""
    grid = Grid.make("gauss-lobatto", 32)
    layer = Dielectric(ior=1.5 + 0j, alpha_u=0.3, alpha_v=0.3, film=Film(500.0, 1.33, 450.0))
    op = numeric_interface_operator(grid, 24, layer, 1.0, reciprocity=False)
    assert op.reciprocity_error() < 1e-12


def test_the_semi_analytic_projection_of_a_filmed_interface_matches_the_numeric_one():
    """Both projection paths evaluate the film: pair energies (order 0 times the quadrature
    weight) agree to 1e-6 of a beam's energy (bare: 3e-7 in transmission, 2e-9 in
    reflection)."""
    grid = Grid.make("gauss-lobatto", 32)
    for layer in (Dielectric(ior=1.5 + 0j, alpha_u=0.3, alpha_v=0.3,
                             film=Film(500.0, 1.33, 450.0)),):
        a = numeric_interface_operator(grid, 40, layer, 1.0)
        b = interface_operator(grid, 40, layer, 1.0)
        for name in ("Rt", "Ttb"):
            diff = (a.coefficients(name, 0) - b.coefficients(name, 0)) * grid.flux_weight
            assert np.max(np.abs(diff)) * 2 * np.pi < 1e-6, name


# ------------------------------------------------------------------------------------------------
# (b), (c) the solver: a smooth filmed conductor is its Airy reflectance; zero thickness
# ------------------------------------------------------------------------------------------------


def scene(layers, wavelengths=RGB, **stack):
    data = {"layer": layers, "stack": dict(stack)}
    if wavelengths is not None:
        data["stack"]["wavelengths"] = list(wavelengths)
    return layersim.Scene.from_dict(data)


@pytest.mark.parametrize("thickness", [100.0, 300.0, 700.0])
def test_a_smooth_filmed_conductor_solves_to_its_airy_reflectance(thickness):
    """(b) A smooth conductor is an exact Fresnel diagonal: the solved BSDF's albedo at every
    ordinate is the film's reflectance from the transfer matrix, in every channel."""
    s = scene([{"kind": "conductor", "ior": GOLD, "film": {"thickness": thickness, "ior": 1.4}}])
    bsdf = layersim.solve(s)
    mu = bsdf.grid.mu[bsdf.grid.mu > np.cos(np.radians(85.0))]
    wi = np.stack([np.sqrt(1 - mu ** 2), np.zeros_like(mu), mu], axis=1)
    R, T = bsdf.albedo(wi)
    for c, lam in enumerate(RGB):
        want = transfer_matrix(mu, 1.0, 1.4, complex(*GOLD), thickness, lam)
        assert np.max(np.abs(R[:, c] - want)) < 1e-6
    assert np.all(T == 0.0)


def test_a_zero_thickness_is_exactly_the_bare_interface():
    """(c) thickness 0: the same records, so the same operators and bit-identical walk
    tallies as without a film."""
    for layers in ([{"kind": "conductor", "ior": GOLD, "roughness": 0.2}],
                   [{"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
                    {"kind": "diffuse", "albedo": 0.5}]):
        bare = scene(layers)
        layers[0]["film"] = {"thickness": 0.0, "ior": 1.4}
        zero = scene(layers)
        assert zero.stacks == bare.stacks
        wi = unit(30.0)[None]
        for a, b in zip(layersim.solve(zero).albedo(wi), layersim.solve(bare).albedo(wi)):
            assert np.array_equal(a, b)
        fa, fb = flatten(zero.channel(0)), flatten(bare.channel(0))
        assert np.array_equal(fa.bnd_f, fb.bnd_f) and not fa.features.film
        ra = mc.simulate(zero, wi[0], 20_000, backend="warp-cpu", seed=1)
        rb = mc.simulate(bare, wi[0], 20_000, backend="warp-cpu", seed=1)
        assert np.array_equal(ra.bins["top"], rb.bins["top"])


# ------------------------------------------------------------------------------------------------
# (d) the solver against the walk
# ------------------------------------------------------------------------------------------------

MU_EDGES = np.linspace(0.0, 1.0, 9)
PHI_EDGES = np.linspace(0.0, 2 * np.pi, 13)


def _agree(s, theta, particles, below=False, seed=7, min_fraction=0.99):
    """Albedo and bins of the solver within 4 standard errors of the walk's, lit at the
    ordinate of the plan nearest to ``theta`` degrees (so that the comparison measures the
    projection, not the interpolation between incident elevations)."""
    bsdf = layersim.solve(s)
    mu = bsdf.grid.mu
    m = mu[np.argmin(np.abs(mu - np.cos(np.radians(theta))))]
    wi = np.array([np.sqrt(1 - m * m), 0.0, -m if below else m])
    res = mc.simulate(s, wi, particles, MU_EDGES, PHI_EDGES, backend="warp-cpu", seed=seed)
    R, T = bsdf.albedo(wi[None])        # both: back to the side of incidence, and through
    for got, want, err in ((R[0], res.reflectance, res.reflectance_stderr),
                           (T[0], res.transmittance, res.transmittance_stderr)):
        assert np.all(np.abs(got - want) <= 4 * err + 1e-12), (got, want, err)
    bins = bsdf.bin_energies(wi, MU_EDGES, PHI_EDGES)
    z = np.concatenate([res.z_scores(side, bins[side]).ravel() for side in ("top", "bottom")])
    assert np.mean(z <= 4.0) >= min_fraction, np.sort(z)[-5:]
    return res


@pytest.mark.slow
def test_a_rough_filmed_conductor_agrees_with_the_walk():
    """(d) Oxide on gold (alpha 0.2, 400 nm of n = 1.4) at 650, 550 and 450 nm: albedo and
    bins within 4 standard errors of 1e7 paths per channel (about 8 s on two cores)."""
    s = scene([{"kind": "conductor", "ior": GOLD, "roughness": 0.2,
                "film": {"thickness": 400.0, "ior": 1.4}}])
    res = _agree(s, 35.0, 10_000_000)
    assert np.ptp(res.reflectance) > 0.01            # the film colours the reflection


@pytest.mark.slow
def test_a_rough_filmed_glass_slab_agrees_with_the_walk_from_both_sides():
    """A water film on rough glass, lit from the air and from inside the glass (the film's
    reflectance from the dense side, and its transmission through the Airy factor). As for
    the bare interface (test_solver_vs_montecarlo), light from inside needs n = 200 for 1e6
    paths: at the planner's n = 66 the internal reflection is 3.7 standard errors off, with
    or without the film."""
    s = layersim.Scene.from_dict({"layer": [{"kind": "dielectric", "ior": 1.5,
                                             "roughness": 0.3,
                                             "film": {"thickness": 500.0, "ior": 1.33}}],
                                  "stack": {"wavelengths": RGB},
                                  "discretization": {"n": 200}})
    _agree(s, 30.0, 1_000_000)
    _agree(s, 30.0, 1_000_000, below=True)


@pytest.mark.slow
def test_an_anisotropic_filmed_conductor_agrees_with_the_walk():
    """The coupled-mode projection evaluates the film too: oxide on anisotropic gold (alpha
    0.15 x 0.35, rotated 30 degrees), 1e6 paths per channel. One bin (of 76 per channel) is
    4.8 standard errors off in every channel, as it is for the bare interface at the plan's
    discretisation (n = 64, ms = 7): 98 % of the bins are asked within 4."""
    s = scene([{"kind": "conductor", "ior": GOLD, "roughness": [0.15, 0.35], "rotation": 30.0,
                "film": {"thickness": 400.0, "ior": 1.4}}])
    _agree(s, 40.0, 1_000_000, min_fraction=0.98)


# ------------------------------------------------------------------------------------------------
# Plan, description, walk features
# ------------------------------------------------------------------------------------------------


def test_the_plan_names_the_film_and_keeps_the_lobe_widths():
    filmed = scene([{"kind": "conductor", "ior": GOLD, "roughness": 0.2,
                     "film": {"thickness": 400.0, "ior": 1.4}}])
    bare = scene([{"kind": "conductor", "ior": GOLD, "roughness": 0.2}])
    pf, pb = layersim.make_plan(filmed), layersim.make_plan(bare)
    assert "thin film d = 400 nm, n = 1.4" in pf.layers[0].detail
    assert "650, 550, 450 nm" in pf.layers[0].detail
    assert pf.layers[0].width == pb.layers[0].width and pf.n == pb.n
    assert "thin film d = 400 nm" in filmed.describe() and "at 650, 550, 450 nm" in \
        filmed.describe()
    assert [x.film.wavelength for x in (filmed.channel(c).layers[0] for c in range(3))] == RGB


def test_the_walk_compiles_film_code_only_for_filmed_stacks():
    filmed = scene([{"kind": "conductor", "ior": GOLD, "roughness": 0.2,
                     "film": {"thickness": 400.0, "ior": 1.4}}])
    bare = scene([{"kind": "conductor", "ior": GOLD, "roughness": 0.2}])
    st = flatten(filmed.channel(2))
    rec = st.bnd_f[:walk.BND_F]
    assert st.features.film and not flatten(bare.channel(0)).features.film
    assert rec[walk.FILM_ETA] == pytest.approx(1.4)
    assert rec[walk.FILM_PHASE] == pytest.approx(4 * np.pi * 1.4 * 400 / 450, rel=1e-6)
    lean = opencl_source(flatten(bare.channel(0)).features)
    assert "sample_microfacet_film" not in lean and "airy" not in lean
    assert "sample_microfacet_film" in opencl_source(st.features)


@pytest.mark.slow
def test_the_opencl_walk_walks_the_film_as_warp_does(cl_device):
    """The translated walk of a smooth filmed coat over a rough filmed conductor follows the
    same particles as Warp's (same seed): every bin within 0.05 standard errors (float32
    rounding in the two compilers)."""
    s = scene([{"kind": "dielectric", "ior": 1.5, "film": {"thickness": 300.0, "ior": 1.33}},
               {"kind": "conductor", "ior": GOLD, "roughness": 0.2,
                "film": {"thickness": 400.0, "ior": 1.4}}])
    mu, phi = np.linspace(0, 1, 5), np.linspace(0, 2 * np.pi, 5)
    a = mc.simulate(s, unit(30.0), 20_000, mu, phi, backend="opencl", seed=2)
    b = mc.simulate(s, unit(30.0), 20_000, mu, phi, backend="warp-cpu", seed=2)
    assert "film" not in a.left_out and a.left_out == b.left_out
    err = np.hypot(a.bins_stderr["top"], b.bins_stderr["top"])
    assert np.all(np.abs(a.bins["top"] - b.bins["top"]) <= 0.05 * err + 1e-12)


# ------------------------------------------------------------------------------------------------
# (f) bad input
# ------------------------------------------------------------------------------------------------

FILM = {"thickness": 300.0, "ior": 1.4}
NDF_THETA = np.linspace(0.0, 90.0, 91)             # an inline Beckmann table, alpha = 0.3
_C = np.cos(np.radians(NDF_THETA[:-1]))
BECKMANN_03 = np.append(np.exp(-(1 / _C ** 2 - 1) / 0.09) / (np.pi * 0.09 * _C ** 4), 0.0)
BAD = [
    ("film on a medium", [{"kind": "medium", "albedo": 0.5, "tau": 1.0, "film": FILM}], RGB,
     SceneError, "layer 0 (medium): field 'film': unknown field"),
    ("film on a diffuse base", [{"kind": "diffuse", "albedo": 0.5, "film": FILM}], RGB,
     SceneError, "layer 0 (diffuse): field 'film': unknown field"),
    ("negative thickness", [{"kind": "conductor", "ior": GOLD,
                             "film": {"thickness": -1.0, "ior": 1.4}}], RGB,
     SceneError, "layer 0 (conductor): field 'film.thickness': must be >= 0"),
    ("too thick", [{"kind": "conductor", "ior": GOLD, "film": {"thickness": 2e4, "ior": 1.4}}],
     RGB, SceneError, "field 'film.thickness': must be <= 10000"),
    ("film index below 1", [{"kind": "dielectric", "ior": 1.5, "roughness": 0.2,
                             "film": {"thickness": 300.0, "ior": 0.5}}], RGB,
     SceneError, "layer 0 (dielectric): field 'film.ior': must be >= 1"),
    ("film not a table", [{"kind": "conductor", "ior": GOLD, "film": 300.0}], RGB,
     SceneError, "field 'film': must be a table"),
    ("film without ior", [{"kind": "conductor", "ior": GOLD, "film": {"thickness": 300.0}}],
     RGB, SceneError, "field 'film.ior': is required"),
    ("unknown film key", [{"kind": "conductor", "ior": GOLD,
                           "film": {"thickness": 300.0, "ior": 1.4, "k": 0.1}}], RGB,
     SceneError, "field 'film.k': unknown key"),
    ("film without wavelengths", [{"kind": "conductor", "ior": GOLD, "film": FILM}], None,
     SceneError, "layer 0 (conductor): field 'film': needs the channels' wavelengths"),
    ("two wavelengths", [{"kind": "conductor", "ior": GOLD, "film": FILM}], [500.0, 600.0],
     SceneError, "field 'stack.wavelengths': must be a list of one or three"),
    ("wavelength out of range", [{"kind": "conductor", "ior": GOLD, "film": FILM}],
     [650.0, 550.0, 50.0], SceneError, "field 'stack.wavelengths[2]': must be >= 100"),
    ("three values, one wavelength",
     [{"kind": "dielectric", "ior": 1.5, "roughness": 0.2, "film": FILM},
      {"kind": "medium", "albedo": [0.5, 0.6, 0.7], "tau": 1.0},
      {"kind": "diffuse", "albedo": 0.5}], [550.0],
     SceneError, "layer 1 (medium): field 'albedo': gives 3 per-channel values but [stack] "
                 "wavelengths has 1"),
    ("three conductor indices, one wavelength",
     [{"kind": "conductor", "ior": [GOLD, GOLD, GOLD], "film": FILM}], [550.0],
     SceneError, "layer 0 (conductor): field 'ior': gives 3 per-channel values"),
    ("film on a tabulated NDF",
     [{"kind": "conductor", "ior": GOLD, "distribution": "tabulated",
       "ndf": {"theta": list(NDF_THETA), "phi": [0.0, 180.0],
               "D": [[d, d] for d in BECKMANN_03]},
       "film": FILM}], RGB, SceneError, "field 'film': is not available with a tabulated NDF"),
    ("film with an energy compensation",
     [{"kind": "conductor", "ior": GOLD, "roughness": 0.2, "film": FILM,
       "energy_compensation": "multiple-scattering"}], RGB,
     SceneError, "layer 0 (conductor): field 'energy_compensation': 'multiple-scattering' is "
                 "not available with a film"),
]


@pytest.mark.parametrize("name, layers, wavelengths, error, message", BAD,
                         ids=[b[0] for b in BAD])
def test_bad_film_input_is_refused_in_one_line(name, layers, wavelengths, error, message):
    with pytest.raises(error) as exc:
        scene(layers, wavelengths)
    text = str(exc.value)
    assert message in text and "\n" not in text, text


def test_the_stack_wide_compensation_is_refused_on_a_filmed_layer():
    with pytest.raises(SceneError, match="layer 0 \\(dielectric\\): field "
                                         "'energy_compensation'.*on this layer"):
        scene([{"kind": "dielectric", "ior": 1.5, "roughness": 0.2, "film": FILM}],
              energy_compensation="multiple-scattering")


def test_what_the_solver_and_the_walk_do_not_handle_is_refused_clearly():
    smooth_coat = scene([{"kind": "dielectric", "ior": 1.5, "film": FILM},
                         {"kind": "diffuse", "albedo": 0.5}])
    with pytest.raises(InfeasibleError, match="layer 0 \\(dielectric\\): field 'film': a film "
                                              "on a smooth dielectric boundary is not solved"):
        layersim.solve(smooth_coat)
    # ... which the walk handles
    res = mc.simulate(smooth_coat, unit(20.0), 10_000, backend="warp-cpu", seed=1)
    assert 0.0 < float(np.min(res.reflectance)) < 1.0
    matched = scene([{"kind": "dielectric", "ior": 1.5, "roughness": 0.2},
                     {"kind": "dielectric", "ior": 1.5, "roughness": 0.2, "film": FILM},
                     {"kind": "diffuse", "albedo": 0.5}])
    for run in (lambda: layersim.solve(matched),
                lambda: mc.simulate(matched, unit(20.0), 100, backend="warp-cpu")):
        with pytest.raises(SceneError, match="layer 1 \\(dielectric\\): field 'film': a film "
                                             "on an index-matched interface"):
            run()
    rough = scene([{"kind": "conductor", "ior": GOLD, "roughness": 0.2, "distribution": "ggx",
                    "film": FILM}])
    with pytest.raises(SceneError, match="layer 0 \\(conductor\\): field 'film': a thin film "
                                         "is not represented"):
        statistical_stacks(rough)
