"""Discretisation plan: from a validated scene, decide what to compute and at what resolution.

The plan is made before any heavy work, and says what it chose and why:

* **Ordinates** ``n`` (quadrature on mu in [-1, 1]): from the narrowest angular lobe of the stack.
  A microfacet lobe of roughness alpha has an angular width of about ``alpha`` in reflection and
  ``alpha |1 - 1/eta|`` in refraction (the refracted direction moves by that fraction of the
  facet tilt); ``n = N_PER_WIDTH / width`` resolves it with a few ordinates across (the constant is
  set so that alpha = 0.1, eta = 1.5 gives layerlab's n = 196; ``benchmarks/convergence.py``
  checks it). Henyey-Greenstein media need ``~N_PER_WIDTH / sqrt(1 - g)`` at most.
* **Fourier orders** ``md``: not from a fitted formula but from the lobes themselves: a pre-pass
  of the projection kernel over every ordinate pair returns the length of each pair's peak
  series (:func:`layersim.fourier.peak_length`); the plan keeps every order needed by lobes whose
  incident and outgoing elevations are both within :data:`THETA_FULL` of the normal. A lobe at
  elevation theta is ~alpha cos(theta) wide in azimuth, so pairs closer to the horizon would need
  ~1/(alpha mu) orders (thousands at the most grazing ordinates); they are truncated and tapered
  (Lanczos sigma factors, so that they blur instead of ringing negative). Truncating orders never
  changes energy (only order 0 carries energy); the plan reports how many pairs are affected.
  Media add the reach of their phase function.
* **What is left out**: transmission blocks below an opaque base, index-matched interfaces and
  empty media (exact no-ops), anisotropic coupling (``ms = 0``) for isotropic stacks.
* **Representation** (see :mod:`layersim.aniso`): isotropic stacks use the cosine series of
  :class:`~layersim.operator.IsoOperator`. A stack with an anisotropic interface
  (``alpha_u != alpha_v``) uses coupled modes; each anisotropic layer is projected with the
  ``ms`` its roughness ratio needs (:func:`layersim.aniso.plan.ms_for_ratio`), isotropic layers
  keep their cheaper operators and runs of them are added isotropically before conversion.
* **Memory**: estimated from the same pre-pass (coefficients actually stored) and refused up front
  when it exceeds the limit (``LAYERSIM_MAX_MEMORY`` bytes, default: half the available RAM).

A ``[discretization]`` table in the scene overrides ``n``, ``md`` and the quadrature rule.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from .errors import InfeasibleError
from .operator import Grid
from .scene import Conductor, Dielectric, Diffuse, Medium, Scene

#: Ordinates per unit of inverse lobe width (see module docstring).
N_PER_WIDTH = 6.5
N_MIN, N_MAX = 64, 4096
MD_MAX = 20_000
#: Lobes with both elevations within this angle of the normal keep all their Fourier orders.
THETA_FULL = 80.0
#: Lower bound on the orders a lobe of roughness alpha needs: md >= this / alpha (half the
#: estimate for a Beckmann lobe at THETA_FULL), used to refuse before the pre-pass.
MD_LOWER_PER_INV_ALPHA = 10.0
#: Relative truncation of the Fourier series (same as the projection's).
SERIES_RELERR = 1e-7
#: Peak bytes of projecting an isotropic interface, per (order x h x h) entry: series of every
#: block's pairs (~16) plus the dense per-block assembly and its temporaries (~24). Measured
#: (benchmarks/memory_phases.py, Table 2 rows 1-3: 204 / 118 / 117 MiB above the baseline) the
#: estimate is then 1.2-1.4x the peak; without this term it was 0.4-0.55x.
PROJECTION_BYTES = 40
DEFAULT_RULE = "gauss-lobatto"


def _available_memory() -> int:
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        return 8 << 30


def memory_limit() -> int:
    """Bytes a solve may use: ``$LAYERSIM_MAX_MEMORY`` or half the available memory."""
    env = os.environ.get("LAYERSIM_MAX_MEMORY")
    if env:
        try:
            return int(float(env))
        except ValueError:
            raise InfeasibleError(f"LAYERSIM_MAX_MEMORY must be a number of bytes, got {env!r}")
    return _available_memory() // 2


@dataclass
class LayerPlan:
    index: int
    kind: str
    action: str          # "project", "adding-doubling", "diffuse", "left out"
    detail: str = ""
    width: float | None = None   # narrowest lobe width (radians) when it drives n
    orders: int = 1              # Fourier orders this layer needs
    ms: int = 0                  # mode coupling (anisotropic interfaces)


@dataclass
class Plan:
    """What :func:`layersim.solve` will compute (see module docstring)."""

    rule: str
    n: int
    md: int
    ms: int = 0
    representation: str = "isotropic"
    layers: list = field(default_factory=list)
    left_out: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    memory_bytes: int = 0
    overridden: dict = field(default_factory=dict)

    @property
    def grid(self) -> Grid:
        return Grid.make(self.rule, self.n)

    def report(self) -> str:
        """Human-readable summary (printed by ``layersim plan`` and ``layersim solve``)."""
        src = lambda k: " (from the scene)" if k in self.overridden else ""
        lines = [
            f"representation: {self.representation} "
            + ("(cosine series in the azimuth difference)" if self.representation == "isotropic"
               else "(Fourier series in phi_d and phi_s, coupled modes, seed 000 eq. (7)-(10))"),
            f"ordinates: n = {self.n}{src('n')}, {self.rule}{src('quadrature')} "
            f"({self.n // 2} per hemisphere)",
            f"Fourier orders: md = {self.md}{src('md')}" + (f", ms = {self.ms}{src('ms')}"
                                                          if self.representation != "isotropic"
                                                          else ", ms = 0"),
            f"estimated memory: {self.memory_bytes / 2**20:.1f} MiB",
        ]
        for lp in self.layers:
            lines.append(f"  layer {lp.index} ({lp.kind}): {lp.action}"
                         + (f" -- {lp.detail}" if lp.detail else ""))
        for item in self.left_out:
            lines.append(f"  left out: {item}")
        for note in self.notes:
            lines.append(f"  note: {note}")
        return "\n".join(lines)


def _interface_widths(layer, eta_rel: complex) -> tuple[float, str]:
    alpha = min(layer.alpha_u, layer.alpha_v)
    if isinstance(layer, Conductor):
        return alpha, "reflection lobe"
    eta = eta_rel.real
    if eta == 1.0:
        return math.inf, ""
    t = alpha * abs(1.0 - 1.0 / max(eta, 1.0 / eta))
    return t, "refraction lobe"


def _n_for_width(width: float) -> int:
    n = math.ceil(N_PER_WIDTH / width)
    n += n % 2
    return max(N_MIN, n)


def make_plan(scene: Scene) -> Plan:
    """Plan the solve of a monochromatic or RGB scene (RGB channels share one plan).

    Raises
    ------
    InfeasibleError
        If a layer cannot be represented (smooth interface) or the discretisation it needs
        exceeds the limits (ordinates, orders, memory). The message names the layer, the limit
        and what to change.
    """
    disc = scene.discretization
    rule = disc.quadrature or DEFAULT_RULE
    plans: list[LayerPlan] = []
    left_out: list[str] = []
    notes: list[str] = []
    from .aniso import plan as aplan
    mono = scene.channel(0)
    widths = []
    media_orders = 1
    for i, layer in enumerate(mono.layers):
        kind = layer.kind
        if isinstance(layer, (Dielectric, Conductor)):
            eta_rel = mono.relative_ior(i)
            if isinstance(layer, Dielectric) and all(
                    s.relative_ior(i) == 1.0 for s in (scene.channel(c) for c in range(scene.channels))):
                left_out.append(f"layer {i} (dielectric): index-matched interface (relative "
                                "index 1) is an exact no-op")
                plans.append(LayerPlan(i, kind, "left out", "index-matched"))
                continue
            if layer.smooth:
                raise InfeasibleError(
                    f"layer {i} ({kind}): smooth interfaces (roughness 0) are not representable "
                    "in the Fourier basis yet (their reflection is a delta in every Fourier "
                    "order); give a small roughness (e.g. 0.01), or use layersim.montecarlo, "
                    "which handles smooth interfaces exactly")
            width, what = _interface_widths(layer, eta_rel)
            widths.append((width, i, kind, what))
            if layer.anisotropic:  # --- anisotropic interfaces (layersim.aniso.plan) ---
                ratio = aplan.anisotropy_ratio(layer)
                lms = aplan.ms_for_layer(layer)
                rot = f", rotated {math.degrees(layer.rotation):g} deg" if layer.rotation else ""
                plans.append(LayerPlan(
                    i, kind, "project (coupled modes)",
                    f"{layer.distribution} alpha=({layer.alpha_u:g}, {layer.alpha_v:g}){rot}, "
                    f"relative index {_fmt_eta(eta_rel)}; ratio {ratio:.3g} -> ms = {lms}",
                    width=width, ms=lms))
                continue
            plans.append(LayerPlan(i, kind, "project",
                                   f"{layer.distribution} alpha={layer.alpha_u:g}, relative "
                                   f"index {_fmt_eta(eta_rel)}", width=width))
        elif isinstance(layer, Medium):
            if layer.tau == 0.0:
                left_out.append(f"layer {i} (medium): tau = 0 is an exact no-op")
                plans.append(LayerPlan(i, kind, "left out", "tau = 0"))
                continue
            from .ingredients.medium import hg_orders
            orders = hg_orders(layer.g) if max(
                s.layers[i].albedo for s in (scene.channel(c) for c in range(scene.channels))) > 0 else 1
            media_orders = max(media_orders, orders)
            if layer.g != 0.0:
                widths.append((math.sqrt(1.0 - abs(layer.g)), i, kind, "phase-function lobe"))
            plans.append(LayerPlan(i, kind, "adding-doubling",
                                   f"tau={layer.tau:g}, g={layer.g:g}: scattering in {orders} "
                                   "order(s), unscattered beam in all", orders=orders))
        elif isinstance(layer, Diffuse):
            plans.append(LayerPlan(i, kind, "diffuse", "order 0 only"))
    if scene.opaque:
        left_out.append("transmission blocks (Ttb, Tbt) and bottom reflection: the base is "
                        "opaque")
    ms_needed = max((lp.ms for lp in plans), default=0)
    anisotropic = ms_needed > 0
    if not anisotropic:
        left_out.append("anisotropic coupling (ms = 0): every layer is isotropic")
    else:
        iso = [lp for lp in plans if lp.action not in ("left out", "project (coupled modes)")]
        if iso:
            left_out.append("coupling in the isotropic layers (" + ", ".join(
                f"{lp.index}" for lp in iso) + "): they keep cosine-series operators and are "
                "converted (block diagonal) only when added to an anisotropic one")
        driver = max((lp for lp in plans if lp.ms), key=lambda lp: lp.ms)
        notes.append(f"coupled modes: ms = {ms_needed} set by layer {driver.index} "
                     f"({driver.kind}), roughness ratio -> ms = ceil({aplan.MS_SLOPE} r "
                     f"{aplan.MS_OFFSET:+g}) (seed 000 eq. (25)), +1 above alpha "
                     f"{aplan.MS_ROUGH:g} (benchmarks/ms_study.py): relative L2 error < 1 %; "
                     f"coefficients below {aplan.COUPLED_RELERR:g} of their ordinate pair's "
                     "largest are dropped (layersim.aniso.plan.COUPLED_RELERR)")

    # ---- ordinates -------------------------------------------------------------------
    overridden = {}
    if disc.n is not None:
        n = disc.n
        overridden["n"] = n
        if widths:
            width, idx, kind, what = min(widths)
            if n < _n_for_width(width):
                notes.append(f"n = {n} from the scene is below the ~{_n_for_width(width)} that "
                             f"layer {idx} ({kind}) needs ({what} ~{width:.3g} rad wide)")
    elif widths:
        width, idx, kind, what = min(widths)
        n = _n_for_width(width)
        if n > N_MAX:
            raise InfeasibleError(
                f"layer {idx} ({kind}): its {what} is {width:.2g} rad wide and needs about "
                f"n = {n} ordinates (limit {N_MAX}); increase the roughness, move the relative "
                "index away from 1, or use layersim.montecarlo")
        notes.append(f"n set by layer {idx} ({kind}): {what} ~{width:.3g} rad wide")
    else:
        n = N_MIN
    if disc.quadrature:
        overridden["quadrature"] = rule
    if rule == "simpson38" and (n - 1) % 3:
        n = 3 * math.ceil((n - 1) / 3) + 1
        n += 3 * (n % 2)
    grid = Grid.make(rule, n)

    # ---- early refusal: a cheap lower bound, before the pre-pass ------------------------
    # A Beckmann lobe at 80 deg needs ~22.8 / alpha orders (K ~ sqrt(2 B ln(1/eps)), B =
    # tan^2(theta) / (2 alpha^2)); half of that is a safe lower bound on md. For coupled modes
    # the block-LU factors of the adding equations then bound the memory from below: refuse
    # there, without paying for a pre-pass that would itself grow like n^2 ms.
    if ms_needed > 0 and disc.md is None:
        alpha_min = min(min(mono.layers[lp.index].alpha_u, mono.layers[lp.index].alpha_v)
                        for lp in plans if lp.action.startswith("project"))
        md_lower = max(media_orders, math.ceil(MD_LOWER_PER_INV_ALPHA / alpha_min))
        lower = aplan.factor_bytes(grid.h, md_lower, 2 * (disc.ms or ms_needed))
        if lower > memory_limit():
            raise InfeasibleError(
                f"the plan (n = {n}, md >= {md_lower}, ms = {disc.ms or ms_needed}) needs at "
                f"least {lower / 2**30:.1f} GiB, over the limit of "
                f"{memory_limit() / 2**30:.2f} GiB (LAYERSIM_MAX_MEMORY); increase the "
                "roughness of the smoothest interface, reduce the anisotropy, or lower n, md "
                "or ms in [discretization]")

    # ---- Fourier orders and memory (pre-pass over the interfaces' pairs) ---------------
    prepass = []
    md_needed = media_orders
    for lp in plans:
        if not lp.action.startswith("project"):
            continue
        layer = mono.layers[lp.index]
        if lp.ms:
            lengths, full = aplan.interface_prepass(grid, layer, mono.ior_above(lp.index),
                                                    lp.ms, aplan.COUPLED_RELERR)
        else:
            lengths, full = _interface_prepass(grid, layer, mono.ior_above(lp.index))
        lp.orders = int(lengths[full].max()) if full.any() else 1
        md_needed = max(md_needed, lp.orders)
        prepass.append((lp, lengths))
    if disc.md is not None:
        md = disc.md
        overridden["md"] = md
        if md < md_needed:
            notes.append(f"md = {md} from the scene is below the {md_needed} orders the lobes "
                         "need: lobes are truncated in azimuth (ringing)")
    else:
        md = max(1, md_needed)
    if disc.ms is not None:
        overridden["ms"] = disc.ms
        if anisotropic and disc.ms < ms_needed:
            notes.append(f"ms = {disc.ms} from the scene is below the {ms_needed} the "
                         "anisotropy needs (relative L2 error above 1 %)")
        for lp in plans:
            if lp.ms:
                lp.ms = max(1, disc.ms) if anisotropic else 0
        ms = disc.ms if anisotropic else 0
    else:
        ms = ms_needed
    stored = 0
    for lp, lengths in prepass:
        if not lp.ms:   # anisotropic layers are estimated below (layersim.aniso.plan)
            stored += int(np.minimum(lengths, md).sum())
        trunc = int(np.count_nonzero(lengths > md))
        if trunc:
            notes.append(f"layer {lp.index}: {trunc} ordinate pairs beyond {THETA_FULL:g} deg "
                         f"would need up to {int(lengths.max())} orders; they keep {md} "
                         "(tapered; energy unaffected)")
    if md > MD_MAX:
        raise InfeasibleError(f"the stack needs {md} Fourier orders (limit {MD_MAX}); increase "
                              "the roughness of the smoothest interface or use layersim.montecarlo")
    h = grid.h
    media = sum(1 for lp in plans if lp.action == "adding-doubling")
    stored += media * (4 * media_orders * h * h + 4 * md * h)
    # the stack itself (assume as dense as the densest ingredient, at most dense) plus adding
    # temporaries: per order per thread ~12 dense h x h arrays
    stored_bytes = int(12 * min(stored * 2, 4 * md * h * h)) + 12 * 8 * h * h * 8
    if not anisotropic:
        # projecting an interface holds every block's per-pair series and then, per block, the
        # dense scatter of layersim.operator._orders_to_csr with its temporaries
        stored_bytes += PROJECTION_BYTES * md * h * h
    if anisotropic:  # --- coupled modes (layersim.aniso.plan) ---
        entries = [aplan.operator_entries(lengths, md, lp.ms) for lp, lengths in prepass
                   if lp.ms]
        stored_bytes = aplan.solve_bytes(entries) + stored_bytes
    memory = stored_bytes * max(1, scene.channels if scene.channels > 1 else 1)
    limit = memory_limit()
    if memory > limit:
        raise InfeasibleError(
            f"the plan (n = {n}, md = {md}{f', ms = {ms}' if anisotropic else ''}) needs about "
            f"{memory / 2**30:.2f} GiB, over the limit of {limit / 2**30:.2f} GiB "
            "(LAYERSIM_MAX_MEMORY); lower n or md" + (" or ms" if anisotropic else "")
            + " in [discretization], or increase the roughness of the smoothest interface"
            + (" or reduce the anisotropy" if anisotropic else ""))
    return Plan(rule=rule, n=n, md=md, ms=ms, layers=plans, left_out=left_out, notes=notes,
                memory_bytes=memory, overridden=overridden,
                representation="anisotropic" if anisotropic else "isotropic")


def _fmt_eta(eta: complex) -> str:
    return f"{eta.real:.4g}" if eta.imag == 0 else f"{eta.real:.4g}+{eta.imag:.4g}i"


def _interface_prepass(grid: Grid, layer, eta_above: float):
    """Series lengths of the significant ordinate pairs of one interface, and which of them lie
    within :data:`THETA_FULL` (one cheap kernel launch per block)."""
    from . import fourier
    from .kernels import projection as kproj
    from .ingredients.microfacet import ENERGY_DROP, L_FIT, _block_pairs

    eta = complex(layer.ior) / eta_above
    names = ("Rt",) if isinstance(layer, Conductor) else ("Rt", "Rb", "Ttb", "Tbt")
    fw = grid.flux_weight
    mu_full = math.cos(math.radians(THETA_FULL))
    lengths, full = [], []
    for name in names:
        mu_i, mu_o, o, i = _block_pairs(grid, name, triangle=False)
        phi = np.broadcast_to(np.linspace(0.0, np.pi, 9), (mu_i.size, 9))
        s, q = kproj.microfacet_split(mu_i, mu_o, phi, eta, layer.alpha, layer.alpha,
                                      layer.distribution)
        q0, qpi = q[:, 0], q[:, -1]
        bound = 10.0 * fourier.peak_values(q0, layer.distribution) * np.abs(s).max(axis=1)
        energy = bound * 2.0 * np.pi * np.maximum(fw[i], fw[o])
        sig = energy > ENERGY_DROP
        lengths.append(fourier.peak_length(q0[sig], qpi[sig], layer.distribution,
                                           SERIES_RELERR) + L_FIT)
        full.append(np.minimum(np.abs(mu_i[sig]), np.abs(mu_o[sig])) >= mu_full)
    return np.concatenate(lengths), np.concatenate(full)
