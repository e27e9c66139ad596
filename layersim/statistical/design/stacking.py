"""Multi-lobe inverse design, top to bottom (Bati et al. 2021, sec. 6: Algorithm 2 with
Algorithm 4 for 1-layer lobes and Algorithm 5 for 2-layer lobes; sec. 5.2 for a 2-layer lobe
at the top, Algorithm 1 being Algorithm 5 with nothing above).

The stack is built per channel as lists of :class:`~layersim.statistical.atomic.Interface` and
:class:`~layersim.statistical.atomic.Absorber`; indices and roughnesses are achromatic, optical
depths and conductor indices per channel.

Choices inside an equivalence class (``choice``, a position in [0, 1]):

* 2-layer lobe: the index of the upper interface at that position in the feasible set N1
  (eq. 12), sampled on :data:`N1_SAMPLES` indices (0.5: its middle), with ``tau = 0`` between
  the lobe and the layers above;
* 1-layer dielectric: the index with ``tau = 0`` in the channel of largest attenuated energy
  (the colour comes from absorption above, Bati et al. 2021 sec. 5.1.1); the root above the
  index of the medium over it, or below it at ``choice == 0`` when both exist (eq. 7);
* conductor: the middle of the class ``[eta_min, eta_max]`` (the paper's pick, sec. 7.1), or
  at ``choice == 0`` its lower bound, the largest edge tint (Gulbrandsen 2014).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .. import fgd
from ..atomic import Absorber, Interface
from ..forward import add_stack
from ..targets import TargetError
from .invert import (base_stats, conductor_index, dielectric_limit, dielectric_root,
                     effective_roughness, interface_roughness, optical_depth)

#: Indices of the upper interface tried for a 2-layer lobe, over [1, eta_max].
N1_SAMPLES = 48


def _append(stacks, per_channel) -> list:
    return [list(s) + [layer] for s, layer in zip(stacks, per_channel)]


def one_layer(stacks, eta_n: float, r_prime, s_r, s_t0n, target, lobe: int, eta_max: float,
              choice: float, top: bool):
    """Algorithm 4: append the interface (and the absorbing medium above it) of a 1-layer
    lobe; returns ``(stacks, eta)``."""
    alpha = interface_roughness(s_r)
    alpha_eff = effective_roughness(s_r, s_t0n)
    channels = len(stacks)
    if target.base == "conductor":
        how = "edge" if choice == 0.0 else "centre"
        iors = [conductor_index(float(r), alpha_eff, eta_n, how, lobe) for r in r_prime]
        return _append(stacks, [Interface(e, alpha) for e in iors]), eta_n
    need = float(np.max(r_prime))
    limit = dielectric_limit(alpha_eff, eta_n, eta_max)
    if need > limit:
        raise TargetError(f"a 1-layer dielectric lobe of roughness {alpha:.4g} reaches at most "
                          f"{limit:.4g} here (index in [1, {eta_max:g}]), this one needs "
                          f"{need:.4g} (attenuated energy, Bati et al. 2021 eq. 7 and 18)",
                          lobe, "energy")
    eta = dielectric_root(need, alpha_eff, eta_n, eta_max,
                          "below" if choice == 0.0 else "above")
    if eta is None:
        raise TargetError(f"no dielectric index in [1, {eta_max:g}] gives energy {need:.4g}",
                          lobe, "energy")
    r12 = float(fgd.dielectric(1.0, alpha_eff, eta / eta_n))
    tau = optical_depth(r12, np.asarray(r_prime))
    tau = np.where(tau > 1e-12, tau, 0.0)
    if np.any(tau > 1e-9):
        if top:
            raise TargetError("a 1-layer dielectric lobe in air reflects the same energy in "
                              "every channel (no absorbing medium above it, Bati et al. 2021 "
                              "sec. 5.1.1); give it layers = 2 or an achromatic energy",
                              lobe, "energy")
        stacks = _append(stacks, [Absorber(float(t)) for t in tau])
    return _append(stacks, [Interface(complex(eta), alpha)] * channels), eta


def two_layer(stacks, eta_n: float, target, total, lobe: int, eta_max: float, choice: float):
    """Algorithm 5 (Algorithm 1 at the top): the upper interface takes the lobe's reflected
    variance, the lower one (Algorithm 4) the rest of its energy ``R̄_k`` (eq. 20)."""
    r_prime, s_r, s_t0n, stats = base_stats(stacks, target.energy, target.variance, lobe)
    feasible, last_error = [], None
    for eta1 in np.linspace(1.0, eta_max, N1_SAMPLES):
        if abs(eta1 - eta_n) < 1e-9:
            continue
        alpha1 = _upper_roughness(stats, s_r, s_t0n, target.variance, eta1 / eta_n, r_prime)
        trial = _append(stacks, [Interface(complex(eta1), alpha1)] * len(stacks))
        above = np.array([add_stack(s, 1.0).R0i for s in trial])
        r_bar = total - above
        if np.any(r_bar <= 0.0):
            continue
        try:
            r2, s_r2, s_t2, _ = base_stats(trial, r_bar, target.variance, lobe)
            result = one_layer(trial, float(eta1), r2, s_r2, s_t2, target, lobe, eta_max,
                               0.5, top=False)
        except TargetError as exc:
            last_error = exc
            continue
        feasible.append(result)
    if not feasible:
        why = f"; e.g. {last_error}" if last_error else ""
        raise TargetError("no 2-layer configuration reaches this lobe (the feasible set N1 of "
                          f"Bati et al. 2021 eq. 12 is empty for indices in [1, {eta_max:g}])"
                          + why, lobe, "energy")
    return feasible[int(round(choice * (len(feasible) - 1)))]


def _upper_roughness(stats, s_r, s_t0n, sigma, eta_rel, r_prime) -> float:
    """Roughness of the upper interface of a 2-layer lobe such that its own lobe has the
    target variance: eq. 19 read with that interface's own energy (a fixed point, since the
    energy depends on the roughness through the FGD) rather than the whole lobe's, which
    Algorithm 5 uses as its first estimate."""
    st = stats[int(np.argmax(r_prime))]
    for _ in range(6):
        r = float(fgd.dielectric(1.0, effective_roughness(s_r, s_t0n), eta_rel))
        rr = st.Ri0 * r
        s_r = max((1.0 - rr) * ((sigma - st.s_ti0) / st.j0i - st.s_t0i) - rr * st.s_ri0, 0.0)
    return interface_roughness(s_r)


def design_stack(targets, choice=0.5):
    """Algorithm 2: the stack (per channel lists of atoms, top to bottom) for ``targets``
    (:class:`~layersim.statistical.targets.Targets`) and, per lobe, the indices of its
    interfaces in the stack. ``choice``: one position in the equivalence classes for all
    lobes, or one per lobe.

    Raises
    ------
    TargetError
        Naming the first lobe that cannot be reached and the bound it violates.
    """
    channels = targets.channels
    stacks = [[] for _ in range(channels)]
    eta_n, total = 1.0, np.zeros(channels)
    groups = []
    choices = np.broadcast_to(np.asarray(choice, dtype=float), (len(targets.lobes),))
    for k, target in enumerate(targets.lobes, start=1):
        choice = float(choices[k - 1])
        energy = np.broadcast_to(target.energy, (channels,))
        target = replace(target, energy=energy)
        total = total + energy
        before = len(stacks[0])
        options = [target.layers] if target.layers else [1, 2]
        errors = []
        for layers in options:
            try:
                if layers == 1:
                    r_prime, s_r, s_t0n, _ = base_stats(stacks, energy, target.variance, k)
                    stacks, eta_n = one_layer(stacks, eta_n, r_prime, s_r, s_t0n, target, k,
                                              targets.eta_max, choice, top=(k == 1))
                else:
                    stacks, eta_n = two_layer(stacks, eta_n, target, total, k,
                                              targets.eta_max, choice)
                errors = []
                break
            except TargetError as exc:
                errors.append(exc)
        if len(errors) == 1:
            raise errors[0]
        if errors:
            raise TargetError(f"{errors[0]}; with 2 layers: {errors[1]}")
        groups.append([i for i in range(before, len(stacks[0]))
                       if isinstance(stacks[0][i], Interface)])
    return stacks, groups
