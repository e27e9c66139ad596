"""The done-when of issue 33 (near-specular interfaces anywhere in a stack) as a benchmark.

Every stack of the issue's table (frosted glass, tinted lacquer, glass pane, smooth coat over
polished gold, brushed coat over gold, the Bati et al. 2021 one-lobe design of energy 0.08 and
roughness 0.02) and the same classes with other values (alpha 0.001-0.03, indices 1.3-1.7,
absorbing media of tau 0.01-2, RGB, rotated anisotropic, near-specular interfaces under a rough
one, Beckmann and GGX): :data:`CASES`, one table. For each case:

* ``layersim.make_plan`` under the 4 GiB limit: the plan's n, md, ms, estimated memory and
  time, or its refusal line;
* ``layersim.solve`` in a child process (``multiprocessing``, spawn) under
  ``LAYERSIM_MAX_MEMORY`` = 4 GiB, so that a plan over 4 GiB is refused before any heavy work;
  the wall time of the solve and the child's peak resident memory (``VmHWM``: the whole
  process, imports included, and the same before the solve) are printed. The parent also
  polls the child's resident memory and kills it above 4 GiB or after ``--timeout`` seconds
  (an estimate that was too low is then an ``error``, not a crash of this machine); the
  timeout covers the child's albedos and bins at every incidence too, whose time is printed
  apart (the issue's 60 s is the solve's);
* the Monte Carlo walk (``layersim.montecarlo``, ``--paths`` per incidence and channel) at
  incidence 0, 10, ..., 70 degrees (azimuth 20 degrees, so that the mirror direction lies
  inside an azimuth bin), its tallies cached in a resumable result file per case
  (``--cache``; ``layersim mc``'s format, :mod:`layersim.montecarlo.resultfile`): a rerun with
  the same cases, paths and backend redoes only the solver side;
* the comparison of the issue's criteria at each incidence and channel:

  - albedos: reflectance (top) and transmittance (bottom) within max(4 standard errors of
    the walk, 1e-3) of the walk's;
  - bins: 10 x 12 bins per side (both sides), edges equal in ``|cos theta_o|`` (0, 0.1, ...,
    1) and in ``phi_o`` (0, 30, ..., 360 degrees) as every solver-vs-walk benchmark of the
    repository lays them out (``layersim bench``, ``plans_vs_gpu_mc.py``: 18 x 36 there): at
    least 97 % of the populated bins (the walk's or the solver's energy nonzero) of all
    incidences and channels of the case together within 3 sigma, sigma the walk's standard
    error with the Poisson floor E / N of nearly empty bins
    (:func:`layersim.montecarlo.compare.against_values`; the solver states no sigma of its
    own). Narrow lobes populate only 10-25 bins per incidence, where 97 % would mean every
    bin: an exact solver would then fail about one case in four by chance (0.27 % of bins
    outside 3 sigma, about 100 bins per case), so the outcome takes the fraction over the
    case; it is printed per incidence with the farthest bin (side, index 0-9 in |cos
    theta_o|, index 0-11 in phi_o), incidences below 97 % on their own are listed, and the
    summary counts the cases that pass the stricter per-incidence reading too. At 60
    degrees the mirror direction (cos = 0.5) lies on a bin edge;
  - the solve in under 60 s and 4 GiB of peak resident memory.

Outcomes: ``pass`` (every criterion met), ``fail`` (a solve that breaks one, with the reasons),
``refused`` (the solver raised a :class:`layersim.LayersimError`: its message), ``error``
(anything else: an exception, the child killed for memory or time). The last line counts them
against the issue's done-when.

Usage::

    python benchmarks/accuracy/near_specular_anywhere.py [--paths 1e7] [--backend warp-cpu]
        [--case NAME ...] [--cache DIR] [--timeout S]
    python benchmarks/accuracy/near_specular_anywhere.py --list

Output on the 2-core VM: ``benchmarks/accuracy/near_specular_anywhere.txt``.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import os
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path[:0] = [str(HERE.parent)]
from headline import commit, machine  # noqa: E402

import layersim  # noqa: E402
from layersim.config import configure  # noqa: E402
from layersim.errors import LayersimError  # noqa: E402
from layersim.montecarlo import compare, resultfile  # noqa: E402
from layersim.montecarlo.campaign import run_walks, walks_of  # noqa: E402
from layersim.montecarlo.driver import DEFAULT_BATCH  # noqa: E402
from layersim.statistical.design import designs  # noqa: E402
from layersim.tomlwrite import dumps  # noqa: E402

#: The issue's limits: memory (bytes of peak resident memory) and wall time (s) of a solve.
MEMORY_LIMIT = 4 * 2**30
TIME_LIMIT = 60.0
#: Incidence (degrees from the normal) and azimuth (degrees) of the comparisons.
INCIDENCE = tuple(float(t) for t in range(0, 80, 10))
AZIMUTH = 20.0
#: Bin edges per side: 10 in |cos theta_o|, 12 in phi_o (radians).
MU_EDGES = np.linspace(0.0, 1.0, 11)
PHI_EDGES = np.linspace(0.0, 2.0 * np.pi, 13)
#: Albedo tolerance: max(ALBEDO_SIGMAS standard errors, ALBEDO_FLOOR); bins: BIN_FRACTION of
#: the populated ones within BIN_SIGMAS.
ALBEDO_SIGMAS, ALBEDO_FLOOR = 4.0, 1e-3
BIN_SIGMAS, BIN_FRACTION = 3.0, 0.97
SEED = 33
#: Steps after which a walk stops (its energy then counts as absorbed; the output reports them).
MAX_STEPS = 100_000


def _example_ior(file: str, layer: int):
    """The index of layer ``layer`` of ``examples/FILE`` (gold: the layerlab tutorial's)."""
    with open(ROOT / "examples" / file, "rb") as f:
        return tomllib.load(f)["layer"][layer]["ior"]


GOLD = _example_ior("coated_gold.toml", 1)            # red channel
GOLD_RGB = _example_ior("coated_gold_rgb.toml", 1)    # R, G, B


def diel(ior, alpha, distribution="beckmann", rotation=0.0) -> dict:
    """A dielectric interface layer (``alpha``: one value or (alpha_u, alpha_v))."""
    return {"kind": "dielectric", "ior": ior, "roughness": alpha, "distribution": distribution,
            "rotation": rotation}


def cond(ior, alpha, distribution="beckmann", rotation=0.0) -> dict:
    """A conductor base layer."""
    return {"kind": "conductor", "ior": ior, "roughness": alpha, "distribution": distribution,
            "rotation": rotation}


def absorbing(tau) -> dict:
    """A non-scattering (albedo 0) medium of optical thickness ``tau``."""
    return {"kind": "medium", "albedo": 0.0, "tau": tau}


def designed(energy: float, roughness: float) -> list:
    """The layers of ``layersim design``'s first candidate for one lobe (Bati et al. 2021)."""
    return designs([{"energy": energy, "roughness": roughness}])[0].data["layer"]


@dataclass(frozen=True)
class Case:
    """One stack: ``row`` is the issue table's row (1-6) or 0 for the other values."""

    name: str
    row: int
    what: str
    layers: tuple

    def scene_dict(self) -> dict:
        return {"stack": {"name": self.name}, "layer": [dict(x) for x in self.layers]}


def _cases() -> list:
    return [
        Case("frosted_glass", 1, "rough glass interface, eta 1.5, Beckmann alpha 0.02",
             (diel(1.5, 0.02),)),
        Case("tinted_lacquer", 2, "frosted glass interface over an absorbing medium of tau 1 "
             "(no base)", (diel(1.5, 0.02), absorbing(1.0))),
        Case("glass_pane", 3, "glass pane: eta 1.5 then 1.0, both alpha 0.01",
             (diel(1.5, 0.01), diel(1.0, 0.01))),
        Case("smooth_coat_polished_gold", 4, "smooth coat (eta 1.5) over gold of alpha 0.01",
             (diel(1.5, 0.0), cond(GOLD, 0.01))),
        Case("brushed_coat_gold", 5, "anisotropic coat alpha (0.03, 0.3), eta 1.5, over gold "
             "alpha 0.2", (diel(1.5, [0.03, 0.3]), cond(GOLD, 0.2))),
        Case("bati_0.08_0.02", 6, "layersim design, one lobe of energy 0.08, roughness 0.02 "
             "(Bati et al. 2021)", tuple(designed(0.08, 0.02))),
        Case("glass_a0.001_eta1.3", 0, "rough glass interface, eta 1.3, alpha 0.001",
             (diel(1.3, 0.001),)),
        Case("glass_ggx_a0.03_eta1.7", 0, "rough glass interface, eta 1.7, GGX alpha 0.03",
             (diel(1.7, 0.03, "ggx"),)),
        Case("glass_rgb_a0.005", 0, "dispersive glass interface, eta (1.48, 1.50, 1.53), alpha "
             "0.005 (RGB)", (diel([1.48, 1.5, 1.53], 0.005),)),
        Case("lacquer_thin_ggx", 0, "eta 1.4, GGX alpha 0.005 over an absorbing medium of tau "
             "0.01", (diel(1.4, 0.005, "ggx"), absorbing(0.01))),
        Case("lacquer_thick", 0, "eta 1.6, alpha 0.03 over an absorbing medium of tau 2",
             (diel(1.6, 0.03), absorbing(2.0))),
        Case("lacquer_rgb", 0, "eta 1.5, alpha 0.01 over an absorbing medium of tau (0.1, 0.5, "
             "2) (RGB)", (diel(1.5, 0.01), absorbing([0.1, 0.5, 2.0]))),
        Case("tinted_pane", 0, "pane eta 1.5 alpha 0.02, absorbing body tau 0.2, polished back "
             "face alpha 0.005", (diel(1.5, 0.02), absorbing(0.2), diel(1.0, 0.005))),
        Case("pane_ggx_eta1.3", 0, "pane eta 1.3, both faces GGX alpha 0.03",
             (diel(1.3, 0.03, "ggx"), diel(1.0, 0.03, "ggx"))),
        Case("pane_smooth_front", 0, "pane with a smooth front (eta 1.5) and a back face of "
             "alpha 0.02", (diel(1.5, 0.0), diel(1.0, 0.02))),
        Case("coat_eta1.7_gold_a0.03", 0, "coat eta 1.7 alpha 0.001 over gold alpha 0.03",
             (diel(1.7, 0.001), cond(GOLD, 0.03))),
        Case("lacquer_over_polished_gold", 0, "coat eta 1.5 alpha 0.02, absorbing medium tau "
             "0.5, gold alpha 0.01", (diel(1.5, 0.02), absorbing(0.5), cond(GOLD, 0.01))),
        Case("coat_rgb_gold_rgb_ggx", 0, "coat eta 1.5 GGX alpha 0.005 over RGB gold GGX alpha "
             "0.01", (diel(1.5, 0.005, "ggx"), cond(GOLD_RGB, 0.01, "ggx"))),
        Case("brushed_coat_rotated", 0, "coat alpha (0.02, 0.3) rotated 30 deg, eta 1.5, over "
             "gold alpha 0.2", (diel(1.5, [0.02, 0.3], rotation=30.0), cond(GOLD, 0.2))),
        Case("brushed_coat_eta1.3", 0, "anisotropic coat alpha (0.03, 0.3), eta 1.3, over gold "
             "alpha 0.2", (diel(1.3, [0.03, 0.3]), cond(GOLD, 0.2))),
        Case("smooth_coat_brushed_gold", 0, "smooth coat eta 1.4 over gold alpha (0.01, 0.03) "
             "rotated 45 deg", (diel(1.4, 0.0), cond(GOLD, [0.01, 0.03], rotation=45.0))),
        Case("inner_under_rough", 0, "rough coat eta 1.5 alpha 0.2 over an inner interface "
             "into eta 1.3 of alpha 0.01, absorbing tau 0.3, white-ish diffuse base 0.8",
             (diel(1.5, 0.2), diel(1.3, 0.01), absorbing(0.3),
              {"kind": "diffuse", "albedo": 0.8})),
        Case("inner_ggx_under_coat", 0, "rough coat eta 1.4 alpha 0.2 over an inner GGX "
             "interface into eta 1.8 of alpha 0.02, absorbing tau 0.5, grey diffuse base 0.5",
             (diel(1.4, 0.2), diel(1.8, 0.02, "ggx"), absorbing(0.5),
              {"kind": "diffuse", "albedo": 0.5})),
        Case("inner_beckmann_0.02", 0, "inner_under_rough with an inner Beckmann interface of "
             "0.02", (diel(1.5, 0.2), diel(1.3, 0.02), absorbing(0.3),
                      {"kind": "diffuse", "albedo": 0.8})),
        Case("inner_ggx_0.01", 0, "inner_ggx_under_coat with an inner GGX interface of 0.01",
             (diel(1.4, 0.2), diel(1.8, 0.01, "ggx"), absorbing(0.5),
              {"kind": "diffuse", "albedo": 0.5})),
        Case("inner_ggx_0.007", 0, "inner_ggx_under_coat with an inner GGX interface of 0.007",
             (diel(1.4, 0.2), diel(1.8, 0.007, "ggx"), absorbing(0.5),
              {"kind": "diffuse", "albedo": 0.5})),
        Case("inner_anisotropic", 0, "inner_under_rough with an anisotropic inner interface "
             "(0.005, 0.02) rotated 30 deg (a mirror from above)",
             (diel(1.5, 0.2), diel(1.3, [0.005, 0.02], rotation=30.0), absorbing(0.3),
              {"kind": "diffuse", "albedo": 0.8})),
        Case("bati_0.04_0.005", 0, "layersim design, one lobe of energy 0.04, roughness 0.005",
             tuple(designed(0.04, 0.005))),
    ]


CASES = {c.name: c for c in _cases()}


def direction(theta_deg: float) -> np.ndarray:
    """Unit vector toward the light at ``theta_deg`` from the normal, azimuth :data:`AZIMUTH`."""
    t, p = math.radians(theta_deg), math.radians(AZIMUTH)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def _rss_gib(pid="self", key: str = "VmHWM") -> float:
    """Resident memory of process ``pid`` from ``/proc``, GiB: its peak (``VmHWM``) or current
    (``VmRSS``) value; 0 if the process is gone. The peak is that of the process's own address
    space: ``ru_maxrss`` would carry the parent's peak across the spawn's fork and exec."""
    try:
        with open(f"/proc/{pid}/status") as f:
            kib = next(int(ln.split()[1]) for ln in f if ln.startswith(key + ":"))
    except (OSError, StopIteration):
        return 0.0
    return kib / 2**20


def _channels(x, channels: int) -> np.ndarray:
    """``x`` (scalar or (..., channels)) as an array with a trailing channel axis."""
    x = np.asarray(x, float)
    return x.reshape(x.shape + (1,)) if channels == 1 else x


def solve_child(data: dict, conn) -> None:
    """Child process: solve the scene ``data`` under the 4 GiB limit and send back what the
    comparison needs: ``R``, ``T`` (angles, channels), bins (angles, side, n_mu, n_phi,
    channels), the plan, wall time and peak resident memory; or the refusal or error."""
    before = _rss_gib()
    try:
        with configure(max_memory=MEMORY_LIMIT):
            scene = layersim.Scene.from_dict(data)
            t0 = time.perf_counter()
            bsdf = layersim.solve(scene)
            seconds = time.perf_counter() - t0
            peak = _rss_gib()
            c = scene.channels
            t0 = time.perf_counter()
            alb = [bsdf.albedo(direction(t)) for t in INCIDENCE]
            bins = [bsdf.bin_energies(direction(t), MU_EDGES, PHI_EDGES) for t in INCIDENCE]
            evaluation = time.perf_counter() - t0
        out = {"status": "solved", "seconds": seconds, "peak_gib": peak, "before_gib": before,
               "evaluation": evaluation,
               "R": np.array([_channels(r, c) for r, _ in alb]),
               "T": np.array([_channels(t, c) for _, t in alb]),
               "bins": np.array([[_channels(b[s], c) for s in compare.SIDES] for b in bins]),
               "plan": f"n={bsdf.info.get('n')} md={bsdf.info.get('md')} "
                       f"ms={bsdf.info.get('ms', 0)}",
               "notes": list(bsdf.info.get("notes", []))}
    except LayersimError as exc:
        out = {"status": "refused", "reason": str(exc), "peak_gib": _rss_gib(),
               "before_gib": before}
    except Exception as exc:   # noqa: BLE001 -- any other failure is this case's outcome
        out = {"status": "error", "reason": f"{type(exc).__name__}: {exc}",
               "peak_gib": _rss_gib(), "before_gib": before}
    conn.send(out)
    conn.close()


def solve_isolated(case: Case, timeout: float) -> dict:
    """:func:`solve_child` in a spawned process, watched: killed when its resident memory
    passes :data:`MEMORY_LIMIT` or after ``timeout`` seconds (an ``error`` outcome)."""
    ctx = multiprocessing.get_context("spawn")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=solve_child, args=(case.scene_dict(), child), daemon=True)
    t0 = time.perf_counter()
    proc.start()
    child.close()
    seen, why = 0.0, None
    while why is None and not parent.poll(0.05):
        seen = max(seen, _rss_gib(proc.pid))
        if seen * 2**30 > MEMORY_LIMIT:
            why = f"killed: peak resident memory {seen:.2f} GiB passed the 4 GiB limit"
        elif time.perf_counter() - t0 > timeout:
            why = f"killed after {timeout:.0f} s (--timeout)"
        elif not proc.is_alive() and not parent.poll(0.5):
            why = f"the solving process died (exit status {proc.exitcode})"
    if why is not None:
        proc.kill()
        proc.join()
        return {"status": "error", "reason": why, "peak_gib": seen, "before_gib": float("nan")}
    out = parent.recv()
    proc.join()
    return out


