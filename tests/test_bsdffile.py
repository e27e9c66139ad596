"""The .bsdf (SCATFUN) file format: byte layout against an independent reader written from
pbrt-v3's FourierBSDFTable::Read, a hand-computed Lambertian table, round trips (v1, v2, RGB),
the renderer-faithful evaluation against our eval, and rejection of corrupt files."""

import json
import struct

import numpy as np
import pytest

import layersim
from layersim import FileFormatError, InfeasibleError, bsdffile
from layersim.channels import LUMINANCE

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
    lambertian.export(path)
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
            table = bsdf.export(path, version=version)
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
    table = bsdffile.read(rough_glass.export(tmp_path / "glass.bsdf") and tmp_path / "glass.bsdf")
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
    table = bsdf.export(tmp_path / "gold.bsdf")
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
    again = bsdffile.read(bsdf.export(tmp_path / "m.bsdf") and tmp_path / "m.bsdf").to_bsdf()
    wi = unit(35.0, 60.0)
    np.testing.assert_allclose(again.albedo(wi), bsdf.albedo(wi), rtol=1e-6)


def test_version_2_layout(tmp_path, rough_glass):
    table = rough_glass.export(tmp_path / "v2.bsdf", version=2)
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
    v1 = bsdffile.read(rough_glass.export(tmp_path / "v1.bsdf") and tmp_path / "v1.bsdf")
    p = int(np.argmax(v1.shape))
    a = v1.coef[v1.offsets[p]:v1.offsets[p] + v1.shape[p]]
    c = table.coef[table.offsets[p]:table.offsets[p] + table.shape[p, 1]]
    np.testing.assert_allclose(c, np.r_[a[0], a[1:] / 2], rtol=1e-6)


def test_version_2_anisotropic_series_are_evaluated_and_refused_for_conversion():
    """A synthetic v2 table whose pairs all hold the same 3 x 2 series: between the inner
    nodes the interpolated series is that series, and eval must follow the 2D formula
    f |cos_light| = 2 sum c_sd cos(s phi_s + d phi_d) - sum_s c_s0 cos(s phi_s)."""
    mu = np.linspace(0.1, 1.0, 10)
    nodes = bsdffile.file_nodes(mu)
    N = nodes.size
    c = np.array([[0.01, 0.02], [0.3, 0.05], [0.01, 0.02]], np.float32)   # s = -1, 0, 1
    shape = np.zeros((N * N, 2), np.uint32)
    full = np.ones((N, N), bool)
    full[[N // 2 - 1, N // 2], :] = full[:, [N // 2 - 1, N // 2]] = False
    shape[full.ravel()] = (3, 2)
    size = shape[:, 0] * shape[:, 1]
    offsets = np.r_[0, np.cumsum(size)[:-1]].astype(np.uint32)
    coef = np.tile(c.ravel(), int(full.sum()))
    cdf = np.zeros(N * N * 2, np.float32)
    table = bsdffile.FourierTable(2, nodes, offsets, shape, coef, cdf, 1)
    again = bsdffile.FourierTable.from_bytes(table.to_bytes())
    wi, wo = unit(40.0, 30.0), unit(50.0, 100.0)
    phi_i, phi_o = np.arctan2(wo[1], wo[0]), np.arctan2(-wi[1], -wi[0])
    ps, pd = phi_o + phi_i, phi_o - phi_i
    s = np.array([-1, 0, 1])
    val = 2 * np.sum(c * np.cos(s[:, None] * ps + np.arange(2)[None, :] * pd)) \
        - np.sum(c[:, 0] * np.cos(s * ps))
    assert again.eval(wi, wo) == pytest.approx(val / wi[2], rel=1e-6)
    with pytest.raises(InfeasibleError, match="anisotropic"):
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
    data = lambertian.export(tmp_path / "ok.bsdf").to_bytes()
    with pytest.raises(FileFormatError, match=match):
        bsdffile.FourierTable.from_bytes(mutate(data))


def test_corrupt_offset_table_is_rejected(tmp_path, lambertian):
    table = lambertian.export(tmp_path / "ok.bsdf")
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
    table = lambertian.export(tmp_path / "ok.bsdf")
    table.metadata = ""
    h = lambertian.grid.h
    table.nodes[h + 2:] = np.linspace(0.05, 1.0, h).astype(np.float32)
    table.nodes[:h] = -table.nodes[h + 2:][::-1]
    again = bsdffile.FourierTable.from_bytes(table.to_bytes())
    with pytest.raises(FileFormatError, match="Gauss-Lobatto|gauss-lobatto"):
        again.to_bsdf()
    assert again.eval(unit(30.0), unit(40.0, 200.0)) > 0
