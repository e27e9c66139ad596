"""The Warp -> OpenCL translator: every translated function agrees with its Warp original.

Each case evaluates one physics / sampling / rng function on random inputs with Warp (CPU) and
with the generated OpenCL C (PoCL here), in float32 (the walk's precision) and, where the device
has fp64, in double (where agreement must be near machine precision, which checks the
translation itself rather than float32 rounding).
"""

import numpy as np
import pytest

from layersim.kernels import opencl_codegen as cg
from layersim.kernels import physics, rng, sampling, walk

from probes import ProbeSet

N = 512


def _unit(r, n, upper=False):
    v = r.normal(size=(n, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    if upper:
        v[:, 2] = np.abs(v[:, 2]) + 1e-3
        v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v


def _u(r, n):
    return r.uniform(1e-6, 1 - 1e-6, n)


def _alpha(r, n):
    return r.uniform(0.05, 1.0, n)


def _dist(r, n):
    return r.integers(0, 2, n)


def _shadow(r, n):
    """Codes of physics.SHADOWING_CODES: separable, height-correlated, its Beta form."""
    return r.integers(0, 3, n)


def _words(r, n):
    return r.integers(0, 2 ** 32, n, dtype=np.uint64).astype(np.uint32)


# (name, function, argument roles, input generator); roles: T scalar, V vec3, i int, u uint
CASES = [
    ("fresnel_dielectric", physics.fresnel_dielectric, "TT",
     lambda r, n: [r.uniform(-1, 1, n), r.uniform(0.4, 2.5, n)]),
    ("fresnel_conductor", physics.fresnel_conductor, "TTT",
     lambda r, n: [r.uniform(0, 1, n), r.uniform(0.1, 3, n), r.uniform(0.5, 5, n)]),
    ("ndf", physics.ndf, "VTTi",
     lambda r, n: [_unit(r, n, True), _alpha(r, n), _alpha(r, n), _dist(r, n)]),
    ("smith_lambda", physics.smith_lambda, "VTTi",
     lambda r, n: [_unit(r, n), _alpha(r, n), _alpha(r, n), _dist(r, n)]),
    ("smith_g1", physics.smith_g1, "VVTTi",
     lambda r, n: [_unit(r, n), _unit(r, n, True), _alpha(r, n), _alpha(r, n), _dist(r, n)]),
    ("microfacet_smooth_q (dielectric)", physics.microfacet_smooth_q, "VVTTTTi",
     lambda r, n: [_unit(r, n), _unit(r, n), r.uniform(1.1, 2.0, n), np.zeros(n),
                   _alpha(r, n), _alpha(r, n), _dist(r, n)]),
    ("microfacet_eval (dielectric)", physics.microfacet_eval, "VVTTTTi",
     lambda r, n: [_unit(r, n), _unit(r, n), r.uniform(1.1, 2.0, n), np.zeros(n),
                   _alpha(r, n), _alpha(r, n), _dist(r, n)]),
    ("microfacet_eval (conductor)", physics.microfacet_eval, "VVTTTTi",
     lambda r, n: [_unit(r, n, True), _unit(r, n, True), r.uniform(0.1, 2.0, n),
                   r.uniform(1, 4, n), _alpha(r, n), _alpha(r, n), _dist(r, n)]),
    ("fresnel_film_dielectric", physics.fresnel_film_dielectric, "TTTT",
     lambda r, n: [r.uniform(-1, 1, n), r.uniform(1.1, 2.0, n), r.uniform(1.0, 2.5, n),
                   r.uniform(0.0, 40.0, n)]),
    ("fresnel_film_conductor", physics.fresnel_film_conductor, "TTTTT",
     lambda r, n: [r.uniform(0, 1, n), r.uniform(0.1, 3, n), r.uniform(0.5, 5, n),
                   r.uniform(1.0, 2.5, n), r.uniform(0.0, 40.0, n)]),
    ("microfacet_eval_film (dielectric)", physics.microfacet_eval_film, "VVTTTTTTi",
     lambda r, n: [_unit(r, n), _unit(r, n), r.uniform(1.1, 2.0, n), np.zeros(n),
                   r.uniform(1.0, 2.5, n), r.uniform(0.0, 40.0, n), _alpha(r, n),
                   _alpha(r, n), _dist(r, n)]),
    ("log_gamma", physics.log_gamma, "T", lambda r, n: [r.uniform(1.0, 30.0, n)]),
    ("smith_g2", physics.smith_g2, "VVVTTii",
     lambda r, n: [_unit(r, n), _unit(r, n), _unit(r, n, True), _alpha(r, n), _alpha(r, n),
                   _dist(r, n), _shadow(r, n)]),
    ("microfacet_eval_shadowed (dielectric)", physics.microfacet_eval_shadowed, "VVTTTTTTii",
     lambda r, n: [_unit(r, n), _unit(r, n), r.uniform(1.1, 2.0, n), np.zeros(n),
                   np.zeros(n), np.zeros(n), _alpha(r, n), _alpha(r, n), _dist(r, n),
                   _shadow(r, n)]),
    ("lambert_eval", physics.lambert_eval, "VVT",
     lambda r, n: [_unit(r, n), _unit(r, n), r.uniform(0, 1, n)]),
    ("hg_eval", physics.hg_eval, "TT",
     lambda r, n: [r.uniform(-1, 1, n), r.uniform(-0.95, 0.95, n)]),
    ("orthonormal_basis", sampling.orthonormal_basis, "V", lambda r, n: [_unit(r, n)]),
    ("to_tangent_frame", sampling.to_tangent_frame, "VTT",
     lambda r, n: [_unit(r, n), *(lambda a: [np.cos(a), np.sin(a)])(r.uniform(0, 6.3, n))]),
    ("refract", sampling.refract, "VVT",
     lambda r, n: [_unit(r, n), _unit(r, n, True), r.uniform(0.4, 2.5, n)]),
    ("sample_cosine_hemisphere", sampling.sample_cosine_hemisphere, "TT",
     lambda r, n: [_u(r, n), _u(r, n)]),
    ("sample_hg", sampling.sample_hg, "VTTT",
     lambda r, n: [_unit(r, n), r.uniform(-0.95, 0.95, n), _u(r, n), _u(r, n)]),
    ("sample_vndf_ggx", sampling.sample_vndf_ggx, "VTTTT",
     lambda r, n: [_unit(r, n, True), _alpha(r, n), _alpha(r, n), _u(r, n), _u(r, n)]),
    ("beckmann_visible_slope", sampling.beckmann_visible_slope, "TT",
     lambda r, n: [np.exp(r.uniform(-6, 6, n)), _u(r, n)]),
    ("sample_vndf_beckmann", sampling.sample_vndf_beckmann, "VTTTTT",
     lambda r, n: [_unit(r, n, True), _alpha(r, n), _alpha(r, n), _u(r, n), _u(r, n),
                   _u(r, n)]),
    ("sample_microfacet", sampling.sample_microfacet, "VTTTTiTTTT",
     lambda r, n: [_unit(r, n), r.uniform(1.1, 2.0, n), np.zeros(n), _alpha(r, n),
                   _alpha(r, n), _dist(r, n), _u(r, n), _u(r, n), _u(r, n), _u(r, n)]),
    ("sample_microfacet_film", sampling.sample_microfacet_film, "VTTTTTTiTTTT",
     lambda r, n: [_unit(r, n, True), r.uniform(0.1, 2.0, n), r.uniform(1, 4, n),
                   r.uniform(1.0, 2.5, n), r.uniform(0.0, 40.0, n), _alpha(r, n),
                   _alpha(r, n), _dist(r, n), _u(r, n), _u(r, n), _u(r, n), _u(r, n)]),
    ("sample_microfacet_shadowed", sampling.sample_microfacet_shadowed, "VTTTTTTiiTTTT",
     lambda r, n: [_unit(r, n), r.uniform(1.1, 2.0, n), np.zeros(n), np.zeros(n),
                   np.zeros(n), _alpha(r, n), _alpha(r, n), _dist(r, n), _shadow(r, n),
                   _u(r, n), _u(r, n), _u(r, n), _u(r, n)]),
    ("microfacet_pdf", sampling.microfacet_pdf, "VVTTTTi",
     lambda r, n: [_unit(r, n), _unit(r, n), r.uniform(1.1, 2.0, n), np.zeros(n),
                   _alpha(r, n), _alpha(r, n), _dist(r, n)]),
    ("sample_smooth", sampling.sample_smooth, "VTTT",
     lambda r, n: [_unit(r, n), r.uniform(1.1, 2.0, n), np.zeros(n), _u(r, n)]),
    ("philox4x32_10", rng.philox4x32_10, "uuuuuu", lambda r, n: [_words(r, n) for _ in range(6)]),
    ("uniform4", rng.uniform4, "uuuuu", lambda r, n: [_words(r, n) for _ in range(5)]),
]

_ROLE = {"float": {"T": "float", "V": "float3", "i": "int", "u": "uint"},
         "double": {"T": "double", "V": "double3", "i": "int", "u": "uint"}}
_INTEGER_ONLY = {"philox4x32_10", "uniform4"}


def _cases(real):
    out = []
    for name, func, roles, gen in CASES:
        if real == "double" and set(roles) <= {"u"}:
            continue
        out.append((name, func, [_ROLE[real][c] for c in roles], gen))
    return out


@pytest.fixture(scope="module")
def probes(tmp_path_factory, cl_device):
    reals = ["float"] + (["double"] if "cl_khr_fp64" in cl_device.extensions else [])
    table = [(real, c) for real in reals for c in _cases(real)]
    ps = ProbeSet([(f, t) for _, (_, f, t, _) in table], tmp_path_factory.mktemp("probes"),
                  cl_device)
    return ps, table


@pytest.mark.slow
def test_translated_functions_agree_with_warp(probes):
    ps, table = probes
    failures = []
    for i, (real, (name, func, types, gen)) in enumerate(table):
        r = np.random.default_rng(1234 + i)
        inputs = gen(r, N)
        want = ps.warp(i, *inputs)
        got = ps.opencl(i, *inputs)
        for j, (a, b) in enumerate(zip(got, want)):
            if a.dtype.kind in "ui":
                ok = np.array_equal(a, b)
                err = "integer mismatch"
            else:
                # float32: a few hundred ulps (sampling chains amplify rounding); double: the
                # translation itself must be exact up to libm differences
                rtol, atol = (2e-4, 2e-4) if real == "float" else (1e-10, 1e-12)
                scale = np.max(np.abs(b)) if b.size else 1.0
                bad = ~np.isclose(a, b, rtol=rtol, atol=atol * scale)
                ok = np.all(np.isfinite(a) == np.isfinite(b)) and not np.any(bad)
                err = f"{np.count_nonzero(bad)} of {bad.size} outside rtol {rtol:g}"
            if not ok:
                failures.append(f"{name} [{real}] result {j}: {err}")
    assert not failures, "\n".join(failures)


def test_kernel_entry_and_source_shape():
    prog = cg.Program()
    assert prog.add_kernel(walk.walk_thread, name="walk") == "walk"
    src = prog.source()
    assert "__kernel void walk(" in src
    assert "cl_khr_int64_base_atomics" in src and "cl_khr_fp64" not in src
    # one definition per specialisation, callees before callers
    assert src.index("ls_rng_philox4x32_10(") < src.index("ls_walk_walk_particle(")
    assert src.count("float ls_physics_smith_lambda_f3ffi(") == 1


def test_generic_functions_are_specialised_per_type():
    prog = cg.Program()
    f = prog.add_function(physics.fresnel_dielectric, ["float", "float"])
    d = prog.add_function(physics.fresnel_dielectric, ["double", "double"])
    assert f != d and prog.returns(physics.fresnel_dielectric, ["double", "double"]) == ["double"]
    assert "cl_khr_fp64" in prog.source()


def test_unsupported_constructs_are_rejected(tmp_path):
    import importlib.util
    import sys

    src = (
        "import warp as wp\n"
        "@wp.func\n"
        "def power(x: wp.float32):\n"
        "    return x ** wp.float32(2.0)\n"
        "@wp.func\n"
        "def mixed(x: wp.float32, i: int):\n"
        "    return x * i\n"
        "@wp.func\n"
        "def retype(x: wp.float32):\n"
        "    y = x\n"
        "    y = int(1)\n"
        "    return y\n")
    path = tmp_path / "cg_bad_funcs.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location("cg_bad_funcs", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["cg_bad_funcs"] = mod
    spec.loader.exec_module(mod)
    for func, args, msg in ((mod.power, ["float"], "operator"),
                            (mod.mixed, ["float", "int"], "mixed types"),
                            (mod.retype, ["float"], "changes type")):
        with pytest.raises(cg.CodegenError, match=msg):
            cg.Program().add_function(func, args)
    with pytest.raises(cg.CodegenError, match="called with"):
        cg.Program().add_function(physics.ndf_peak, ["float", "float"])