def walk(case: Case, paths: int, backend: str, cache: Path):
    """The walks of ``case`` at every incidence and channel, from (or into) the resumable
    result file ``cache/NAME_PATHS_BACKEND.npz``: (``MCFile``, seconds spent now, whether
    the file was complete already). A file of an earlier version of the case is rerun."""
    data = case.scene_dict()
    scene = layersim.Scene.from_dict(data)
    out = cache / f"{case.name}_{paths:.0e}_{backend}.npz"
    complete = out.exists() and _complete(out)
    wis = [direction(t) for t in INCIDENCE]
    walks = walks_of(scene, wis, MU_EDGES, PHI_EDGES, SEED, MAX_STEPS, backend)
    kw = dict(batch=DEFAULT_BATCH[backend], out=out, scene_texts=[dumps(data)],
              scene_names=[case.name],
              walk_channel=[c for _ in wis for c in range(scene.channels)])
    t0 = time.perf_counter()
    try:
        run_walks(walks, paths, **kw)
    except ValueError as exc:              # the file holds another run: the case changed
        print(f"  walk cache: {exc}; rerun", flush=True)
        complete = False
        run_walks(walks, paths, restart=True, **kw)
    return resultfile.load(out), time.perf_counter() - t0, complete


def _complete(path: Path) -> bool:
    try:
        return bool(resultfile.load(path).complete)
    except ValueError:
        return False


