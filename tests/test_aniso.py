"""Anisotropic layer calculus: the real slot basis against the complex basis of Zeltner & Jakob 2018, the
projection of anisotropic microfacet interfaces against direct evaluation of the physics, its
symmetries (isotropic limit, axis swap = 90 degree rotation, reciprocity, conservation), the
coupled adding equations against isotropic adding and a dense solve, and the plan/solve/BSDF
pipeline."""

import contextlib
import os

import numpy as np
import pytest
import scipy.sparse as sps

import layersim
from layersim.stacking import adding
from layersim.aniso import AnisoOperator, adding as aniso_adding, basis, reciprocity_error
from layersim.aniso.banded import banded_solve
from layersim.config import configure
from layersim.errors import InfeasibleError
from layersim.ingredients.numeric import numeric_interface_operator
from layersim.ingredients import interface_operator, medium_operator
from layersim.ingredients.aniso_microfacet import AnisoProjectionStats, aniso_interface_operator
from layersim.kernels import projection as kproj
from layersim.operators.operator import Grid
from layersim.scene import Conductor, Dielectric

from conftest import random_directions, unit

G32 = Grid.make("gauss-lobatto", 32)
GOLD = complex(0.143552, 3.98397)


def files_in(directory) -> list:
    """Our files in ``directory``: the named ones, and the spool files held open by this
    process (layersim.outofcore.spool.Spool removes a file from the directory as it creates it, so
    that it lives only while open; Linux /proc lists it as ``path (deleted)``)."""
    prefix = os.path.join(str(directory), "")
    held = []
    for fd in os.listdir("/proc/self/fd"):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            continue
        if target.startswith(prefix):
            held.append(target)
    return held + [str(p) for p in directory.iterdir()]


@pytest.fixture
def park_dir():
    """``park_dir(where)`` sets ``settings().park_dir`` for the rest of the test (None: parking
    off)."""
    with contextlib.ExitStack() as stack:
        yield lambda where: stack.enter_context(configure(park_dir=where))


def slot_values(op, name, o, i, phi_i, phi_o):
    """The operator's BSDF at ordinate pairs (o, i) and propagation azimuths, straight from the
    slot-basis coefficients (no interpolation): f = sum G[a, b] u_a(phi_o) v_b(phi_i)."""
    G = op.coefficients(name).tocsr()
    h, S = op.h, op.slots
    mode, sin = basis.slot_mode(op.md), basis.slot_is_sin(op.md)
    out = np.empty(len(o))
    for q in range(len(o)):
        g = G[np.arange(S) * h + o[q]][:, np.arange(S) * h + i[q]].toarray()
        u = np.where(sin, np.sin(mode * phi_o[q]), np.cos(mode * phi_o[q]))
        v = np.where(sin, 2 * np.sin(mode * phi_i[q]), 2 * np.cos(mode * phi_i[q]))
        v[0] = 1.0
        out[q] = u @ g @ v
    return out


def energy_weighted_error(a, b):
    """Relative Frobenius error in the energy basis (sqrt(w mu) scaling)."""
    w = np.tile(np.sqrt(a.grid.flux_weight), a.slots)
    W, Wi = sps.diags(w), sps.diags(1.0 / w)
    num = den = 0.0
    for k in b.blocks:
        if b.blocks[k] is None:
            continue
        x, y = W @ a.blocks[k] @ Wi, W @ b.blocks[k] @ Wi
        num += (x - y).power(2).sum()
        den += y.power(2).sum()
    return float(np.sqrt(num / den))


# ---- the basis ------------------------------------------------------------------------------

def test_slot_basis_is_the_complex_basis_of_seed_000_for_real_radiance():
    """Real entries = T^-1 B T for a conjugate-symmetric complex operator with l -> l + 2s
    coupling; the inverse map; rotation = phase exp(-2 i s rot); isotropic = block diagonal."""
    rng = np.random.default_rng(1)
    md = 6
    M = md - 1
    modes = np.arange(-M, M + 1)
    L, K = np.meshgrid(modes, modes, indexing="ij")
    B = (rng.normal(size=L.shape) + 1j * rng.normal(size=L.shape)) * ((L - K) % 2 == 0)
    B = 0.5 * (B + np.conj(B[::-1, ::-1]))                     # B_{-l,-k} = conj(B_{l,k})
    S = basis.n_slots(md)
    T = np.zeros((2 * M + 1, S), complex)                      # x_complex = T x_real
    T[M, 0] = 1.0
    for l in range(1, md):
        T[M + l, 2 * l - 1] = T[M - l, 2 * l - 1] = 0.5
        T[M + l, 2 * l], T[M - l, 2 * l] = -0.5j, 0.5j
    ref = np.linalg.solve(T, B @ T)
    upper = (L > 0) | ((L == 0) & (K >= 0))
    r, c, v, _ = basis.real_entries(L[upper], K[upper], B[upper])
    R = np.zeros((S, S))
    np.add.at(R, (r, c), v)
    assert np.abs(ref.imag).max() < 1e-13
    np.testing.assert_allclose(R, ref.real, atol=1e-13)
    back = basis.complex_entries(r, c, v)
    for (l, k), val in back.items():
        assert abs(val - B[M + l, M + k]) < 1e-13
    # rotating the layer multiplies f_{d,s} by exp(-2 i s rot), s = (l - k) / 2
    rot = 0.37
    Rrot = basis.rotation_matrix(md, 1, rot) @ R @ basis.rotation_matrix(md, 1, -rot)
    r, c, v, _ = basis.real_entries(L[upper], K[upper], (B * np.exp(-1j * (L - K) * rot))[upper])
    R2 = np.zeros((S, S))
    np.add.at(R2, (r, c), v)
    np.testing.assert_allclose(Rrot, R2, atol=1e-13)
    # an isotropic operator is block diagonal: cos<-cos = sin<-sin = B_l
    iso = medium_operator(G32, 4, 0.9, 0.5, 1.0, 1.0)
    an = AnisoOperator.from_iso(iso)
    h = G32.h
    for l in (1, 3):
        for a in (2 * l - 1, 2 * l):
            np.testing.assert_array_equal(
                an.blocks["Rt"][a * h:(a + 1) * h, a * h:(a + 1) * h].toarray(),
                iso.block("Rt", l).toarray())
    assert an.ms == 0


# ---- projection -----------------------------------------------------------------------------

@pytest.mark.parametrize("layer", [
    Conductor(ior=complex(0.2, 3.0), alpha_u=0.25, alpha_v=0.25),
    Conductor(ior=complex(0.2, 3.0), alpha_u=0.25, alpha_v=0.25, distribution="ggx"),
    Dielectric(ior=1.5, alpha_u=0.3, alpha_v=0.3)], ids=["beckmann", "ggx", "dielectric"])
