"""The .bsdf (SCATFUN) file format: byte layout against an independent reader written from
pbrt-v3's FourierBSDFTable::Read, a hand-computed Lambertian table, round trips (v1, v2, RGB),
the renderer-faithful evaluation against our eval, and rejection of corrupt files."""

import json
import struct

import numpy as np
import pytest

import layersim
from layersim import FileFormatError, InfeasibleError, bsdffile
from layersim.solved.channels import LUMINANCE, green_from_ybr

from conftest import random_directions, unit

GOLD_RGB = [[0.143552, 3.98397], [0.377438, 2.38495], [1.43825, 1.60434]]


def pbrt_read(data: bytes) -> dict:
    """Transcription of pbrt-v3's FourierBSDFTable::Read (little-endian): the header is read
    field by field, then mu, cdf, the offset/length table and the coefficients, in this order;
    metadata follows (pbrt ignores it, layerlab reads nMetadataBytes)."""
    pos = 0

    def read(fmt, count=1):
        nonlocal pos
        vals = struct.unpack_from("<" + fmt * count, data, pos)
        pos += struct.calcsize("<" + fmt * count)
        return vals if count > 1 else vals[0]

    out = {"header": data[:8]}
    pos = 8
    out["flags"], out["nMu"], out["nCoeffs"], out["mMax"], out["nChannels"], out["nBases"] = \
        (read("i") for _ in range(6))
    out["nMetadataBytes"], out["nParameters"], out["nParameterValues"] = read("i", 3)
    out["eta"] = read("f")
    out["alpha"] = read("f", 2)
    out["unused"] = read("f", 2)
    assert pos == 64
    n = out["nMu"]
    out["mu"] = np.array(read("f", n))
    out["cdf"] = np.array(read("f", n * n)).reshape(n, n)
    ol = np.array(read("i", 2 * n * n)).reshape(n * n, 2)
    out["aOffset"], out["m"] = ol[:, 0], ol[:, 1]
    out["a"] = np.array(read("f", out["nCoeffs"]))
    out["metadata"] = data[pos:pos + out["nMetadataBytes"]].decode()
    out["end"] = pos + out["nMetadataBytes"]
    return out


@pytest.fixture(scope="module")
def lambertian():
    return layersim.solve(layersim.Scene.from_dict({"layer": [{"kind": "diffuse",
                                                                "albedo": 0.6}]}))


def test_lambertian_file_matches_the_hand_computed_layout(tmp_path, lambertian):
    path = tmp_path / "lambert.bsdf"
    layersim.export(lambertian, path)
    data = path.read_bytes()
    t = pbrt_read(data)
    grid = lambertian.grid
    h = grid.h
    N = 2 * h + 2
    # header as pbrt-v3 requires it: version 1, flags 1, one basis, no parameters
    assert t["header"] == b"SCATFUN\x01"
    assert (t["flags"], t["nMu"], t["nChannels"], t["nBases"], t["nParameters"],
            t["nParameterValues"], t["mMax"], t["eta"]) == (1, N, 1, 1, 0, 0, 1, 1.0)
    assert t["end"] == len(data)
    assert len(data) == 64 + 4 * N + 4 * N * N + 8 * N * N + 4 * t["nCoeffs"] \
        + t["nMetadataBytes"]
    np.testing.assert_array_equal(t["mu"], np.concatenate(
        [-grid.mu[::-1], [0, 0], grid.mu]).astype(np.float32))
    # our normalisation of a Lambertian layer: f = albedo / (2 pi sum_j w_j mu_j) (= albedo / pi
    # up to the rule's O(1/n^2)); the file stores a_0 = f |mu_o| for every top-reflection pair
    f = 0.6 / (2 * np.pi * grid.flux_weight.sum())
    assert f == pytest.approx(0.6 / np.pi, rel=1e-3)
    m = t["m"].reshape(N, N)                                     # [i, o]
    a0 = np.where(t["m"] > 0, t["a"][np.minimum(t["aOffset"], t["nCoeffs"] - 1)], 0.0)
    a0 = a0.reshape(N, N)
    expected = np.zeros((N, N))
    expected[h + 2:, :h] = f * grid.mu[::-1][None, :]            # light from above, leaving up
    np.testing.assert_array_equal(m, (expected > 0).astype(int))
    np.testing.assert_allclose(a0, expected, rtol=1.2e-7, atol=0)        # float32 rounding
    # the CDF integrates a_0 over mu_o with Catmull-Rom splines (exact for this linear profile)
    np.testing.assert_allclose(t["cdf"][h + 2:, -1], f / 2, rtol=1e-6)
    np.testing.assert_array_equal(t["cdf"][:h + 2, :], 0.0)
    meta = json.loads(t["metadata"])
    assert meta["layersim"]["rule"] == grid.rule and meta["layersim"]["opaque"]