@dataclass
class Row:
    """The comparison at one incidence and channel: albedo gaps in units of their tolerance
    (> 1 fails), |z| of the populated bins of both sides (distances in standard errors) and
    the farthest bin, ``(|z|, side, i_mu, i_phi)``."""

    theta: float
    channel: int
    R: tuple          # (walk, walk stderr, solver or None)
    T: tuple
    R_gap: float = float("nan")
    T_gap: float = float("nan")
    z: np.ndarray = None
    worst: tuple = None
    truncated: int = 0

    @property
    def within(self) -> float:
        """Fraction of the populated bins within :data:`BIN_SIGMAS` (NaN: no solve)."""
        return float(np.mean(self.z <= BIN_SIGMAS)) if self.z is not None else float("nan")


def albedo_gap(walk_value: float, stderr: float, ours: float) -> float:
    """|ours - walk| in units of the tolerance max(4 standard errors, 1e-3)."""
    return abs(ours - walk_value) / max(ALBEDO_SIGMAS * stderr, ALBEDO_FLOOR)


def rows(f, solved: dict | None) -> list:
    """One :class:`Row` per walk of result file ``f`` (incidence-major, channels inner),
    compared with the solver's values where ``solved`` holds them."""
    out = []
    channels = int(f.walk_channel.max()) + 1
    for i in range(f.n_walks):
        k, c = divmod(i, channels)
        res = f.result(i)
        walk_R = (res.reflectance, res.reflectance_stderr)
        walk_T = (res.transmittance, res.transmittance_stderr)
        if solved is None:
            out.append(Row(INCIDENCE[k], c, walk_R + (None,), walk_T + (None,),
                           truncated=res.truncated))
            continue
        R, T = float(solved["R"][k, c]), float(solved["T"][k, c])
        bins = {s: solved["bins"][k, j, ..., c] for j, s in enumerate(compare.SIDES)}
        cmp = compare.against_values(res, R, T, bins)
        out.append(Row(INCIDENCE[k], c, walk_R + (R,), walk_T + (T,),
                       albedo_gap(*walk_R, R), albedo_gap(*walk_T, T),
                       cmp.populated(), cmp.largest(), res.truncated))
    return out