def test_equal_roughness_on_the_coupled_path_reproduces_the_isotropic_operator(layer):
    """Same operator to 2e-5 (energy-weighted) from the coupled projection and the isotropic
    (numeric) one, and internal reflection (Rb, Fresnel kink at the critical angle) checked
    against the physics."""
    md = 200   # enough orders that neither path truncates
    coupled = aniso_interface_operator(G32, md, 2, layer, 1.0)
    # the isotropic path of solve(): the numeric projection (the semi-analytic isotropic path is
    # less accurate at grazing pairs, see tests/test_projection.py)
    iso = AnisoOperator.from_iso(numeric_interface_operator(G32, md, layer, 1.0))
    for name, blk in iso.blocks.items():
        if blk is None or name == "Rb":
            continue
        one = lambda op: AnisoOperator(G32, md, {"Rt": op.blocks[name]}, 1.0, None)
        assert energy_weighted_error(one(coupled), one(iso)) < 2e-5, name
        assert abs(coupled.blocks[name] - blk).max() < 5e-5 * abs(blk).max(), name
    if iso.blocks["Rb"] is not None:
        mu = G32.mu
        rng = np.random.default_rng(0)
        o, i = rng.choice(np.flatnonzero(mu > 0.2), (2, 2000))
        phi_i, phi_o = rng.uniform(0, 2 * np.pi, (2, 2000))
        ref = kproj.microfacet_values_ds(-mu[i], mu[o], (phi_o - phi_i)[:, None],
                                         (phi_o + phi_i)[:, None], 1.5, 0.3, 0.3,
                                         "beckmann")[:, 0]
        sel = np.flatnonzero(ref > 0.01 * ref.max())[:150]
        err = {k: np.abs(slot_values(op, "Rb", o[sel], i[sel], phi_i[sel], phi_o[sel])
                         / ref[sel] - 1) for k, op in (("coupled", coupled), ("iso", iso))}
        assert np.median(err["coupled"]) < 1e-5
        assert np.percentile(err["coupled"], 90) <= np.percentile(err["iso"], 90)
    # eval through the BSDF agrees as well
    rng = np.random.default_rng(5)
    wi, wo = random_directions(rng, 400), random_directions(rng, 400)
    a, b = layersim.BSDF([coupled]).eval(wi, wo), layersim.BSDF([iso]).eval(wi, wo)
    np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-5 * np.abs(b).max())