def test_round_trip_reproduces_eval_to_float32(tmp_path, coated_gold, rough_glass):
    rng = np.random.default_rng(0)
    wi = np.concatenate([random_directions(rng, 2000), random_directions(rng, 2000, lower=True)])
    wo = np.concatenate([random_directions(rng, 2000), random_directions(rng, 2000, lower=True)])
    rng.shuffle(wo)
    for bsdf in (coated_gold, rough_glass):
        for version in (1, 2):
            path = tmp_path / f"v{version}.bsdf"
            table = layersim.export(bsdf, path, version=version)
            assert path.stat().st_size == table.nbytes()
            again = bsdffile.read(path).to_bsdf()
            f, g = bsdf.eval(wi, wo), again.eval(wi, wo)
            assert np.max(np.abs(f - g)) <= 1e-7 * np.max(np.abs(f))
            np.testing.assert_allclose(again.albedo(wi[:50]), bsdf.albedo(wi[:50]), rtol=1e-6)


def test_renderer_evaluation_agrees_with_ours(tmp_path, rough_glass):
    """pbrt-v3 evaluates the table adjointly (camera as the file's incident direction, eta^2 in
    transmission). At ordinate directions no interpolation is involved: it must equal our
    f(wo, wi) times (eta_wi / eta_wo)^2 -- our f(wi, wo) by generalized reciprocity -- to float32
    precision; between ordinates it differs by the interpolation error only."""
    table = bsdffile.read(layersim.export(rough_glass, tmp_path / "glass.bsdf") and tmp_path / "glass.bsdf")
    mu = rough_glass.grid.mu
    rng = np.random.default_rng(1)
    k_i, k_o = rng.integers(2, mu.size, 400), rng.integers(2, mu.size, 400)
    zi = mu[k_i] * rng.choice([-1, 1], 400)
    zo = mu[k_o] * rng.choice([-1, 1], 400)
    pi, po = rng.uniform(0, 2 * np.pi, (2, 400))
    wi = np.stack([np.sqrt(1 - zi**2) * np.cos(pi), np.sqrt(1 - zi**2) * np.sin(pi), zi], -1)
    wo = np.stack([np.sqrt(1 - zo**2) * np.cos(po), np.sqrt(1 - zo**2) * np.sin(po), zo], -1)
    ours_adjoint = rough_glass.eval(wo, wi)
    eta_i = np.where(wi[:, 2] > 0, 1.0, 1.5)
    eta_o = np.where(wo[:, 2] > 0, 1.0, 1.5)
    expected = np.maximum(ours_adjoint, 0) * (eta_o / eta_i) ** 2
    np.testing.assert_allclose(table.eval(wi, wo), expected, rtol=2e-5,
                               atol=1e-6 * expected.max())
    # between ordinates, on the lobes: interpolation error only
    wi, wo = random_directions(rng, 3000, min_z=0.2), random_directions(rng, 3000, min_z=0.2)
    wo[1500:, 2] *= -1
    f = rough_glass.eval(wi, wo)
    lobe = f > 0.05 * f.max()
    assert np.median(np.abs(table.eval(wi, wo)[lobe] / f[lobe] - 1)) < 1e-3