def plan_line(case: Case) -> str:
    """The plan under the 4 GiB limit: discretisation, estimates, notes and refusal."""
    try:
        with configure(max_memory=MEMORY_LIMIT):
            p = layersim.make_plan(layersim.Scene.from_dict(case.scene_dict()), refuse=False)
    except LayersimError as exc:
        return f"refused: {exc}"
    est = "not estimated" if p.seconds is None else f"{p.seconds['total']:.2g} s"
    lines = [f"{p.representation}, n={p.n} md={p.md} ms={p.ms}, estimated "
             f"{p.memory_bytes / 2**30:.2f} GiB, {est}"]
    lines += [f"    note: {n[:200]}" for n in p.notes]
    if p.refused:
        lines.append(f"    refused: {p.refused}")
    return "\n".join(lines)


def judge(solved: dict, table: list) -> tuple:
    """(outcome, reasons) of a case from the solve and its rows."""
    if solved["status"] != "solved":
        return solved["status"], [solved["reason"]]
    reasons = []
    if solved["seconds"] > TIME_LIMIT:
        reasons.append(f"solve took {solved['seconds']:.1f} s > {TIME_LIMIT:.0f} s")
    if solved["peak_gib"] * 2**30 > MEMORY_LIMIT:
        reasons.append(f"peak resident memory {solved['peak_gib']:.2f} GiB > 4 GiB")
    for r in table:
        where = f"{r.theta:g} deg" + (f" channel {'RGB'[r.channel]}" if _rgb(table) else "")
        for name, gap, (w, se, ours) in (("R", r.R_gap, r.R), ("T", r.T_gap, r.T)):
            if not gap <= 1.0:
                reasons.append(f"{name} {ours:.5f} vs walk {w:.5f} +- {se:.1e} at {where}")
    z = np.concatenate([r.z for r in table])
    if not np.mean(z <= BIN_SIGMAS) >= BIN_FRACTION:
        reasons.append(f"{100 * np.mean(z <= BIN_SIGMAS):.1f} % of the {z.size} populated "
                       "bins within 3 sigma")
    return ("fail" if reasons else "pass"), reasons