@pytest.mark.slow
def test_swapping_alpha_u_and_alpha_v_equals_rotating_by_90_degrees():
    """Convention check: alpha_u acts along (cos rot, sin rot, 0)."""
    a = aniso_interface_operator(G32, 24, 3, Conductor(ior=GOLD, alpha_u=0.2, alpha_v=0.4,
                                                        rotation=np.pi / 2), 1.0)
    b = aniso_interface_operator(G32, 24, 3, Conductor(ior=GOLD, alpha_u=0.4, alpha_v=0.2), 1.0)
    assert abs(a.blocks["Rt"] - b.blocks["Rt"]).max() < 1e-10 * abs(b.blocks["Rt"]).max()
    # and a rotation by 30 degrees equals evaluating the unrotated layer in a rotated frame
    rot = np.radians(30.0)
    c = aniso_interface_operator(G32, 24, 3, Conductor(ior=GOLD, alpha_u=0.4, alpha_v=0.2,
                                                        rotation=rot), 1.0)
    rng = np.random.default_rng(2)
    wi, wo = random_directions(rng, 200, min_z=0.3), random_directions(rng, 200, min_z=0.3)
    Rz = np.array([[np.cos(rot), np.sin(rot), 0], [-np.sin(rot), np.cos(rot), 0], [0, 0, 1]])
    np.testing.assert_allclose(layersim.BSDF([c]).eval(wi, wo),
                               layersim.BSDF([b]).eval(wi @ Rz.T, wo @ Rz.T), rtol=1e-6,
                               atol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("layer,names,tol", [
    (Conductor(ior=GOLD, alpha_u=0.2, alpha_v=0.4), ("Rt",), (1e-6, 1e-5)),
    (Conductor(ior=GOLD, alpha_u=0.2, alpha_v=0.4, distribution="ggx"), ("Rt",), (2e-6, 2e-4)),
    (Dielectric(ior=1.5, alpha_u=0.3, alpha_v=0.15), ("Rt", "Ttb", "Tbt"), (1e-6, 5e-5)),
], ids=["beckmann-conductor", "ggx-conductor", "beckmann-dielectric"])
def test_projection_matches_direct_evaluation_of_the_physics(layer, names, tol):
    """At ordinate pairs (no interpolation) and random azimuths where the lobe carries energy
    (f > 1 % of its peak; both elevations within 80 degrees, where the plan keeps all orders),
    the projected series reproduces physics.microfacet_eval: median and 99th percentile of the
    relative error below `tol`. (Internal reflection, with the Fresnel kink of total internal
    reflection inside broad lobes, is limited by the truncated series itself to ~1e-3 at the
    worst pairs: see the module docstring of layersim.ingredients.aniso_microfacet.)"""
    stats = AnisoProjectionStats()
    op = aniso_interface_operator(G32, 128, 12, layer, 1.0, stats)
    assert stats.s_dropped_energy < 1e-5
    mu = G32.mu
    rng = np.random.default_rng(0)
    for name in names:
        sign_i = 1 if name in ("Rt", "Ttb") else -1
        sign_o = 1 if name in ("Rb", "Ttb") else -1
        ok = np.flatnonzero(mu >= np.cos(np.radians(80.0)))
        o, i = rng.choice(ok, 3000), rng.choice(ok, 3000)
        phi_i, phi_o = rng.uniform(0, 2 * np.pi, (2, 3000))
        ref = kproj.microfacet_values_ds(sign_i * mu[i], sign_o * mu[o], (phi_o - phi_i)[:, None],
                                         (phi_o + phi_i)[:, None], layer.ior, layer.alpha_u,
                                         layer.alpha_v, layer.distribution)[:, 0]
        sel = np.flatnonzero(ref > 0.01 * ref.max())[:200]
        assert sel.size > 50
        got = slot_values(op, name, o[sel], i[sel], phi_i[sel], phi_o[sel])
        err = np.abs(got / ref[sel] - 1.0)
        assert np.median(err) < tol[0] and np.percentile(err, 99) < tol[1], (
            name, np.median(err), np.percentile(err, 99))


@pytest.mark.slow
def test_projection_without_the_reciprocity_shortcut_is_reciprocal_and_conserving():
    """Projecting every block independently checks physics and projection against generalized
    reciprocity; a rough dielectric never creates energy (R + T <= 1 for uniform illumination
    and for collimated beams at any azimuth; single-scattering microfacets lose some)."""
    layer = Dielectric(ior=1.5, alpha_u=0.3, alpha_v=0.5, rotation=0.6)
    full = aniso_interface_operator(G32, 12, 4, layer, 1.0, reciprocity=False)
    short = aniso_interface_operator(G32, 12, 4, layer, 1.0)
    assert reciprocity_error(short) < 1e-12
    assert reciprocity_error(full) < 1e-8
    assert energy_weighted_error(full, short) < 1e-8
    E = full.albedo_slots()
    from layersim.aniso.bsdf import node_energy
    phi = np.linspace(0, 2 * np.pi, 13)
    for r, t in (("Rt", "Ttb"), ("Rb", "Tbt")):
        assert np.all(E[r][0] + E[t][0] <= 1.0)
        assert np.all(node_energy(full, r, phi) + node_energy(full, t, phi) <= 1.0)
    assert np.median(E["Rt"][0] + E["Ttb"][0]) > 0.98


def test_coarse_bounds_in_chunks_of_pairs_equal_all_pairs_at_once(monkeypatch):
    """The pre-pass bounds of a block (_coarse, peak parameters and BSDF bound per pair) are
    the same evaluated a few pairs at a time (the memory bound) as all at once."""
    from layersim.ingredients import aniso_microfacet as am
    mu_i, mu_o, _, _ = am.block_pairs(G32, "Rb", False)
    args = (mu_i, mu_o, 1.5, 0.15, 0.05, "beckmann", 32)
    whole = am._coarse(*args)
    monkeypatch.setattr(am, "COARSE_ELEMENTS", 17 * 17 * 7)        # 7 pairs per launch
    chunked = am._coarse(*args)
    assert mu_i.size > 7 * 10
    for x, y in zip(whole, chunked):
        assert x.shape == y.shape and np.array_equal(x, y)


# ---- adding ---------------------------------------------------------------------------------

def test_coupled_adding_of_isotropic_operators_is_isotropic_adding():
    d = interface_operator(G32, 16, Dielectric(ior=1.5, alpha_u=0.3, alpha_v=0.3), 1.0)
    hg = medium_operator(G32, 16, 0.9, 0.6, 1.5, 1.5)
    c = interface_operator(G32, 16, Conductor(ior=complex(0.2, 3.0), alpha_u=0.2,
                                              alpha_v=0.2), 1.5)
    for top, bottom in ((d, hg), (adding.add(d, hg), c)):
        iso = AnisoOperator.from_iso(adding.add(top, bottom))
        coupled = aniso_adding.add(AnisoOperator.from_iso(top), bottom)   # mixed operands
        assert coupled.ms == 0
        for name, blk in iso.blocks.items():
            if blk is not None:
                # (the substitution prunes below PRUNE = 1e-10 of a group's right-hand side)
                assert abs(coupled.blocks[name] - blk).max() < 1e-9 * abs(blk).max()


@pytest.fixture(scope="module")
def coupled_layers():
    d = aniso_interface_operator(G32, 16, 3, Dielectric(ior=1.5, alpha_u=0.2, alpha_v=0.35,
                                                        rotation=0.4), 1.0)
    hg = medium_operator(G32, 16, 1.0, 0.6, 0.7, 1.5)
    c = aniso_interface_operator(G32, 16, 3, Conductor(ior=complex(0.2, 3.0), alpha_u=0.35,
                                                       alpha_v=0.2), 1.5)
    glass_out = aniso_interface_operator(G32, 16, 3, Dielectric(ior=1.0, alpha_u=0.3,
                                                                alpha_v=0.2), 1.5)
    return d, hg, c, glass_out


@pytest.mark.slow
def test_coupled_adding_matches_a_dense_solve_and_is_associative(coupled_layers):
    d, hg, c, _ = coupled_layers
    bottom = aniso_adding.add(hg, c)
    stack = aniso_adding.add(d, bottom)
    assert stack.ms > 3                       # multiple scattering widens the coupling
    Rb1, Rt2 = d.blocks["Rb"].toarray(), bottom.blocks["Rt"].toarray()
    Y = np.linalg.solve(np.eye(d.size) - Rb1 @ Rt2, d.blocks["Ttb"].toarray())
    dense = d.blocks["Rt"].toarray() + d.blocks["Tbt"].toarray() @ Rt2 @ Y
    assert np.abs(stack.blocks["Rt"].toarray() - dense).max() < 1e-9 * np.abs(dense).max()
    other = aniso_adding.add(aniso_adding.add(d, hg), c)
    assert energy_weighted_error(other, stack) < 1e-9
    assert reciprocity_error(stack) < 1e-8


def test_coupled_stack_never_creates_energy_and_is_reciprocal(coupled_layers):
    """A glass slab (two anisotropic rough interfaces around a conservative HG medium) loses
    what its single-scattering interfaces lose, and never creates energy, for uniform and
    collimated illumination at any azimuth; adding a clear layer is a no-op."""
    from layersim.aniso.bsdf import node_energy
    d, hg, _, glass_out = coupled_layers
    slab = aniso_adding.add(d, aniso_adding.add(hg, glass_out))
    phi = np.linspace(0, 2 * np.pi, 13)
    for r, t in (("Rt", "Ttb"), ("Rb", "Tbt")):
        total = node_energy(slab, r, phi) + node_energy(slab, t, phi)
        assert np.all(total <= 1.0) and np.all(total > 0.5)
    assert reciprocity_error(slab) < 1e-8
    clear = AnisoOperator.identity(G32, 16, 1.0)
    assert energy_weighted_error(aniso_adding.add(clear, slab), slab) < 1e-13


@pytest.mark.slow
@pytest.mark.parametrize("parking", [False, True])
def test_consuming_adding_gives_the_same_stack_and_releases_the_operands(
        coupled_layers, parking, tmp_path, monkeypatch, park_dir):
    """``consume`` only changes when blocks are released (and, with parking, that the idle
    ones wait on disk): same result, with and without the per-pair truncation of the solver,
    transmissive and opaque bottoms; consumed operands refuse to be used again; no parked
    file is left behind."""
    from layersim.outofcore import parking as park
    from layersim.errors import OperatorError
    park_dir(str(tmp_path) if parking else None)
    monkeypatch.setattr(park, "PARK_MIN_BYTES", 0)
    written = []
    init = park.Parked.__init__
    monkeypatch.setattr(park.Parked, "__init__", lambda self, mat, directory, head=0: (
        written.append(mat.nnz), init(self, mat, directory, head))[1])
    d, hg, c, glass_out = coupled_layers
    copy = lambda op: AnisoOperator(op.grid, op.md, {k: None if m is None else m.copy()
                                                     for k, m in op.blocks.items()},
                                    op.eta_top, op.eta_bottom, op.delta)
    for bottom in (c, aniso_adding.add(hg, glass_out)):
        for kw in ({}, {"relerr": 1e-7, "relerr_intermediate": 1e-6}):
            ref = aniso_adding.add(d, bottom, **kw)
            top_c, bottom_c = copy(d), copy(bottom)
            got = aniso_adding.add(top_c, bottom_c, consume="both", **kw)
            for name, mat in ref.blocks.items():
                assert (mat is None) == (got.blocks[name] is None)
                if mat is not None:
                    assert abs(mat - got.blocks[name]).max() <= 1e-15 * abs(mat).max()
            with pytest.raises(OperatorError, match="consumed"):
                top_c.block("Rt")
            with pytest.raises(OperatorError, match="consumed"):
                bottom_c.block("Rt")
            with pytest.raises(OperatorError, match="top operator was consumed"):
                aniso_adding.add(top_c, bottom)
    assert d.block("Rt").nnz                  # operands not named in consume are untouched
    with pytest.raises(ValueError, match="consume"):
        aniso_adding.add(d, c, consume="yes")
    # opaque bottom: Rt1, Tbt1; transmissive: those, Ttb2, Rb2, then Ttb1, Rb1 after use
    # (two relerr settings each; the right-hand side Rt2 Ttb1, K and Tbt1 Z1 go to files
    # as row pieces as they are formed, not through Parked)
    assert len(written) == (2 * (2 + 6) if parking else 0)
    assert files_in(tmp_path) == []


def test_malloc_arena_cap_is_explicit_and_not_applied_on_import():
    """Importing layersim leaves glibc's malloc untouched (mallopt is never called); a program
    that owns its process caps the arenas with cap_arenas (0 leaves glibc's default). Run in a
    fresh process: the cap cannot be undone."""
    import subprocess
    import sys
    from layersim.outofcore import memory
    if not memory._load() or not hasattr(memory._load(), "mallopt"):
        pytest.skip("not glibc")
    code = ("import ctypes\n"
            "from layersim.outofcore import memory\n"
            "calls = []\n"
            "class Libc:\n"
            "    def __init__(self, lib): self.lib = lib\n"
            "    def malloc_trim(self, pad): return self.lib.malloc_trim(pad)\n"
            "    def mallopt(self, *a): calls.append(a); return self.lib.mallopt(*a)\n"
            "memory._libc = Libc(memory._load())\n"
            "import layersim\n"
            "print(len(calls), memory.cap_arenas(0), memory.cap_arenas(2), len(calls))\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["0", "False", "True", "1"]


@pytest.mark.slow
def test_a_killed_solve_leaves_no_spool_file(tmp_path):
    """A process killed (SIGKILL, as the out-of-memory killer does) while it holds spooled
    data on disk leaves nothing in the parking directory: the file has no name there from
    the moment it is created."""
    import subprocess
    import sys
    code = ("import os, signal, numpy as np\n"
            "from layersim.outofcore.spool import Spool\n"
            f"s = Spool({str(tmp_path)!r})\n"
            "s.append((np.arange(100000.0),))\n"
            "assert s.on_disk and next(iter(s))[0][-1] == 99999.0\n"
            f"print(len(os.listdir({str(tmp_path)!r})), flush=True)\n"
            "os.kill(os.getpid(), signal.SIGKILL)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == -9, run.stderr
    assert run.stdout.strip() == "0"
    assert list(tmp_path.iterdir()) == []


def test_parked_block_round_trip_and_where_parking_is_refused(tmp_path, monkeypatch,
                                                             park_dir):
    from layersim.outofcore import parking as park
    mat = sps.random(50, 40, 0.2, random_state=2, format="csr")
    ref = mat.copy()
    monkeypatch.setattr(park, "PARK_MIN_BYTES", 0)
    blk = park.park(mat, str(tmp_path))
    assert isinstance(blk, park.Parked) and mat.nnz == 0        # the caller's copy is freed
    assert len(files_in(tmp_path)) == 1
    back = park.unpark(blk)
    assert files_in(tmp_path) == []
    assert back.dtype == ref.dtype and (back != ref).nnz == 0
    with pytest.raises(RuntimeError, match="already loaded"):
        blk.load()
    assert park.park(ref, None) is ref                          # nowhere to park
    monkeypatch.setattr(park, "PARK_MIN_BYTES", 1 << 40)
    assert park.park(ref, str(tmp_path)) is ref                 # too small to bother
    park_dir(None)
    assert park.park_directory() is None
    park_dir(str(tmp_path))
    assert park.park_directory(1) == str(tmp_path)
    assert park.park_directory(1 << 62) is None                 # not enough free space
    park_dir(str(tmp_path / "missing"))
    assert park.park_directory() is None
    monkeypatch.setattr(park, "_filesystem", lambda path: "tmpfs")
    park_dir(str(tmp_path))
    assert park.park_directory() is None                        # RAM-backed: no gain


@pytest.mark.parametrize("on_disk", [False, True])
def test_spooled_parts_assemble_as_a_list_of_them_does(on_disk, tmp_path):
    """A Spool reads its tuples back in order, as often as asked, and from_parts of a spool
    (with a pair pruning applied as the parts are read) equals from_parts of the list; the
    file goes once the spool is drained."""
    from layersim.aniso.pairs import PairPruner
    from layersim.outofcore.assemble import from_parts
    from layersim.outofcore.spool import Spool
    rng = np.random.default_rng(5)
    shape, h = (30, 24), 6
    parts = [(rng.integers(0, shape[0], k).astype(np.int32),
              rng.integers(0, shape[1], k).astype(np.int32),
              rng.normal(size=k) * np.exp(rng.normal(0, 5, k))) for k in (40, 0, 90, 7)]
    spool = Spool(str(tmp_path) if on_disk else None)
    for part in parts:
        spool.append(part)
    assert spool.on_disk == on_disk and len(spool) == 4
    assert len(files_in(tmp_path)) == int(on_disk)
    for _ in range(2):
        for got, ref in zip(spool, parts):
            assert all(np.array_equal(x, y) and x.dtype == y.dtype for x, y in zip(got, ref))
    keep = PairPruner(h, 1e-3)
    for part in parts:
        keep(*part)                                 # the stream's pair maxima
    ref = from_parts([keep.final_filter(*p) for p in parts], shape)
    got = from_parts(spool, shape, select=keep.final_filter)
    assert sum(keep.final_filter(*p)[0].size for p in parts) < sum(p[0].size for p in parts)
    assert (got != ref).nnz == 0 and np.array_equal(got.indices, ref.indices)
    assert len(spool) == 0 and files_in(tmp_path) == []


def test_csr_product_equals_scipys_product():
    """Rows lo..hi of a @ b, read in place from a, equal scipy's product of the slice entry
    for entry and in order: 32- and 64-bit indices, empty rows, an empty product, one row,
    and cancellation to exact zeros (dropped by both)."""
    from layersim.outofcore import products as aop
    rng = np.random.default_rng(11)
    a = sps.random(60, 80, 0.08, random_state=rng, format="csr")
    b = sps.random(80, 70, 0.1, random_state=rng, format="csr")
    keep = np.ones(60)
    keep[5] = 0.0
    a = sps.csr_matrix(sps.diags(keep) @ a)                  # an empty row
    a.eliminate_zeros()
    b2 = b.tolil()
    b2[4] = b2[3]
    b2 = sps.csr_matrix(b2)
    a2 = sps.csr_matrix(([1.0, -1.0], ([0, 0], [3, 4])), shape=(1, 80))  # a2 @ b2 = 0
    cases = [(a, b, 0, 60), (a, b, 17, 41), (a, b, 5, 6), (a, b, 59, 60), (a2, b2, 0, 1)]
    wide = sps.csr_matrix(a)
    wide.indptr, wide.indices = wide.indptr.astype(np.int64), wide.indices.astype(np.int64)
    cases.append((wide, b, 3, 50))
    for x, y, lo, hi in cases:
        ptr, cols, vals = aop.csr_product(x, lo, hi, y)
        ref = sps.csr_matrix(x[lo:hi] @ y)
        assert np.array_equal(ptr, ref.indptr)
        assert np.array_equal(cols, ref.indices) and np.array_equal(vals, ref.data)
    assert aop.csr_product(a2, 0, 1, b2)[1].size == 0


def test_pruned_product_is_the_pair_pruned_product(monkeypatch, tmp_path):
    """The chunked product (CSR pieces, filtered as they come, then stacked, or kept as row
    pieces in memory or in a file; the left factor whole or read in row pieces from a file)
    keeps exactly the entries of prune_pairs of the whole product, with chunks of one row up
    to one chunk."""
    from layersim.aniso import pairs
    from layersim.outofcore import assemble, products, rowpieces, rows
    monkeypatch.setattr(rows, "PIECE_ENTRIES", 150)            # a written in several pieces
    rng = np.random.default_rng(3)
    for n, m, density in ((83, 250, 0.05), (97, 113, 0.2), (40, 30, 0.0)):
        a = sps.random(n, m, density, random_state=rng, format="csr")
        b = sps.random(m, n + 7, density, random_state=rng, format="csr")
        a.data -= 0.5
        b.data *= np.exp(rng.normal(0.0, 4.0, b.nnz))     # magnitudes over many decades
        row_flops = np.array([np.diff(b.indptr)[a.indices[a.indptr[r]:a.indptr[r + 1]]].sum()
                              for r in range(n)], int)
        flops = int(row_flops.sum())
        for chunk_flops, stack_every in ((1, 1), (max(1, flops // 7), 50), (flops + 1, 1 << 22)):
            monkeypatch.setattr(products, "PRODUCT_CHUNK_FLOPS", chunk_flops)
            monkeypatch.setattr(assemble, "RELEASE_ENTRIES", stack_every)
            starts = products.product_row_chunks(a, b, chunk_flops)
            assert starts[0] == 0 and starts[-1] == n and np.all(np.diff(starts) > 0)
            for lo, hi in zip(starts[:-1], starts[1:]):     # the bound, or a single row
                assert hi - lo == 1 or row_flops[lo:hi].sum() <= chunk_flops
                assert hi == n or row_flops[lo:hi + 1].sum() > chunk_flops   # greedy
            whole, ref = pairs.pruned_product(a, b, 5, None), sps.csr_matrix(a @ b)
            assert np.array_equal(whole.indptr, ref.indptr)         # relerr None: a @ b
            assert np.array_equal(whole.indices, ref.indices)
            assert np.array_equal(whole.data, ref.data)
            for h, relerr in ((5, 1e-6), (7, 0.3)):
                got = pairs.pruned_product(a, b, h, relerr)
                ref = pairs.prune_pairs(a @ b, h, relerr)
                assert got.shape == ref.shape and got.nnz == ref.nnz
                assert np.array_equal(got.indptr, ref.indptr)
                assert np.array_equal(got.indices, ref.indices)
                assert np.array_equal(got.data, ref.data)
                if density:
                    assert 0 < ref.nnz < (a @ b).nnz
                for where in (None, str(tmp_path)):             # pieces in memory, on disk
                    left = rowpieces.RowPieces.written(a, where)   # a read piece by piece
                    for factor in (a, left):
                        pieces = pairs.pruned_product(factor, b, h, relerr, pieces=True,
                                                      directory=where)
                        assert pieces.on_disk == (where is not None) and pieces.nnz == ref.nnz
                        whole = pieces.to_csr()
                        assert np.array_equal(whole.indptr, ref.indptr)
                        assert np.array_equal(whole.indices, ref.indices)
                        assert np.array_equal(whole.data, ref.data)
                        pieces.close()
                    left.close()
                    assert files_in(tmp_path) == []       # the filtered copy's file too


@pytest.mark.slow
@pytest.mark.parametrize("on_disk", [False, True])
def test_sums_and_reciprocal_pruning_in_pieces_equal_the_whole(coupled_layers, on_disk,
                                                                 tmp_path, monkeypatch):
    """sum_pieces (row chunks, in memory or in a file, assembled one piece at a time) equals
    scipy's sum, and reciprocal_prune through many pieces (in memory or in files) equals it
    in one piece; the pruned stack is exactly reciprocal and lost entries; no file is left."""
    from layersim.aniso import operator as aop
    from layersim.outofcore import rows, sums
    monkeypatch.setattr(sums, "CHUNK_ENTRIES", 5000)            # many pieces
    monkeypatch.setattr(rows, "PIECE_ENTRIES", 3000)            # blocks written in pieces
    where = str(tmp_path) if on_disk else None
    d, hg, c, glass_out = coupled_layers
    a, b = d.blocks["Rt"], glass_out.blocks["Tbt"]
    for alpha, beta in ((1.0, 1.0), (0.5, -0.5)):
        pieces = sums.sum_pieces(a, b, alpha, beta, where)
        assert pieces.on_disk == on_disk and len(list(pieces)) > 3
        got, ref = pieces.to_csr(release=True), alpha * a + beta * b
        assert got.nnz == ref.nnz and abs(got - ref).max() <= 1e-15 * abs(ref).max()
        assert pieces.nnz == 0 and files_in(tmp_path) == []
    slab = aniso_adding.add(d, aniso_adding.add(hg, glass_out))     # all four blocks
    ref, got = dict(slab.blocks), dict(slab.blocks)
    args = (slab.grid, slab.md, slab.eta_top, slab.eta_bottom, slab.delta, 1e-5)
    with monkeypatch.context() as m:                # the reference: one piece each
        m.setattr(sums, "CHUNK_ENTRIES", 10 ** 9)
        aop.reciprocal_prune(ref, *args)
    aop.reciprocal_prune(got, *args, directory=where)
    for name in ref:
        assert (got[name] != ref[name]).nnz == 0 and got[name].nnz == ref[name].nnz
        assert got[name].nnz < slab.blocks[name].nnz
    assert reciprocity_error(AnisoOperator(slab.grid, slab.md, got, slab.eta_top,
                                           slab.eta_bottom, slab.delta)) < 1e-14
    assert files_in(tmp_path) == []


@pytest.mark.parametrize("on_disk", [False, True])
def test_transpose_and_sum_of_a_matrix_in_row_pieces(on_disk, tmp_path):
    """A matrix given as row pieces (rows in no piece, pieces of one row) transposes by the
    counting sort over its pieces to scipy's transpose, exactly and in canonical form, sums
    piece by piece (rows between pieces taken from the other term) to the whole sum and
    prunes piece by piece as the whole matrix does."""
    from layersim.aniso import operator as aop
    from layersim.outofcore.rowpieces import RowPieces
    from layersim.outofcore.sums import sum_pieces
    from layersim.outofcore.transpose import transposed
    rng = np.random.default_rng(4)
    A = sps.random(60, 45, density=0.2, random_state=rng, format="csr")
    A = sps.csr_matrix(sps.diags((np.arange(60) % 7 != 3).astype(float)) @ A)   # empty rows
    A.eliminate_zeros()
    B = sps.random(60, 45, density=0.2, random_state=rng, format="csr")
    pieces = RowPieces(A.shape, str(tmp_path) if on_disk else None)
    held = np.zeros(60)
    for lo, hi in ((0, 1), (1, 9), (12, 13), (13, 40), (52, 58)):   # rows 9-11, 40-51, 58-59
        part = A[lo:hi]                                               # in no piece
        pieces.append(lo, part.indptr, part.indices, part.data)
        held[lo:hi] = 1.0
    A = sps.csr_matrix(sps.diags(held) @ A)
    A.eliminate_zeros()
    T = transposed(pieces)
    assert T.has_canonical_format and T.shape == (45, 60) and T.nnz == A.nnz
    assert np.array_equal(T.toarray(), A.T.toarray())
    got = sum_pieces(pieces, B, 0.5, -2.0, str(tmp_path) if on_disk else None)
    assert np.allclose(got.to_csr(release=True).toarray(), (0.5 * A - 2.0 * B).toarray(),
                       rtol=0, atol=1e-15)
    cut = 0.5 * abs(A).max()                    # prune: piece by piece as whole
    kept = aop.prune(pieces, 0.5)
    assert pieces.nnz == 0 and kept.on_disk == on_disk
    kept = kept.to_csr(release=True)
    assert 0 < kept.nnz < A.nnz and np.abs(kept.data).min() >= cut
    assert (kept != aop.prune(A.copy(), 0.5)).nnz == 0
    assert files_in(tmp_path) == []


def test_from_parts_sums_duplicates_in_either_format(monkeypatch):
    """from_parts (counting sort of the parts into CSR, trimming the heap as it goes) equals
    scipy's COO conversion, duplicates summed, for CSR and CSC, with empty parts."""
    from layersim.outofcore import assemble as aop
    monkeypatch.setattr(aop, "RELEASE_ENTRIES", 10)
    rng = np.random.default_rng(11)
    shape = (37, 23)
    parts = []
    for size in (0, 50, 1, 200, 0, 75):
        parts.append((rng.integers(0, shape[0], size).astype(np.int32),
                      rng.integers(0, shape[1], size).astype(np.int32), rng.normal(size=size)))
    rows, cols, vals = (np.concatenate(x) for x in zip(*parts))
    ref = sps.coo_matrix((vals, (rows, cols)), shape=shape).tocsr()
    assert ref.nnz < rows.size                              # there are duplicates
    for fmt in ("csr", "csc"):
        got = aop.from_parts(list(parts), shape, fmt)
        assert got.format == fmt and got.shape == shape and got.nnz == ref.nnz
        assert np.allclose(got.toarray(), ref.toarray(), rtol=1e-15, atol=1e-15)
        assert got.has_canonical_format
    one = list(parts)
    aop.from_parts(one, shape)
    assert one == []                                        # handed over and emptied


def test_block_lu_solver_matches_sparse_lu_on_a_banded_system():
    h, md = 6, 9
    N = basis.n_slots(md) * h
    mode = basis.slot_mode(md)[np.arange(N) // h]
    A = sps.random(N, N, density=0.3, random_state=5, format="csr")
    A = A.multiply(np.abs(mode[:, None] - mode[None, :]) <= 2) * 0.1
    A = sps.identity(N) - A
    B = sps.random(N, 20, density=0.2, random_state=6, format="csr")
    Y = banded_solve(A, B, h, md)
    np.testing.assert_allclose(Y.toarray(), np.linalg.solve(A.toarray(), B.toarray()),
                               atol=1e-12)


def _swapped_orders_system(h, md, diagonal, coupling, fill=0.0):
    """``A`` (CSR) equal to the identity except that the blocks of Fourier orders 0 and 2
    are ``diagonal * I`` and couple to each other by ``coupling * I + fill`` (so that
    solving needs pivoting across the two orders), and a sparse right-hand side ``B``."""
    N = basis.n_slots(md) * h
    mode = basis.slot_mode(md)
    s0, s2 = int(np.flatnonzero(mode == 0)[0]), int(np.flatnonzero(mode == 2)[0])
    A = sps.lil_matrix(np.eye(N))
    for a, b in ((s0, s0), (s2, s2)):
        A[a * h:(a + 1) * h, b * h:(b + 1) * h] = np.eye(h) * diagonal
    for a, b in ((s0, s2), (s2, s0)):
        A[a * h:(a + 1) * h, b * h:(b + 1) * h] = np.eye(h) * coupling + fill
    return sps.csr_matrix(A), sps.random(N, 7, density=0.5, random_state=3, format="csr")


def test_banded_solve_with_a_singular_diagonal_block_falls_back_to_sparse_lu():
    """A coupled system that needs pivoting across Fourier orders (the block of order 0 is
    zero, orders 0 and 2 swap): the block LU (no pivoting across blocks) detects the singular
    block and the sparse LU solves it exactly."""
    h, md = 4, 5
    A, B = _swapped_orders_system(h, md, diagonal=0.0, coupling=2.0)
    Y = banded_solve(A, B, h, md)
    np.testing.assert_allclose(Y.toarray(), np.linalg.solve(A.toarray(), B.toarray()),
                               atol=1e-13)


def test_banded_solve_with_block_lu_growth_falls_back_to_sparse_lu(monkeypatch):
    """As above, but the diagonal blocks of orders 0 and 2 are 1e-14 (invertible: LAPACK
    does not warn): the block LU divides by them and its factors grow by ~1e14, which the
    residual check on random dense right-hand sides catches; the sparse LU (pivoting across
    orders) then gives the accurate solution. Without the check the block-LU answer is wrong
    far beyond the tolerance below."""
    from layersim.aniso import banded as aadd
    h, md = 4, 5
    A, B = _swapped_orders_system(h, md, diagonal=1e-14, coupling=2.0, fill=0.3)
    ref = np.linalg.solve(A.toarray(), B.toarray())
    checked = []
    residual = aadd._residual
    monkeypatch.setattr(aadd, "_residual", lambda *a: checked.append(residual(*a)) or
                        checked[-1])
    Y = banded_solve(A, B, h, md)
    assert checked and checked[0] > aadd.RESIDUAL_CHECK         # the block LU was refused
    np.testing.assert_allclose(Y.toarray(), ref, atol=1e-12 * np.abs(ref).max())
    monkeypatch.setattr(aadd, "RESIDUAL_CHECK", np.inf)          # accept it: wrong
    bad = banded_solve(A, B, h, md).toarray()
    assert np.abs(bad - ref).max() > 1e-6 * np.abs(ref).max()


@pytest.mark.parametrize("on_disk", [False, True])
def test_banded_solve_reads_a_matrix_in_row_pieces(on_disk, tmp_path, monkeypatch):
    """``I - K`` with ``K`` given as row pieces (in memory or in a file; rows left out of
    every piece, pieces of one row) solves as the assembled matrix does, and the pieces read
    back as the matrix they hold (counts, products, columns, diagonal, slot pairs)."""
    from layersim.aniso.pairs import slot_pairs
    from layersim.outofcore import rowpieces, rows
    h, md = 6, 9
    N = basis.n_slots(md) * h
    mode = basis.slot_mode(md)[np.arange(N) // h]
    K = sps.random(N, N, density=0.3, random_state=7, format="csr")
    K = sps.csr_matrix(K.multiply(np.abs(mode[:, None] - mode[None, :]) <= 2) * 0.1)
    keep = np.ones(N)
    keep[10:17] = 0.0                               # empty rows: eliminated unknowns
    K = sps.csr_matrix(sps.diags(keep) @ K)
    K.eliminate_zeros()
    B = sps.random(N, 20, density=0.2, random_state=8, format="csr")
    pieces = rowpieces.RowPieces(K.shape, str(tmp_path) if on_disk else None)
    bounds = [0, 1, 10, 17, 40, 41, N]              # rows 10 .. 16 in no piece
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        if lo != 10:
            part = K[lo:hi]
            pieces.append(lo, part.indptr, part.indices, part.data)
    assert len(files_in(tmp_path)) == int(on_disk)
    assert np.array_equal(pieces.row_counts(), np.diff(K.indptr))
    assert abs(pieces.to_csr() - K).max() == 0.0
    assert abs(pieces.matmul(B) - K @ B).max() < 1e-15
    D = np.random.default_rng(1).standard_normal((N, 3))
    assert np.abs(pieces.matmul(D) - K @ D).max() < 1e-14          # dense: ndarray
    assert abs(pieces.columns([3, 50, 7]) - K[:, [3, 50, 7]]).max() == 0.0
    assert np.array_equal(pieces.diagonal(), K.diagonal())
    assert all(np.array_equal(x, y) for x, y in zip(slot_pairs(pieces, h), slot_pairs(K, h)))
    monkeypatch.setattr(rows, "PIECE_ENTRIES", 100)            # RowPieces.of: many pieces
    wrapped = rowpieces.RowPieces.of(K)
    assert len(list(wrapped)) > 5 and abs(wrapped.to_csr() - K).max() == 0.0
    ref = np.linalg.solve(np.eye(N) - K.toarray(), B.toarray())
    Y = banded_solve(pieces, B, h, md, identity_minus=True, release=True)
    np.testing.assert_allclose(Y.toarray(), ref, atol=1e-12)
    assert pieces.nnz == 0 and files_in(tmp_path) == []   # released: file removed


# ---- plan, solve, BSDF ----------------------------------------------------------------------

def test_plan_chooses_the_representation_and_the_coupling_width():
    iso = layersim.make_plan(layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.2, "rotation": 30},  # rotation: no-op
        {"kind": "conductor", "ior": [0.2, 3.0], "roughness": 0.3}]}))
    assert iso.representation == "isotropic" and iso.ms == 0
    aniso = layersim.make_plan(layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.2},
        {"kind": "conductor", "ior": [0.2, 3.0], "roughness": [0.1, 0.3]}]}))
    assert aniso.representation == "anisotropic"
    # Zeltner & Jakob 2018, eq. (25) at ratio 3 (1 % of the coefficients), and the margin
    assert aniso.ms == int(np.ceil(2.58 * 3 - 1.82)) + 2
    assert [lp.ms for lp in aniso.layers] == [0, aniso.ms]
    text = aniso.report()
    assert "coupled modes" in text and "ratio 3" in text and f"ms = {aniso.ms}" in text
    assert "converted (block diagonal)" in text
    forced = layersim.make_plan(layersim.Scene.from_dict({"layer": [
        {"kind": "conductor", "ior": [0.2, 3.0], "roughness": [0.1, 0.3]}],
        "discretization": {"ms": 2}}))
    assert forced.ms == 2 and any("below the" in n for n in forced.notes)


