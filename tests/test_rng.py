"""Philox-4x32-10 and the uniform mapping of layersim.kernels.rng (Warp CPU)."""

import numpy as np
import pytest

from layersim.kernels import rng
from layersim.kernels.runtime import ensure_init

from probes import ProbeSet

# Random123 tests/kat_vectors, "philox4x32 10" lines: counter[4], key[2] -> result[4]
KAT = [
    ([0, 0, 0, 0], [0, 0], [0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8]),
    ([0xFFFFFFFF] * 4, [0xFFFFFFFF] * 2, [0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD]),
    ([0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344], [0xA4093822, 0x299F31D0],
     [0xD16CFE09, 0x94FDCCEB, 0x5001E420, 0x24126EA1]),
]


@pytest.fixture(scope="module")
def probes(tmp_path_factory):
    ensure_init()
    return ProbeSet([(rng.philox4x32_10, ["uint"] * 6), (rng.u01, ["uint"]),
                     (rng.uniform4, ["uint"] * 5)],
                    tmp_path_factory.mktemp("rng"), name="layersim_test_rng_probes")


def test_philox_known_answers(probes):
    cols = [np.array([c[i] for c, _, _ in KAT], dtype=np.uint32) for i in range(4)]
    cols += [np.array([k[i] for _, k, _ in KAT], dtype=np.uint32) for i in range(2)]
    out = np.stack(probes.warp(0, *cols), axis=1)
    want = np.array([r for _, _, r in KAT], dtype=np.uint32)
    np.testing.assert_array_equal(out, want)


def test_u01_is_open_interval_with_32_bit_resolution(probes):
    words = np.array([0, 1, 2, 1 << 31, 0xFFFFFF7F, 0xFFFFFFFF], dtype=np.uint32)
    u = probes.warp(1, words)[0].astype(np.float64)
    assert u[0] == 2.0 ** -33 and u[1] == 1.5 * 2.0 ** -32      # resolution 2^-32 near 0
    assert u[2] - u[1] == 2.0 ** -32
    assert u[3] == 0.5
    assert np.all(u > 0) and np.all(u < 1) and u[-1] == 1 - 2.0 ** -24
    assert np.all(np.diff(u) >= 0)


def test_uniform4_streams_are_uniform_and_distinct(probes):
    n = 50_000
    draw = np.repeat(np.arange(5, dtype=np.uint32), n // 5)
    part = np.tile(np.arange(n // 5, dtype=np.uint32), 5)
    zeros = np.zeros(n, dtype=np.uint32)
    u = np.stack(probes.warp(2, zeros, zeros, part, zeros, draw), axis=1).astype(np.float64)
    # each of the 4 lanes: mean 1/2, variance 1/12 within 5 sigma
    se_mean = np.sqrt(1 / 12 / n)
    assert np.all(np.abs(u.mean(axis=0) - 0.5) < 5 * se_mean)
    assert np.all(np.abs(u.var(axis=0) - 1 / 12) < 5 * np.sqrt(1 / 180 / n))
    # lanes and consecutive draws uncorrelated
    c = np.corrcoef(u.T)
    assert np.all(np.abs(c[np.triu_indices(4, 1)]) < 5 / np.sqrt(n))
    # another seed or particle gives another stream
    other = np.stack(probes.warp(2, zeros + 1, zeros, part, zeros, draw), axis=1)
    assert not np.any(np.all(other == u.astype(np.float32), axis=1))
    # 10 equal-width bins: chi-square with 9 dof far below its 1e-6 tail (~ 46)
    counts = np.histogram(u[:, 0], bins=10, range=(0, 1))[0]
    chi2 = np.sum((counts - n / 10) ** 2 / (n / 10))
    assert chi2 < 46