def short_incidences(table: list) -> list:
    """The incidences (and channels) whose own populated bins fall below 97 % within 3
    sigma: the stricter reading of the criterion, reported beside the outcome."""
    return [f"{r.theta:g} deg" + (f" {'RGB'[r.channel]}" if _rgb(table) else "")
            + f" {100 * r.within:.1f} % of {r.z.size} (farthest {r.worst[0]:.1f} sigma, "
            f"{r.worst[1]} {r.worst[2]},{r.worst[3]})"
            for r in table if r.z is not None and not r.within >= BIN_FRACTION]


def _rgb(table: list) -> bool:
    return any(r.channel for r in table)


def _value(x) -> str:
    return "      -" if x is None else f"{x:.5f}"


def table_lines(table: list) -> list:
    """The per-incidence rows: walk and solver albedos, gaps, bins."""
    lines = ["  theta ch   R walk  +- se    R solve  gap   T walk  +- se    T solve  gap   "
             "bins in 3 sigma"]
    for r in table:
        ch = "RGB"[r.channel] if _rgb(table) else "-"
        gaps = lambda g: "    -" if math.isnan(g) else f"{g:5.2f}"
        bins = "-" if r.z is None else (f"{100 * r.within:5.1f} % of {r.z.size:3d}, farthest "
                                        f"{r.worst[0]:4.1f} ({r.worst[1]} {r.worst[2]},"
                                        f"{r.worst[3]})")
        stop = f"  ({r.truncated} walks stopped)" if r.truncated else ""
        lines.append(f"  {r.theta:5.0f} {ch:>2} {r.R[0]:.5f} {r.R[1]:.0e} {_value(r.R[2])} "
                     f"{gaps(r.R_gap)}  {r.T[0]:.5f} {r.T[1]:.0e} {_value(r.T[2])} "
                     f"{gaps(r.T_gap)}  {bins}{stop}")
    return lines