def test_memory_limit_refuses_a_coupled_plan_and_says_what_to_reduce():
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.1},
        {"kind": "conductor", "ior": [0.2, 3.0], "roughness": [0.05, 0.15]}]})
    with configure(max_memory=2_000_000), \
            pytest.raises(InfeasibleError, match="ms = 8.*GiB.*ms in \\[discretization\\]"):
        layersim.make_plan(scene)


@pytest.fixture(scope="module")
def brushed_coating():
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
        {"kind": "conductor", "ior": [0.2, 3.0], "roughness": [0.4, 0.2], "rotation": 20}],
        "discretization": {"n": 48, "md": 24}})
    return layersim.solve(scene)


def test_solved_anisotropic_stack_eval_albedo_bins_and_persistence(brushed_coating, tmp_path):
    b = brushed_coating
    assert b.anisotropic and b.info["representation"] == "anisotropic"
    # the directional albedo depends on the incident azimuth, with period pi
    theta = np.radians(60.0)
    phis = np.radians([0.0, 45.0, 90.0, 180.0])
    wi = np.stack([np.sin(theta) * np.cos(phis), np.sin(theta) * np.sin(phis),
                   np.full(4, np.cos(theta))], axis=-1)
    R, T = b.albedo(wi)
    assert np.all(T == 0) and np.all((R > 0.3) & (R < 1))
    assert abs(R[0] - R[2]) > 1e-3
    assert R[0] == pytest.approx(R[3], rel=1e-9)
    # bins cover the hemisphere exactly and follow the mirror direction
    bins = b.bin_energies(wi[1], np.linspace(0, 1, 9), np.linspace(0, 2 * np.pi, 17))
    assert bins["top"].sum() == pytest.approx(float(R[1]), rel=1e-12)
    assert bins["top"].min() >= -1e-4 * bins["top"].max()
    # reciprocity of eval
    rng = np.random.default_rng(9)
    a, c = random_directions(rng, 300), random_directions(rng, 300)
    np.testing.assert_allclose(b.eval(a, c), b.eval(c, a), rtol=1e-8,
                               atol=1e-10 * np.abs(b.eval(a, c)).max())
    # save / load (format version 2) round trip
    path = b.save(tmp_path / "brushed.lsim")
    again = layersim.BSDF.load(path)
    assert again.anisotropic and again.operators[0].ms == b.operators[0].ms
    np.testing.assert_array_equal(again.eval(a, c), b.eval(a, c))
    with np.load(path) as d:
        assert int(d["version"]) == 2


