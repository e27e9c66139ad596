"""Belcour's statistical forward model: energies and variances added interface by interface
(Belcour 2018, sec. 6; Bati et al. 2021, eq. 2 for the energies, eq. 4-5 for the variances).

For one channel and one incidence, :func:`add_stack` walks the atoms of
:mod:`layersim.statistical.atomic` from the top and keeps the statistics of the stack above the
current depth: reflectances ``R0i`` (from above) and ``Ri0`` (from below), transmittances
``T0i, Ti0``, their variances ``s_*`` and the Jacobians ``j0i, ji0``. Each interface adds one lobe:
the light that reaches it and comes back out (energy ``T0i R12 Ti0 / (1 - Ri0 R12)``, eq. 2),
with variance ``s_ti0 + j0i (s_t0i + (s_r12 + Ri0 R12 s_ri0) / (1 - Ri0 R12))`` (eq. 5).
Channels are independent (Bati et al. 2021, footnote 1: statistics are not averaged over them).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .atomic import Absorber, Interface, absorber, interface


@dataclass
class StackStats:
    """Statistics of a stack seen from above and below, for one channel (the notation of
    Bati et al. 2021, Fig. 13: ``R0n, Rn0, T0n, Tn0`` and the variances ``s_r0n, s_rn0,
    s_t0n, s_tn0``); ``cos`` is the mean cosine below the stack (None: no light gets there)."""

    R0i: float = 0.0
    Ri0: float = 0.0
    T0i: float = 1.0
    Ti0: float = 1.0
    s_r0i: float = 0.0
    s_ri0: float = 0.0
    s_t0i: float = 0.0
    s_ti0: float = 0.0
    j0i: float = 1.0
    ji0: float = 1.0
    cos: float | None = 1.0
    eta: float = 1.0
    lobes: list = field(default_factory=list)
    """``(energy, variance, layer index)`` of each interface's lobe, top first."""


def add_atom(st: StackStats, a, index: int) -> None:
    """Add the atom ``a`` (layer ``index``) below the stack ``st`` (in place): the adding
    equations on energies (Bati et al. 2021, eq. 2) and variances (eq. 4-5)."""
    denom = 1.0 - st.Ri0 * a.R12
    m_r0i = st.T0i * a.R12 * st.Ti0 / denom
    m_ri0 = a.T21 * st.Ri0 * a.T12 / denom
    m_rr = st.Ri0 * a.R12 / denom
    e_r0i, e_ri0 = st.R0i + m_r0i, a.R21 + m_ri0
    spread = a.s_r12 + m_rr * (a.s_r12 + st.s_ri0)
    if a.lobe:
        st.lobes.append((m_r0i, st.s_ti0 + st.j0i * (st.s_t0i + spread), index))
    s_r0i = st.R0i * st.s_r0i + m_r0i * (st.s_ti0 + st.j0i * (st.s_t0i + spread))
    s_ri0 = a.R21 * a.s_r21 + m_ri0 * (a.s_t12 + a.j12 * (a.s_t21 + st.s_ri0 + m_rr * (
        a.s_r12 + st.s_ri0)))
    st.s_t0i = a.j12 * st.s_t0i + a.s_t12 + a.j12 * (a.s_r12 + st.s_ri0) * m_rr
    st.s_ti0 = st.ji0 * a.s_t21 + st.s_ti0 + st.ji0 * (a.s_r12 + st.s_ri0) * m_rr
    st.s_r0i = s_r0i / e_r0i if e_r0i > 0.0 else 0.0
    st.s_ri0 = s_ri0 / e_ri0 if e_ri0 > 0.0 else 0.0
    st.T0i, st.Ti0 = st.T0i * a.T12 / denom, a.T21 * st.Ti0 / denom
    st.R0i, st.Ri0 = e_r0i, e_ri0
    st.j0i, st.ji0 = st.j0i * a.j12, st.ji0 * a.j21
    st.cos = a.cos_t


def add_stack(layers, cos_i: float, top_ior: float = 1.0) -> StackStats:
    """Statistics of ``layers`` (top to bottom: :class:`Interface`, :class:`Absorber`) lit at
    incidence cosine ``cos_i`` from a medium of index ``top_ior``, for one channel.

    Returns
    -------
    StackStats
        The statistics below the last layer light reaches, and the lobes (one per interface
        reached; a conductor or total internal reflection ends the walk).
    """
    st = StackStats(cos=cos_i, eta=top_ior)
    for i, layer in enumerate(layers):
        if isinstance(layer, Absorber):
            a = absorber(layer, st.cos)
        else:
            a = interface(layer, st.eta, st.cos, st.s_t0i)
            st.eta = layer.ior.real
        add_atom(st, a, i)
        if st.cos is None or (isinstance(layer, Interface) and layer.ior.imag > 0.0):
            break
    return st