def solve_line(solved: dict) -> str:
    before = solved["before_gib"]
    mem = f"peak RSS {solved['peak_gib']:.2f} GiB" + ("" if math.isnan(before) else
                                                       f" (before the solve {before:.2f})")
    if solved["status"] == "solved":
        return (f"solved: {solved['plan']} in {solved['seconds']:.1f} s, {mem}; albedos and "
                f"bins at {len(INCIDENCE)} incidences then took {solved['evaluation']:.1f} s")
    return f"{solved['status']} ({mem}): {solved['reason']}"


def run_case(case: Case, args) -> dict:
    """Plan, solve, walk and compare one case; prints its block and returns its summary."""
    print(f"[{case.name}] ({f'issue row {case.row}' if case.row else 'other values'}) "
          f"{case.what}", flush=True)
    print(f"  plan: {plan_line(case)}", flush=True)
    solved = solve_isolated(case, args.timeout)
    print(f"  solve: {solve_line(solved)}", flush=True)
    f, seconds, cached = walk(case, args.paths, args.backend, args.cache)
    print(f"  walk: {int(f.particles[0]):.0e} paths per incidence and channel, {f.n_walks} "
          f"walks, {f.backend} ({f.device}), {float(f.seconds):.1f} s"
          + (" (from the cache)" if cached else f" ({seconds:.1f} s now)"), flush=True)
    table = rows(f, solved if solved["status"] == "solved" else None)
    print("\n".join(table_lines(table)))
    outcome, reasons = judge(solved, table)
    print(f"  outcome: {outcome}" + (f": {'; '.join(reasons)}" if reasons else ""), flush=True)
    short = short_incidences(table)
    if short:
        print(f"  below 97 % at one incidence: {'; '.join(short)}", flush=True)
    return {"case": case, "outcome": outcome, "solved": solved, "table": table}