@pytest.mark.slow
@pytest.mark.parametrize("parking", [False, True])
def test_rgb_stack_shares_layers_across_channels_and_matches_per_channel_solves(
        parking, tmp_path, monkeypatch, park_dir):
    """The solver hands a layer operator over to the adding (which releases its blocks) only
    at its last use: a coating shared by all channels and a base shared by channels 0 and 2
    give, channel by channel, the stacks of separate monochrome solves; with parking, the
    operators projected for their last use wait on disk (same result, no file left)."""
    from layersim.outofcore import parking as park
    park_dir(str(tmp_path) if parking else None)
    monkeypatch.setattr(park, "PARK_MIN_BYTES", 0)
    written = []
    init = park.Parked.__init__
    monkeypatch.setattr(park.Parked, "__init__", lambda self, mat, directory, head=0: (
        written.append(head), init(self, mat, directory, head))[1])
    disc = {"n": 32, "md": 10, "ms": 3}
    coat = {"kind": "dielectric", "ior": 1.5, "roughness": [0.5, 0.3]}
    iors = [[0.2, 3.0], [0.5, 2.4], [0.2, 3.0]]
    rgb = layersim.solve(layersim.Scene.from_dict({
        "layer": [coat, {"kind": "conductor", "ior": iors, "roughness": [0.2, 0.35]}],
        "discretization": disc}))
    assert rgb.info["representation"] == "anisotropic" and len(rgb.operators) == 3
    for c, ior in enumerate(iors):
        mono = layersim.solve(layersim.Scene.from_dict({
            "layer": [coat, {"kind": "conductor", "ior": ior, "roughness": [0.2, 0.35]}],
            "discretization": disc}))
        ref, got = mono.operators[0].blocks["Rt"], rgb.operators[c].blocks["Rt"]
        assert abs(ref - got).max() <= 1e-14 * abs(ref).max()
    assert abs(rgb.operators[0].blocks["Rt"] - rgb.operators[1].blocks["Rt"]).max() > 1e-3
    # parked by the projection (slot-0 rows kept): operators projected for their only use,
    # the base of channel 1 (the shared ones are projected for channel 0), and the coating
    # (4 blocks) and base of each monochrome solve
    projected = sum(1 for head in written if head)
    assert projected == ((1 + 3 * (4 + 1)) if parking else 0)
    assert files_in(tmp_path) == []