def test_rgb_files_store_luminance_red_blue(tmp_path):
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
        {"kind": "conductor", "roughness": 0.3, "ior": GOLD_RGB}],
        "discretization": {"n": 48, "md": 64}})
    bsdf = layersim.solve(scene)
    table = layersim.export(bsdf, tmp_path / "gold.bsdf")
    t = pbrt_read((tmp_path / "gold.bsdf").read_bytes())
    assert t["nChannels"] == 3
    # one pair: its three blocks are Y, R, B of our coefficients times |mu_o|
    h = bsdf.grid.h
    N = 2 * h + 2
    o, i = 5, 7
    p = (h + 2 + i) * N + (h - 1 - o)                 # Rt[o, i]
    L = t["m"][p]
    blocks = t["a"][t["aOffset"][p]:t["aOffset"][p] + 3 * L].reshape(3, L)
    coef = np.stack([op.coefficients("Rt", l)[o, i] for op in bsdf.operators
                     for l in range(L)]).reshape(3, L) * bsdf.grid.mu[o]
    np.testing.assert_allclose(blocks[0], LUMINANCE @ coef, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(blocks[1:], coef[[0, 2]], rtol=1e-6, atol=1e-9)
    # round trip of all three channels (green reconstructed from Y, R, B)
    again = bsdffile.read(tmp_path / "gold.bsdf").to_bsdf()
    rng = np.random.default_rng(2)
    wi, wo = random_directions(rng, 1000), random_directions(rng, 1000)
    f, g = bsdf.eval(wi, wo), again.eval(wi, wo)
    assert f.shape == g.shape == (1000, 3)
    assert np.max(np.abs(f - g)) <= 1e-6 * np.max(np.abs(f))
    r = table.eval(wi, wo)
    assert r.shape == (1000, 3) and np.all(r >= 0)


def test_unscattered_transmission_survives_the_round_trip(tmp_path):
    bsdf = layersim.solve(layersim.Scene.from_dict({"layer": [
        {"kind": "medium", "albedo": 0.5, "tau": 0.3}]}))
    again = bsdffile.read(layersim.export(bsdf, tmp_path / "m.bsdf") and tmp_path / "m.bsdf").to_bsdf()
    wi = unit(35.0, 60.0)
    np.testing.assert_allclose(again.albedo(wi), bsdf.albedo(wi), rtol=1e-6)


def test_version_2_layout(tmp_path, rough_glass):
    table = layersim.export(rough_glass, tmp_path / "v2.bsdf", version=2)
    data = (tmp_path / "v2.bsdf").read_bytes()
    (magic, version, flags, N, n_coef, ms, md, nch, nb, nmeta, npar, npv, eta, a0, a1,
     unused) = struct.unpack_from("<7sB10If2ff", data)
    assert (magic, version, flags, nch, nb, npar, npv) == (b"SCATFUN", 2, 1, 1, 1, 0, 0)
    assert ms == 1 and md == rough_glass.operators[0].m and eta == pytest.approx(1.5)
    n_marg = ms // 2 + 1
    assert len(data) == 64 + 4 * N + 4 * n_marg * N * N + 12 * N * N + 4 * n_coef + nmeta
    off = 64 + 4 * N + 4 * n_marg * N * N
    tab = np.frombuffer(data, "<u4", 3 * N * N, off).reshape(N * N, 3)
    assert set(np.unique(tab[:, 1])) <= {0, 1}
    # an isotropic pair in v2 holds c_00 = a_0 and c_0d = a_d / 2 of the v1 file
    v1 = bsdffile.read(layersim.export(rough_glass, tmp_path / "v1.bsdf") and tmp_path / "v1.bsdf")
    p = int(np.argmax(v1.shape))
    a = v1.coef[v1.offsets[p]:v1.offsets[p] + v1.shape[p]]
    c = table.coef[table.offsets[p]:table.offsets[p] + table.shape[p, 1]]
    np.testing.assert_allclose(c, np.r_[a[0], a[1:] / 2], rtol=1e-6)


def _file_series(c, s, ps, pd):
    """``2 sum_{s, d >= 0} Re(c_sd e^{i(s ps + d pd)}) - sum_s Re(c_s0 e^{i s ps})`` for a
    (ms, md) block ``c`` (rows ``s``), written from the Layer Laboratory's
    ``eval_fourier_series_2d`` with complex coefficients; ps, pd broadcast (..., 1, 1)."""
    e = np.exp(1j * (s[:, None] * ps + np.arange(c.shape[1])[None, :] * pd))
    return 2 * np.sum((c * e).real, axis=(-2, -1)) - np.sum((c[:, 0] * e[..., 0]).real, axis=-1)


@pytest.mark.parametrize("imag", [False, True])
def test_version_2_series_are_evaluated_with_the_2d_formula(imag):
    """A synthetic v2 table whose pairs all hold the same 3 x 2 series (real, as the Layer
    Laboratory writes, or complex with flag 0x04): between the inner nodes the interpolated
    series is that series, and eval must follow the 2D formula of the module docstring with
    the plugin's azimuths (camera; reversed light). Foreign nodes are refused for conversion."""
    mu = np.linspace(0.1, 1.0, 10)
    nodes = bsdffile.file_nodes(mu)
    N = nodes.size
    c = np.array([[0.01, 0.02], [0.3, 0.05], [0.01, 0.02]])               # s = -1, 0, 1
    if imag:
        c = c + 1j * np.array([[0.02, -0.01], [0.0, 0.04], [-0.02, 0.03]])
    shape = np.zeros((N * N, 2), np.uint32)
    full = np.ones((N, N), bool)
    full[[N // 2 - 1, N // 2], :] = full[:, [N // 2 - 1, N // 2]] = False
    shape[full.ravel()] = (3, 2)
    parts = 2 if imag else 1
    size = parts * shape[:, 0] * shape[:, 1]
    offsets = np.r_[0, np.cumsum(size)[:-1]].astype(np.uint32)
    block = np.r_[c.real.ravel(), c.imag.ravel()] if imag else c.real.ravel()
    coef = np.tile(block.astype(np.float32), int(full.sum()))
    flags = bsdffile.FLAG_BSDF | (bsdffile.FLAG_COMPLEX if imag else 0)
    cdf = np.zeros(N * N * (3 if imag else 2), np.float32)
    table = bsdffile.FourierTable(2, nodes, offsets, shape, coef, cdf, 1, flags=flags)
    again = bsdffile.FourierTable.from_bytes(table.to_bytes())
    assert again.is_complex == imag and again.anisotropic
    wi, wo = unit(40.0, 30.0), unit(50.0, 100.0)
    phi_i, phi_o = np.arctan2(wo[1], wo[0]), np.arctan2(-wi[1], -wi[0])
    val = _file_series(c, np.array([-1, 0, 1]), phi_o + phi_i, phi_o - phi_i)
    assert again.eval(wi, wo) == pytest.approx(val / wi[2], rel=1e-6)
    if imag:       # the sine terms are there: the real parts alone give another value
        assert abs(_file_series(c.real, np.array([-1, 0, 1]), phi_o + phi_i,
                                phi_o - phi_i) - val) > 1e-3
    with pytest.raises(FileFormatError, match="gauss-lobatto"):
        again.to_bsdf()


@pytest.mark.parametrize("mutate,match", [
    (lambda d: d[:40], "truncated header"),
    (lambda d: b"SCATFUX" + d[7:], "identifier"),
    (lambda d: d[:7] + b"\x07" + d[8:], "version 7"),
    (lambda d: d[:-1], "size mismatch"),
    (lambda d: d + b"\0", "size mismatch"),
    (lambda d: d[:8] + struct.pack("<I", 0) + d[12:], "flag 0x01"),
    (lambda d: d[:8] + struct.pack("<I", 3) + d[12:], "harmonic"),
    (lambda d: d[:24] + struct.pack("<I", 2) + d[28:], "channels"),
    (lambda d: d[:28] + struct.pack("<I", 4) + d[32:], "textured"),
    (lambda d: d[:12] + struct.pack("<I", 0xFFFFFFF0) + d[16:], "size mismatch"),
])
def test_corrupt_files_are_rejected(tmp_path, lambertian, mutate, match):
    data = layersim.export(lambertian, tmp_path / "ok.bsdf").to_bytes()
    with pytest.raises(FileFormatError, match=match):
        bsdffile.FourierTable.from_bytes(mutate(data))


def test_corrupt_offset_table_is_rejected(tmp_path, lambertian):
    table = layersim.export(lambertian, tmp_path / "ok.bsdf")
    data = bytearray(table.to_bytes())
    N = table.n_nodes
    start = 64 + 4 * N + 4 * N * N
    p = int(np.flatnonzero(table.shape)[-1])
    struct.pack_into("<I", data, start + 8 * p, table.coef.size)      # offset past the end
    with pytest.raises(FileFormatError, match="offset table"):
        bsdffile.FourierTable.from_bytes(bytes(data))
    data = bytearray(table.to_bytes())
    struct.pack_into("<f", data, start + 8 * N * N, float("nan"))     # first coefficient
    with pytest.raises(FileFormatError, match="non-finite"):
        bsdffile.FourierTable.from_bytes(bytes(data))
    (tmp_path / "junk.bsdf").write_bytes(b"SCATFUN\x01" + bytes(100))
    with pytest.raises(FileFormatError, match="junk.bsdf"):
        bsdffile.read(tmp_path / "junk.bsdf")
    with pytest.raises(FileFormatError, match="cannot read"):
        bsdffile.read(tmp_path / "missing.bsdf")


def test_foreign_nodes_are_refused_for_conversion_but_evaluated(tmp_path, lambertian):
    table = layersim.export(lambertian, tmp_path / "ok.bsdf")
    table.metadata = ""
    h = lambertian.grid.h
    table.nodes[h + 2:] = np.linspace(0.05, 1.0, h).astype(np.float32)
    table.nodes[:h] = -table.nodes[h + 2:][::-1]
    again = bsdffile.FourierTable.from_bytes(table.to_bytes())
    with pytest.raises(FileFormatError, match="Gauss-Lobatto|gauss-lobatto"):
        again.to_bsdf()
    assert again.eval(unit(30.0), unit(40.0, 200.0)) > 0


# ---- anisotropic stacks in version 2 ------------------------------------------------------

ANISO_SCENES = {
    # aligned: real coefficients, the Layer Laboratory's layout bit for bit
    "brushed": {"layer": [{"kind": "conductor", "ior": [0.2, 3.0], "roughness": [0.4, 0.2]}],
                "discretization": {"n": 24, "md": 10}},
    # rotated tangent frame, transmissive (all four blocks, eta 1.5): complex coefficients
    "rotated": {"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": [0.3, 0.5],
                           "rotation": 25}], "discretization": {"n": 24, "md": 10}},
    "rgb": {"layer": [{"kind": "conductor", "ior": GOLD_RGB, "roughness": [0.4, 0.2],
                       "rotation": -40}], "discretization": {"n": 24, "md": 10}},
}


@pytest.fixture(scope="module")
def aniso(tmp_path_factory):
    """The three anisotropic stacks solved and exported (default version: 2), once."""
    d = tmp_path_factory.mktemp("aniso")
    out = {}
    for name, scene in ANISO_SCENES.items():
        bsdf = layersim.solve(layersim.Scene.from_dict(scene))
        table = layersim.export(bsdf, d / f"{name}.bsdf")
        out[name] = (bsdf, table, d / f"{name}.bsdf")
    return out


def _ordinate_directions(rng, mu, n, opaque):
    """Directions at the ordinates' elevations (either side unless opaque), random azimuths."""
    z = mu[rng.integers(0, mu.size, (2, n))]
    if not opaque:
        z = z * rng.choice([-1, 1], (2, n))
    ph = rng.uniform(0, 2 * np.pi, (2, n))
    s = np.sqrt(1 - z ** 2)
    return tuple(np.stack([s[k] * np.cos(ph[k]), s[k] * np.sin(ph[k]), z[k]], -1)
                 for k in range(2))


@pytest.mark.parametrize("name", list(ANISO_SCENES))
def test_anisotropic_round_trip_reproduces_eval_to_float32(aniso, name):
    """export -> read -> to_bsdf -> eval equals the solver's eval to float32 precision at random
    direction pairs (both sides); the renderer's adjoint evaluation of the file equals our
    f(wo, wi) (eta_wo / eta_wi)^2 at the ordinates' elevations and any azimuths."""
    bsdf, table, path = aniso[name]
    assert table.version == 2 and path.stat().st_size == table.nbytes()
    assert table.is_complex == (name != "brushed")            # rotated frames: sine terms
    again = bsdffile.read(path)
    back = again.to_bsdf()
    assert back.anisotropic and back.channels == bsdf.channels
    assert back.operators[0].md == bsdf.operators[0].md
    rng = np.random.default_rng(5)
    wi = np.concatenate([random_directions(rng, 1500), random_directions(rng, 1500, lower=True)])
    wo = np.concatenate([random_directions(rng, 1500), random_directions(rng, 1500, lower=True)])
    rng.shuffle(wo)
    f, g = bsdf.eval(wi, wo), back.eval(wi, wo)
    assert np.max(np.abs(f)) > 0.1
    assert np.max(np.abs(f - g)) <= 1e-7 * np.max(np.abs(f))
    np.testing.assert_allclose(back.albedo(wi[:40]), bsdf.albedo(wi[:40]), rtol=1e-6,
                               atol=1e-9)
    # the renderer's evaluation of the table itself (no layersim operator involved)
    wi, wo = _ordinate_directions(rng, bsdf.grid.mu, 800, bsdf.opaque)
    eta_b = 1.0 if bsdf.opaque else 1.5
    ratio = (np.where(wo[:, 2] > 0, 1.0, eta_b) / np.where(wi[:, 2] > 0, 1.0, eta_b)) ** 2
    f = bsdf.interpolant(wo, wi)      # the file holds the series, not eval's positive part
    if f.ndim == 2:        # renderers clamp Y at 0 before they reconstruct G, then clamp RGB
        y = np.maximum(f @ LUMINANCE, 0)
        f = np.stack([f[:, 0], green_from_ybr(y, f[:, 0], f[:, 2]), f[:, 2]], -1)
        ratio = ratio[:, None]
    expected = np.maximum(f, 0) * ratio
    np.testing.assert_allclose(again.eval(wi, wo), expected, rtol=2e-5,
                               atol=1e-6 * expected.max())


def test_version_2_anisotropic_layout(aniso):
    """Header fields, the exact file size, the offset table and one pair's coefficients of a
    complex v2 file, read with struct against the module docstring's layout; the pair's values
    against the operator's complex coefficients (layersim.aniso.basis.complex_entries)."""
    from layersim.aniso import basis
    bsdf, table, path = aniso["rotated"]
    data = path.read_bytes()
    (magic, version, flags, N, n_coef, ms_max, md_max, nch, nb, nmeta, npar, npv, eta, a0, a1,
     unused) = struct.unpack_from("<7sB10If2ff", data)
    op = bsdf.operators[0]
    h = op.h
    assert (magic, version, flags, nch, nb, npar, npv) == (b"SCATFUN", 2, 5, 1, 1, 0, 0)
    assert N == 2 * h + 2 and eta == pytest.approx(1.5) and (a0, a1, unused) == (0, 0, 0)
    assert ms_max % 2 == 1 and ms_max >= 2 * op.ms + 1 and md_max == op.md
    M = ms_max // 2 + 1 + ms_max // 2                   # cosines and (flag 0x04) sines
    assert len(data) == 64 + 4 * N + 4 * M * N * N + 12 * N * N + 4 * n_coef + nmeta
    off = 64 + 4 * N + 4 * M * N * N
    tab = np.frombuffer(data, "<u4", 3 * N * N, off).reshape(N * N, 3).astype(np.int64)
    assert tab[:, 1].max() == ms_max and tab[:, 2].max() == md_max
    assert np.all((tab[:, 1] % 2 == 1) | (tab[:, 1] * tab[:, 2] == 0))
    per_pair = 2 * tab[:, 1] * tab[:, 2]                 # real and imaginary parts, 1 channel
    np.testing.assert_array_equal(tab[:, 0], np.r_[0, np.cumsum(per_pair)[:-1]])
    assert per_pair.sum() == n_coef
    coef = np.frombuffer(data, "<f4", n_coef, off + 12 * N * N)
    # Rt[o, i] is file pair (h + 2 + i) N + (h - 1 - o)
    o, i = 4, 9
    p = (h + 2 + i) * N + (h - 1 - o)
    ms, md = tab[p, 1:]
    block = coef[tab[p, 0]:tab[p, 0] + 2 * ms * md].astype(float).reshape(2, ms, md)
    stored = block[0] + 1j * block[1]                    # [s + ms // 2, d]
    G = op.coefficients("Rt").tocsr()
    S = basis.n_slots(op.md)
    rows, cols = np.arange(S) * h + o, np.arange(S) * h + i
    sub = G[rows][:, cols].tocoo()
    full = {}                                            # f_{d,s} over all d, s
    for (l, k), v in basis.complex_entries(sub.row, sub.col, sub.data).items():
        d, s = (l + k) // 2, (l - k) // 2
        full[(d, s)], full[(-d, -s)] = v, np.conj(v)
    want = np.zeros((ms, md), complex)
    for (d, s), v in full.items():
        if d >= 0 and v != 0:
            want[s + ms // 2, d] = v * op.grid.mu[o]
    assert np.abs(want.imag).max() > 1e-3 * np.abs(want).max()
    np.testing.assert_allclose(stored, want, rtol=1e-6, atol=1e-7 * np.abs(want).max())


def test_version_2_marginal_table_integrates_the_azimuthal_average(aniso):
    """The marginal table of a complex file: for every incident node, its entries evaluated at
    phi_i (cosines and sines in 2 phi_i) equal the Catmull-Rom integral over mu_o of the file's
    series averaged over the outgoing azimuth (trapezoid rule, exact for these series)."""
    bsdf, table, path = aniso["rotated"]
    t = bsdffile.read(path)
    N = t.n_nodes
    ms_max = t.max_order[0]
    J = ms_max // 2
    M = bsdffile.n_marginal(ms_max, t.flags)
    assert M == 2 * J + 1 and t.cdf.size == N * N * M
    phi_i = np.array([0.3, 1.1, 2.5])
    phi_o = np.linspace(0, 2 * np.pi, 4 * (ms_max + t.max_order[1]), endpoint=False)
    avg = np.zeros((phi_i.size, N, N))                   # [phi_i, i, o]
    for p in np.flatnonzero(t.pair_size):
        ms, md = t.shape[p]
        c = t.coef[t.offsets[p]:t.offsets[p] + 2 * ms * md].astype(float).reshape(2, ms, md)
        vals = _file_series(c[0] + 1j * c[1], np.arange(ms) - ms // 2,
                            (phi_o[None, :] + phi_i[:, None])[..., None, None],
                            (phi_o[None, :] - phi_i[:, None])[..., None, None])
        avg[:, p // N, p % N] = vals.mean(axis=1)
    want = bsdffile.integrate_catmull_rom(t.nodes.astype(float), avg)        # [phi_i, i, o]
    cdf = t.cdf.reshape(N, N, M).transpose(1, 0, 2)                           # [i, o, j]
    j = np.arange(J + 1)
    basis_ = np.concatenate([np.cos(2 * j[None, :] * phi_i[:, None]),
                             np.sin(2 * j[None, 1:] * phi_i[:, None])], axis=1)
    got = np.einsum("ioj,qj->qio", cdf, basis_)
    assert np.abs(want).max() > 0.1
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6 * np.abs(want).max())
    # the sine half matters for a rotated layer
    sines = np.abs(cdf[:, :, J + 1:]).max()
    assert sines > 1e-3 * np.abs(cdf).max()


def test_unscattered_transmission_survives_the_anisotropic_round_trip(tmp_path):
    """A medium (unscattered beam on the transmission diagonals of every slot) with a coupled
    reflection term added, so that the file is anisotropic: the delta comes back from the
    metadata, in every slot."""
    from layersim.aniso.operator import AnisoOperator, as_aniso
    disc = {"n": 24, "md": 8}
    medium = layersim.solve(layersim.Scene.from_dict({"layer": [
        {"kind": "medium", "albedo": 0.5, "tau": 0.3}], "discretization": disc}))
    metal = layersim.solve(layersim.Scene.from_dict({"layer": [
        {"kind": "conductor", "ior": [0.2, 3.0], "roughness": [0.4, 0.2], "rotation": 30}],
        "discretization": disc}))
    m, c = as_aniso(medium.operators[0], 8), metal.operators[0]
    assert m.grid.rule == c.grid.rule and m.grid.n == c.grid.n
    blocks = dict(m.blocks)
    blocks["Rt"] = m.blocks["Rt"] + 0.05 * c.blocks["Rt"]
    op = AnisoOperator(m.grid, 8, blocks, m.eta_top, m.eta_bottom, m.delta)
    bsdf = layersim.BSDF([op])
    table = layersim.export(bsdf, tmp_path / "m.bsdf")
    assert table.anisotropic and table.is_complex
    back = bsdffile.read(tmp_path / "m.bsdf").to_bsdf()
    assert back.anisotropic and set(back.operators[0].delta) == {"Ttb", "Tbt"}
    for wi in (unit(35.0, 60.0), unit(50.0, 200.0, below=True)):
        R, T = bsdf.albedo(wi)
        assert T > 0.5
        np.testing.assert_allclose(back.albedo(wi), (R, T), rtol=1e-6)


V2_CORRUPTIONS = [
    (lambda d, t: d[:-4], "size mismatch"),
    (lambda d, t: d + b"\0", "size mismatch"),
    (lambda d, t: d[:40], "truncated header"),
    # without the complex flag the marginal table has fewer coefficients: the size no longer fits
    (lambda d, t: _put(d, 8, "<I", 1), "size mismatch"),
    (lambda d, t: _put(d, 8, "<I", 0x0D), "unknown flags"),
    (lambda d, t: _put(d, 20, "<I", t.max_order[0] + 2), "size mismatch"),        # ms_max
    (lambda d, t: _put(d, 16, "<I", 0xFFFFFFF0), "size mismatch"),                 # nCoeffs
    (lambda d, t: _put(d, _entry(t, 1), "<I", t.max_order[0] + 2), "n_max_order_s"),
    (lambda d, t: _put(d, _entry(t, 2), "<I", t.max_order[1] + 1), "n_max_order_d"),
    (lambda d, t: _put(d, _entry(t, 1), "<I", 2), "even ms"),
    (lambda d, t: _put(d, _entry(t, 0), "<I", t.coef.size - 1), "offset table"),
]


def _entry(t, field_):
    """Byte position of field ``field_`` (0 offset, 1 ms, 2 md) of the last non-empty pair's
    offset-table entry."""
    N = t.n_nodes
    p = int(np.flatnonzero(t.pair_size)[-1])
    return 64 + 4 * N + 4 * t.cdf.size + 12 * p + 4 * field_


def _put(data, pos, fmt, value):
    data = bytearray(data)
    struct.pack_into(fmt, data, pos, value)
    return bytes(data)


@pytest.mark.parametrize("mutate,match", V2_CORRUPTIONS)
def test_corrupt_version_2_files_are_rejected(aniso, mutate, match):
    """Truncated files, wrong counts and offsets past the end of a complex v2 file raise
    FileFormatError naming the field (the file is never read out of bounds)."""
    _, table, path = aniso["rotated"]
    data = path.read_bytes()
    bsdffile.FourierTable.from_bytes(data)                # the intact file reads
    with pytest.raises(FileFormatError, match=match):
        bsdffile.FourierTable.from_bytes(mutate(data, table))


def test_relative_truncation_shrinks_version_2_files_within_its_bound(aniso, tmp_path):
    """``relerr`` drops each pair's coefficients below that fraction of its largest: a smaller
    file, still exactly the size of its layout, whose eval moves by at most the dropped
    coefficients' sum (measured: 5e-4 of the peak at relerr = 1e-3, 1.4e-8 at 1e-6)."""
    bsdf, full, _ = aniso["rotated"]
    rng = np.random.default_rng(8)
    wi = np.concatenate([random_directions(rng, 800), random_directions(rng, 800, lower=True)])
    wo = np.concatenate([random_directions(rng, 800), random_directions(rng, 800, lower=True)])
    rng.shuffle(wo)
    f = bsdf.eval(wi, wo)
    errors, sizes = [], []
    for relerr in (1e-6, 1e-3):
        path = tmp_path / f"trunc_{relerr:g}.bsdf"
        table = layersim.export(bsdf, path, relerr=relerr)
        assert path.stat().st_size == table.nbytes()
        assert table.coef.size <= full.coef.size
        sizes.append(table.coef.size)
        assert json.loads(table.metadata)["relerr"] == relerr
        g = bsdffile.read(path).to_bsdf().eval(wi, wo)
        errors.append(np.max(np.abs(f - g)) / np.max(np.abs(f)))
    assert errors[0] < 1e-6 and 1e-6 < errors[1] < 3e-3, errors
    assert sizes[1] < full.coef.size
    with pytest.raises(ValueError, match="relerr"):
        layersim.export(bsdf, tmp_path / "bad.bsdf", relerr=1.0)
    iso = layersim.solve(layersim.Scene.from_dict(
        {"layer": [{"kind": "conductor", "ior": [0.2, 3.0], "roughness": 0.3}],
         "discretization": {"n": 12, "md": 6}}))
    with pytest.raises(ValueError, match="version 2 files only"):
        layersim.export(iso, tmp_path / "v1.bsdf", version=1, relerr=1e-3)


def test_version_1_refuses_anisotropic_stacks(aniso, tmp_path):
    bsdf = aniso["brushed"][0]
    with pytest.raises(InfeasibleError, match="version 1 .* isotropic BSDFs only"):
        layersim.export(bsdf, tmp_path / "v1.bsdf", version=1)