def summary_lines(results: list) -> list:
    """One line per case and the issue's done-when."""
    lines = ["# summary: case, outcome, solve time, peak RSS, largest albedo gap (1 = the "
             "tolerance), fraction of the populated bins (all incidences) within 3 sigma"]
    for r in results:
        s, t = r["solved"], r["table"]
        solved = s["status"] == "solved"
        gap = max(max(x.R_gap, x.T_gap) for x in t) if solved else float("nan")
        z = np.concatenate([x.z for x in t]) if solved else np.zeros(0)
        within = float(np.mean(z <= BIN_SIGMAS)) if z.size else float("nan")
        sec = f"{s['seconds']:6.1f} s" if solved else "      -"
        lines.append(f"#   {r['case'].name:28s} {r['outcome']:8s} {sec} {s['peak_gib']:5.2f} GiB"
                     + (f"  gap {gap:5.2f}  bins {100 * within:5.1f} %" if solved else ""))
    count = {k: sum(r["outcome"] == k for r in results)
             for k in ("pass", "fail", "refused", "error")}
    rows_ = [r for r in results if r["case"].row]
    lines.append(f"# done-when of issue 33 (solve < {TIME_LIMIT:.0f} s and < 4 GiB; R and T "
                 f"within max(4 se, 1e-3); >= 97 % of the populated 10 x 12 bins per side, "
                 f"incidence 0-70 deg together, within 3 sigma): "
                 + ", ".join(f"{k} {v}" for k, v in count.items())
                 + f" of {len(results)} cases ({sum(r['outcome'] == 'pass' for r in rows_)} of "
                   f"{len(rows_)} issue rows pass): "
                 + ("met" if count["pass"] == len(results) else "not met"))
    strict = sum(r["outcome"] == "pass" and not short_incidences(r["table"]) for r in results)
    lines.append(f"# with 97 % of the bins at every incidence on its own (the stricter "
                 f"reading): pass {strict} of {len(results)} cases")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--case", action="append", choices=sorted(CASES), metavar="NAME",
                    help="run this case (repeatable; default: all); --list names them")
    ap.add_argument("--paths", default="1e7", help="walk paths per incidence and channel")
    ap.add_argument("--backend", default="warp-cpu", help="walk backend (warp-cuda on a GPU)")
    ap.add_argument("--cache", type=Path, default=ROOT / "out" / "near_specular_anywhere",
                    help="folder of the walks' result files (resumed, reused)")
    ap.add_argument("--timeout", type=float, default=900.0,
                    help="seconds after which the child (solve, then albedos and bins at "
                         "every incidence) is killed (an error)")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    args = ap.parse_args(argv)
    if args.list:
        print("\n".join(f"{c.name:28s} {c.row or '-'}  {c.what}" for c in CASES.values()))
        return 0
    args.paths = int(float(args.paths))
    args.cache.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    print("# near_specular_anywhere.py: the done-when of issue 33 against the walk")
    print(f"# command: python benchmarks/accuracy/near_specular_anywhere.py "
          f"{' '.join(sys.argv[1:] if argv is None else argv)}".rstrip())
    print(f"# machine: {machine(args.backend == 'warp-cuda')}")
    print(f"# date: {time.strftime('%Y-%m-%d %H:%M')}; commit: {commit()}")
    print(f"# load average (1 min) at the start: {os.getloadavg()[0]:.2f}; walks: "
          f"{args.paths:.0e} paths per incidence and channel, backend {args.backend}, seed "
          f"{SEED}; incidence {', '.join(f'{t:g}' for t in INCIDENCE)} deg at azimuth "
          f"{AZIMUTH:g} deg; bins 10 x 12 per side (|cos theta_o| 0, 0.1, ..., 1; phi_o 0, "
          f"30, ..., 360 deg)", flush=True)
    results = [run_case(CASES[name], args) for name in (args.case or CASES)]
    print("\n".join(summary_lines(results)))
    print(f"# load average (1 min) at the end: {os.getloadavg()[0]:.2f}; wall time "
          f"{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