@pytest.mark.slow
def test_projection_parks_the_blocks_of_an_operator_handed_to_the_adding(
        coupled_layers, tmp_path, monkeypatch):
    """aniso_interface_operator(workspace=...) on disk parks each block as it is built (rotated, its
    slot-0 rows kept): the energy check reads the same albedos, a parked block refuses direct
    use, and a consuming adding step gives the stack of the resident operators."""
    from layersim.errors import OperatorError
    from layersim.outofcore import parking as park
    from layersim.outofcore.workspace import Workspace
    monkeypatch.setattr(park, "PARK_MIN_BYTES", 0)
    ws = Workspace(str(tmp_path))
    d, _, c, _ = coupled_layers
    top = aniso_interface_operator(G32, 16, 3, Dielectric(ior=1.5, alpha_u=0.2, alpha_v=0.35,
                                                          rotation=0.4), 1.0,
                                   workspace=ws)
    base = aniso_interface_operator(G32, 16, 3, Conductor(ior=complex(0.2, 3.0), alpha_u=0.35,
                                                          alpha_v=0.2), 1.5,
                                    workspace=ws)
    assert all(isinstance(m, park.Parked) for m in top.blocks.values())
    assert len(files_in(tmp_path)) == 5 and base.ms == c.ms and top.memory_bytes() == 0
    for name, alb in d.albedo_slots().items():
        assert np.array_equal(top.albedo_slots()[name], alb)
    with pytest.raises(OperatorError, match="parked"):
        top.block("Rt")
    for kw in ({}, {"relerr": 1e-7, "relerr_intermediate": 1e-6}):
        if kw:      # a second pair: the first was consumed
            top = aniso_interface_operator(G32, 16, 3, Dielectric(
                ior=1.5, alpha_u=0.2, alpha_v=0.35, rotation=0.4), 1.0, workspace=ws)
            base = aniso_interface_operator(G32, 16, 3, Conductor(
                ior=complex(0.2, 3.0), alpha_u=0.35, alpha_v=0.2), 1.5, workspace=ws)
        ref = aniso_adding.add(d, c, **kw)
        got = aniso_adding.add(top, base, consume="both", **kw)
        assert abs(ref.blocks["Rt"] - got.blocks["Rt"]).max() == 0.0
        del top, base
        assert files_in(tmp_path) == []


