"""simulate(): backends, determinism, batching, early stop, channels, stack layout, bad input."""

import math

import numpy as np
import pytest

import layersim
import layersim.montecarlo as mc
from layersim.kernels import walk
from layersim.montecarlo.stack import flatten

COATED = {"layer": [
    {"kind": "dielectric", "ior": 1.5, "roughness": [0.1, 0.2], "rotation": 15.0},
    {"kind": "medium", "albedo": 0.9, "g": 0.4, "tau": 0.3},
    {"kind": "conductor", "ior": [0.143552, 3.98397], "roughness": [0.2, 0.1]}]}
SLAB = {"layer": [{"kind": "dielectric", "ior": 1.3, "roughness": 0.2, "distribution": "ggx"},
                  {"kind": "medium", "albedo": 0.95, "g": 0.5, "tau": 2.0},
                  {"kind": "dielectric", "ior": 1.0, "roughness": 0.3}]}
WI = np.array([math.sin(0.6) * math.cos(0.4), math.sin(0.6) * math.sin(0.4), math.cos(0.6)])
MU = np.linspace(0, 1, 4)
PHI = np.linspace(0, 2 * np.pi, 5)


def scene(d):
    return layersim.Scene.from_dict(d)


def run(d, n=20_000, backend="warp-cpu", **kw):
    return mc.simulate(scene(d), kw.pop("wi", WI), n, mu_edges=MU, phi_edges=PHI,
                       backend=backend, **kw)


def same(a, b):
    return (a.reflectance == b.reflectance and a.transmittance == b.transmittance
            and a.absorbed == b.absorbed and a.events == b.events
            and all(np.array_equal(a.bins[s], b.bins[s]) for s in ("top", "bottom"))
            and all(np.array_equal(a.bins_stderr[s], b.bins_stderr[s])
                    for s in ("top", "bottom")))


def test_z_scores_measure_bin_differences_in_standard_errors_with_a_poisson_floor():
    """The walk's own bins are 0 standard errors from themselves; a shift by 3 standard errors
    of its busiest bin reads 3 se / sqrt(se^2 + E / N); a value E in a bin the walk left empty
    (zero standard error) is judged against the Poisson spread sqrt(E / N): sqrt(E N); bins
    empty in both are left out."""
    import dataclasses
    res = run(SLAB)
    est, se = res.bins["top"], res.bins_stderr["top"]
    assert np.all(res.z_scores("top", est) == 0.0) and res.z_scores("top", est).size == est.size
    busy = np.unravel_index(np.argmax(est), est.shape)
    shifted = est.copy()
    shifted[busy] += 3.0 * se[busy]
    z = res.z_scores("top", shifted)
    assert z.max() == pytest.approx(3.0 * se[busy] / np.sqrt(se[busy] ** 2
                                                             + shifted[busy] / res.particles))
    hole = (0, 0)
    est0, se0 = est.copy(), se.copy()
    est0[hole] = se0[hole] = 0.0
    holed = dataclasses.replace(res, bins={**res.bins, "top": est0},
                                bins_stderr={**res.bins_stderr, "top": se0})
    values = est0.copy()
    values[hole] = 1e-3
    z = holed.z_scores("top", values)
    assert z.size == np.count_nonzero(est0) + 1
    assert z.max() == pytest.approx(np.sqrt(1e-3 * res.particles))


# ------------------------------------------------------------------------------------------------
# Determinism and batching
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("d", [COATED, SLAB], ids=["coated", "slab"])
def test_same_seed_is_bit_identical_and_batch_size_does_not_matter(d):
    a = run(d, seed=3)
    b = run(d, seed=3)
    c = run(d, seed=3, batch_size=1234)
    assert same(a, b) and same(a, c)
    other = run(d, seed=4)
    assert other.reflectance != a.reflectance