@pytest.mark.slow
def test_eval_of_a_rotated_anisotropic_interface_matches_the_physics():
    """BSDF.eval (cubic interpolation between ordinates) of a single rotated anisotropic
    conductor at the planner's discretisation, against physics.microfacet_eval evaluated in the
    interface's frame: median relative error < 3e-4, 99 % < 1e-2 where the lobe exceeds 5 % of
    its peak (elevations within 75 degrees). The planner's ms (Zeltner & Jakob 2018, eq. (25): 1 % L2)
    leaves ~1e-2 errors at a few percent of the points; raising ms removes them."""
    rot = np.radians(35.0)
    scene_dict = {"layer": [
        {"kind": "conductor", "ior": [0.2, 3.0], "roughness": [0.3, 0.6], "rotation": 35}]}
    b = layersim.solve(layersim.Scene.from_dict(scene_dict))
    rng = np.random.default_rng(11)
    wi = random_directions(rng, 6000, min_z=0.26)
    wo = random_directions(rng, 6000, min_z=0.26)
    Rz = np.array([[np.cos(rot), np.sin(rot), 0], [-np.sin(rot), np.cos(rot), 0], [0, 0, 1]])
    from test_physics import _eval_pairs
    ref = _eval_pairs(wi @ Rz.T, wo @ Rz.T, 0.2, 3.0, 0.3, 0.6, "beckmann")
    lobe = ref > 0.05 * ref.max()
    err = np.abs(b.eval(wi, wo)[lobe] / ref[lobe] - 1)
    assert lobe.sum() > 300
    assert np.median(err) < 3e-4 and np.percentile(err, 99) < 5e-2
    wide = layersim.solve(layersim.Scene.from_dict({**scene_dict, "discretization": {"ms": 10}}))
    err = np.abs(wide.eval(wi, wo)[lobe] / ref[lobe] - 1)
    assert np.median(err) < 3e-4 and np.percentile(err, 99) < 1e-2