def test_particles_are_a_prefix_of_a_longer_run():
    """Particle p's path depends on (seed, p) only: runs with N and 2N particles share the
    first N walks, so the first half of the long run reproduces the short one exactly."""
    short = run(SLAB, 4000, seed=11)
    long_ = run(SLAB, 8000, seed=11, batch_size=4000, target_stderr=1.0)   # stops after batch 1
    assert long_.particles == 4000 and same(short, long_)


def test_early_stop_on_target_stderr():
    target = 4e-3
    res = run(SLAB, 2_000_000, seed=2, batch_size=5000, target_stderr=target)
    assert res.particles < 2_000_000 and res.particles % 5000 == 0
    assert max(res.reflectance_stderr, res.transmittance_stderr, res.absorbed_stderr) <= target
    prev = run(SLAB, res.particles - 5000, seed=2)
    assert max(prev.reflectance_stderr, prev.transmittance_stderr, prev.absorbed_stderr) > target


# ------------------------------------------------------------------------------------------------
# Backends
# ------------------------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("d", [COATED, SLAB], ids=["coated", "slab"])
def test_warp_and_opencl_agree(d, cl_device):
    w = run(d, 40_000, seed=5)
    o = run(d, 40_000, backend="opencl", seed=5)
    assert o.backend == "opencl" and w.backend == "warp-cpu"
    for key in ("reflectance", "transmittance", "absorbed"):
        err = math.hypot(getattr(w, key + "_stderr"), getattr(o, key + "_stderr"))
        assert abs(getattr(w, key) - getattr(o, key)) <= 4 * err + 1e-6, key
    for s in ("top", "bottom"):
        err = np.hypot(w.bins_stderr[s], o.bins_stderr[s])
        assert np.all(np.abs(w.bins[s] - o.bins[s]) <= 4 * err + 1e-6)
    # same random numbers and the same translated physics: the paths themselves coincide
    # except where float32 library functions round differently
    assert abs(w.events - o.events) <= 1e-3 * w.events


@pytest.mark.slow
def test_opencl_is_deterministic_across_batch_sizes(cl_device):
    a = run(COATED, 30_000, backend="opencl", seed=8)
    b = run(COATED, 30_000, backend="opencl", seed=8, batch_size=7000)
    assert same(a, b)


def test_backend_selection_and_errors():
    from layersim.montecarlo import backends
    names = mc.available_backends()
    assert "warp-cpu" in names
    if "opencl" in names:
        device = backends.opencl_device()
        small_cpu = backends._is_cpu(device) and \
            device.max_compute_units < backends.OPENCL_CPU_MIN_UNITS
        # on a CPU with few cores PoCL is slower than warp-cpu: "auto" must not pick it
        assert (names.index("warp-cpu") < names.index("opencl")) == small_cpu
    res = run(SLAB, 100, backend="auto")
    assert res.backend == names[0]
    with pytest.raises(ValueError, match="unknown backend"):
        run(SLAB, 100, backend="cuda")
    if "warp-cuda" not in names:
        with pytest.raises(mc.BackendUnavailableError, match="CUDA"):
            run(SLAB, 100, backend="warp-cuda")


# ------------------------------------------------------------------------------------------------
# Channels, truncation, layout
# ------------------------------------------------------------------------------------------------


def test_rgb_scene_has_a_trailing_channel_axis():
    d = {"layer": [{"kind": "dielectric", "ior": 1.5},
                   {"kind": "diffuse", "albedo": [0.2, 0.5, 0.8]}]}
    res = run(d, 20_000, seed=1)
    assert res.reflectance.shape == (3,) and res.bins["top"].shape == (3, 4, 3)
    assert res.particles.shape == (3,) and np.all(res.particles == 20_000)
    assert np.all(np.diff(res.reflectance) > 0)
    for c in range(3):
        mono = mc.simulate(scene(d).channel(c), WI, 20_000, mu_edges=MU, phi_edges=PHI,
                           backend="warp-cpu", seed=1)
        assert mono.reflectance == res.reflectance[c]
        assert np.array_equal(mono.bins["top"], res.bins["top"][..., c])


def test_truncated_walks_are_reported():
    d = {"layer": [{"kind": "medium", "albedo": 1.0, "tau": 50.0}]}
    with pytest.warns(RuntimeWarning, match="max_steps"):
        res = run(d, 2000, max_steps=3)
    assert res.truncated > 0
    assert res.absorbed == pytest.approx(res.truncated / res.particles, abs=1e-12)


def test_stack_layout():
    s = layersim.Scene.from_dict({"layer": [
        {"kind": "medium", "albedo": 0.5, "tau": 1.0},
        {"kind": "dielectric", "ior": 1.5, "roughness": [0.1, 0.3], "rotation": 90.0},
        {"kind": "dielectric", "ior": 1.2},
        {"kind": "medium", "albedo": 0.7, "g": 0.3, "tau": 2.0},
        {"kind": "medium", "albedo": 0.9, "tau": 0.5},
        {"kind": "dielectric", "ior": 1.2},          # index-matched: a null boundary
        {"kind": "conductor", "ior": [0.2, 3.0], "roughness": 0.1, "distribution": "ggx"}],
        "stack": {"top_ior": 1.1}})
    st = flatten(s)
    kinds = st.bnd_i[0::3].tolist()
    assert kinds == [walk.NULL, walk.DIELECTRIC, walk.DIELECTRIC, walk.NULL, walk.NULL,
                     walk.CONDUCTOR]
    assert st.n_slabs == 5 and st.opaque
    np.testing.assert_allclose(st.slab_f.reshape(-1, 3), [
        [1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [2.0, 0.7, 0.3], [0.5, 0.9, 0.0], [0.0, 1.0, 0.0]],
        rtol=1e-7)
    f = st.bnd_f.reshape(-1, walk.BND_F)
    assert f[1, :4] == pytest.approx([1.5 / 1.1, 0, 0.1, 0.3])
    assert f[1, 4:6] == pytest.approx([0, 1], abs=1e-7)          # rotated 90 degrees
    assert f[2, 0] == pytest.approx(1.2 / 1.5)
    assert f[5, :2] == pytest.approx([0.2 / 1.2, 3.0 / 1.2])
    assert st.bnd_i[1::3].tolist()[5] == 1                         # ggx


# ------------------------------------------------------------------------------------------------
# Bad input
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("wi, msg", [
    ([0, 0, 1, 0], "shape"), ([[0, 0, 1]], "shape"), ([0, 0, 2], "unit"),
    ([1, 0, 0], "non-zero"), ([0, 0, np.nan], "finite"), ("up", "direction")])
def test_bad_wi(wi, msg):
    with pytest.raises(ValueError, match=msg):
        mc.simulate(scene(SLAB), wi, 10)


def test_light_from_below_an_opaque_stack():
    with pytest.raises(ValueError, match="opaque"):
        mc.simulate(scene(COATED), [0, 0, -1], 10)


@pytest.mark.parametrize("n", [0, -5, 2.5, True, "10"])
def test_bad_particles(n):
    with pytest.raises(ValueError, match="particles"):
        mc.simulate(scene(SLAB), WI, n)


@pytest.mark.parametrize("kw, msg", [
    (dict(mu_edges=[0.5]), "at least 2"), (dict(mu_edges=[0, 0.5, 0.5, 1]), "increasing"),
    (dict(mu_edges=[-0.1, 1]), r"\[0, 1\]"), (dict(phi_edges=[0, 7]), "phi_o"),
    (dict(mu_edges=[[0, 1]]), "1-D"), (dict(phi_edges=[0, np.inf]), "finite"),
    (dict(seed=-1), "seed"), (dict(seed=2 ** 64), "seed"), (dict(batch_size=0), "batch_size"),
    (dict(target_stderr=0.0), "target_stderr"), (dict(max_steps=0), "max_steps")])
def test_bad_options(kw, msg):
    with pytest.raises(ValueError, match=msg):
        mc.simulate(scene(SLAB), WI, 10, **kw)


def test_scene_must_be_validated():
    with pytest.raises(TypeError, match="Scene"):
        mc.simulate(SLAB, WI, 10)