def _rotate_z(v, psi):
    c, s = np.cos(psi), np.sin(psi)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1], v[..., 2]],
                    axis=-1)


@pytest.mark.slow
def test_rotational_average_is_the_mean_over_frame_rotations_and_sampling_is_unbiased():
    """The isotropic proposal of anisotropic sampling equals the BSDF's interpolant averaged
    over rotations of both directions about the normal (an identity of the linear interpolant;
    eval is its positive part), and weights drawn with it average to the albedo."""
    scene = layersim.Scene.from_dict({"layer": [
        {"kind": "conductor", "ior": [0.2, 3.0], "roughness": [0.15, 0.45], "rotation": 20.0}],
        "discretization": {"n": 48, "md": 64}})
    bsdf = layersim.solve(scene)
    avg = layersim.BSDF([op.rotational_average() for op in bsdf.operators])
    rng = np.random.default_rng(4)
    wi = unit(rng.uniform(10, 70, 6), rng.uniform(0, 360, 6))
    wo = unit(rng.uniform(10, 70, 6), rng.uniform(0, 360, 6))
    psi = np.linspace(0.0, 2 * np.pi, 256, endpoint=False)
    mean = np.mean([bsdf.interpolant(_rotate_z(wi, p), _rotate_z(wo, p)) for p in psi], axis=0)
    np.testing.assert_allclose(avg.interpolant(wi, wo), mean, rtol=1e-6, atol=1e-9 * mean.max())
    # importance sampling: E[weight] = R(wi), and the returned pdf is pdf(wi, wo)
    w1 = unit(40.0, 75.0)
    u = rng.random((200_000, 2))
    wo_s, weight, pdf = bsdf.sample(w1, u)
    ok = pdf > 0
    np.testing.assert_allclose(bsdf.pdf(w1, wo_s[ok][:500]), pdf[ok][:500], rtol=1e-9)
    R, _ = bsdf.albedo(w1)
    se = weight.std() / np.sqrt(weight.size)
    assert abs(weight.mean() - float(R)) < 4 * se + 2e-3, (weight.mean(), float(R), se)


@pytest.mark.slow
def test_projecting_a_subset_of_blocks_leaves_the_others_empty_and_the_rest_unchanged():
    layer = Dielectric(ior=1.5, alpha_u=0.2, alpha_v=0.35, rotation=0.4)
    full = aniso_interface_operator(G32, 8, 3, layer, 1.0)
    part = aniso_interface_operator(G32, 8, 3, layer, 1.0, only=("Rb", "Ttb", "Tbt"))
    assert part.blocks["Rt"].nnz == 0
    for name in ("Rb", "Ttb", "Tbt"):
        assert (part.blocks[name] != full.blocks[name]).nnz == 0
    rb = aniso_interface_operator(G32, 8, 3, layer, 1.0, only=("Rb",))
    assert rb.blocks["Ttb"].nnz == rb.blocks["Tbt"].nnz == 0
    assert (rb.blocks["Rb"] != full.blocks["Rb"]).nnz == 0
    with pytest.raises(ValueError, match="reciprocal image"):
        aniso_interface_operator(G32, 8, 3, layer, 1.0, only=("Ttb",))
