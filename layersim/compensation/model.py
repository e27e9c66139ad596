"""The compensation terms: separable, azimuth-independent lobes added to a rough interface.

Every term is, per block ``b`` of the interface (``Rt, Rb, Ttb, Tbt`` of
:mod:`layersim.operators.operator`), ``f_b(mu_i, mu_o) = u_b(mu_i) v_b(mu_o)`` (1/sr, radiance
convention), with ``u_b, v_b`` tabulated at the nodes of :mod:`.tables` and interpolated there.
Its albedo is ``a_b(mu_i) = u_b(mu_i) V_b`` with ``V_b = 2 pi int v_b(mu) mu dmu``. Reflection
blocks are symmetric (``u_b`` proportional to ``v_b``); the transmission blocks satisfy the
generalized reciprocity ``f_Tbt(mu_i, mu_o) = f_Ttb(mu_o, mu_i) / eta^2`` (``eta`` the relative
index below/above; ``docs/conventions.md``).

``L_t = 1 - E_R^t - E_T^t`` and ``L_b`` are the energies the single-scattering interface loses
for light from the top and from the bottom (:mod:`.tables`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import tables

#: Values of the scene's ``energy_compensation``.
MODES = ("none", "layerlab", "multiple-scattering")


@dataclass(frozen=True)
class Lobes:
    """Compensation term of one interface (one channel).

    Attributes
    ----------
    mode : str
        ``"layerlab"`` or ``"multiple-scattering"``.
    u, v : dict
        ``{block: ndarray (NODES,)}`` at :func:`tables.nodes`; blocks absent from them are
        zero (a conductor has ``Rt`` only).
    summary : dict
        Scalars that characterise the term (hemispherical averages, the Fresnel factor, the
        transmitted share), for the plan and the report.
    """

    mode: str
    u: dict
    v: dict
    summary: dict = field(default_factory=dict)

    def integral(self, block: str) -> float:
        """``V_b = 2 pi int v_b(mu) mu dmu``."""
        return tables.hemispherical_integral(self.v[block])

    def eval(self, block: str, mu_i, mu_o) -> np.ndarray:
        """``f_b(mu_i, mu_o)`` (1/sr) at cosines ``mu_i, mu_o`` (broadcast; absolute values)."""
        if block not in self.u:
            return np.zeros(np.broadcast(mu_i, mu_o).shape)
        return (tables.interpolate(self.u[block], np.abs(mu_i))
                * tables.interpolate(self.v[block], np.abs(mu_o)))

    def albedo(self, block: str, mu_i) -> np.ndarray:
        """Energy the term sends through ``block`` for incident cosine ``mu_i``."""
        if block not in self.u:
            return np.zeros(np.shape(mu_i))
        return tables.interpolate(self.u[block], np.abs(mu_i)) * self.integral(block)


def _loss(r, t) -> np.ndarray:
    return np.maximum(1.0 - r - t, 0.0)


def _ratio(num: float, den: float) -> float:
    return num / den if den > 1e-15 else 0.0


def conductor_term(e1: np.ndarray, factor: float, mode: str, summary: dict,
                   integral=tables.hemispherical_integral) -> Lobes:
    """``f = factor (1 - E1(mu_i)) (1 - E1(mu_o)) / V`` on ``Rt``: the separable lobe of Kulla
    & Conty 2017 (their ``f_ms``, with ``V = pi (1 - E1_avg)``) times a Fresnel factor."""
    loss = _loss(e1, 0.0)
    area = integral(loss)
    return Lobes(mode, {"Rt": loss * _ratio(factor, area)}, {"Rt": loss}, summary)


def multiple_scattering_conductor(e1: np.ndarray, f_avg: float,
                                  integral=tables.hemispherical_integral) -> Lobes:
    """Kulla & Conty 2017 for a conductor: ``E1`` is the albedo with the Fresnel factor set to 1
    and the lobe is scaled by ``F_avg^2 E1_avg / (1 - F_avg (1 - E1_avg))`` (the energy of the
    light that leaves after two or more bounces on facets of average reflectance ``F_avg``,
    per unit of the lobe's albedo ``1 - E1_avg``). With ``F_avg = 1`` (a perfect mirror) the
    interface conserves energy exactly: ``E1(mu) + (1 - E1(mu)) = 1``. ``e1`` is given at some
    nodes and ``integral`` integrates over them (see :func:`multiple_scattering_dielectric`)."""
    e_avg = integral(e1) / np.pi
    factor = _ratio(f_avg * f_avg * e_avg, 1.0 - f_avg * (1.0 - e_avg))
    return conductor_term(e1, factor, "multiple-scattering",
                          {"E1_avg": e_avg, "F_avg": f_avg, "factor": factor}, integral)


def layerlab_conductor(e1: np.ndarray, f_avg: float,
                       integral=tables.hemispherical_integral) -> Lobes:
    """layerlab's conductor correction: the same lobe scaled by ``F_avg E1_avg / (1 - F_avg (1 -
    E1_avg))`` (one factor ``F_avg`` fewer than Kulla & Conty's)."""
    e_avg = integral(e1) / np.pi
    factor = _ratio(f_avg * e_avg, 1.0 - f_avg * (1.0 - e_avg))
    return conductor_term(e1, factor, "layerlab",
                          {"E1_avg": e_avg, "F_avg": f_avg, "factor": factor}, integral)


def multiple_scattering_dielectric(a: tables.Albedos, eta: float,
                                   integral=tables.hemispherical_integral) -> Lobes:
    """Reciprocal, energy-conserving compensation of a rough dielectric interface.

    Separable lobes in the losses (the form of Kulla & Conty 2017's ``f_ms``):
    ``f_Rt = c_Rt L_t L_t``, ``f_Rb = c_Rb L_b L_b``, ``f_Ttb = c_T L_t(mu_i) L_b(mu_o)``,
    ``f_Tbt = c_T L_b(mu_i) L_t(mu_o) / eta^2`` (generalized reciprocity). With ``A = V(L)``,
    energy conservation on both sides reads ``c_Rt A_t + c_T A_b = 1`` and ``c_Rb A_b + c_T A_t
    / eta^2 = 1``. The transmitted share of the returned energy from the top, ``tau_t = c_T
    A_b``, is that of the single-scattering interface (``T_avg / (R_avg + T_avg)`` from the top,
    as Kulla & Conty split their dielectric term by the average Fresnel transmittance); the
    bottom's share ``tau_b = tau_t A_t / (eta^2 A_b)`` follows from reciprocity and is capped at
    1 (then ``tau_t`` is lowered to keep both equations). ``E + L = 1`` holds on both sides at
    every node, and hence wherever the tables are interpolated.

    ``a`` holds the albedos at some nodes and ``integral(v)`` is ``2 pi int v mu dmu`` over
    them: the table nodes (the walk's term), or the solver's ordinates with its quadrature
    (:mod:`layersim.ingredients.compensation`).
    """
    lt, lb = _loss(a.r_top, a.t_top), _loss(a.r_bottom, a.t_bottom)
    at, ab = integral(lt), integral(lb)
    r_avg = integral(a.r_top)
    t_avg = integral(a.t_top)
    tau_t = _ratio(t_avg, r_avg + t_avg)
    tau_b = _ratio(tau_t * at, eta * eta * ab)
    if tau_b > 1.0:
        tau_b, tau_t = 1.0, _ratio(eta * eta * ab, at)
    c_rt, c_rb = _ratio(1.0 - tau_t, at), _ratio(1.0 - tau_b, ab)
    c_t = _ratio(tau_t, ab) if at > 1e-15 else 0.0
    u = {"Rt": c_rt * lt, "Rb": c_rb * lb, "Ttb": c_t * lt, "Tbt": c_t * lb / eta ** 2}
    v = {"Rt": lt, "Rb": lb, "Ttb": lb, "Tbt": lt}
    return Lobes("multiple-scattering", u, v,
                 {"E_avg_top": 1.0 - at / np.pi, "E_avg_bottom": 1.0 - ab / np.pi,
                  "transmitted_share_top": tau_t, "transmitted_share_bottom": tau_b})


def layerlab(a: tables.Albedos, eta: float, integral=tables.hemispherical_integral) -> Lobes:
    """layerlab's near-diffuse correction of a rough dielectric (``Layer::setMicrofacet`` with
    ``conserveEnergy``; Jakob's layerlab tutorial sec. 6.2), in continuous form.

    ``A_tb = L_t T_t / (R_t + T_t)`` and ``A_bt = L_b T_b / (R_b + T_b)`` are the lost energies
    in the proportion of the single-scattering transmission. Transmission gets
    ``f_Ttb = A_tb(mu_i) A_bt(mu_o) / D`` and ``f_Tbt = A_bt(mu_i) A_tb(mu_o) / (eta^2 D)``
    with ``D = max(V(A_bt), V(A_tb) / eta^2)`` (as much of the wanted energy as reciprocity and
    conservation allow); what is still missing, ``A_t = 1 - R_t - T_t - A_tb V(A_bt) / D`` (and
    ``A_b``), goes into ``f_Rt = A_t A_t / V(A_t)`` and ``f_Rb = A_b A_b / V(A_b)``. The
    compensated albedo is 1 from both sides wherever these are non-negative. ``a`` and
    ``integral`` as in :func:`multiple_scattering_dielectric`.
    """
    def share(r, t):
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.nan_to_num(_loss(r, t) * t / (r + t))
    atb, abt = share(a.r_top, a.t_top), share(a.r_bottom, a.t_bottom)
    vtb, vbt = integral(atb), integral(abt)
    d = max(vbt, vtb / eta ** 2)
    inv = _ratio(1.0, d)
    u = {"Ttb": atb * inv, "Tbt": abt * inv / eta ** 2}
    v = {"Ttb": abt, "Tbt": atb}
    added_t = atb * _ratio(vbt, d)
    added_b = abt * _ratio(vtb, eta ** 2 * d)
    at_ = _loss(a.r_top, a.t_top + added_t)
    ab_ = _loss(a.r_bottom, a.t_bottom + added_b)
    u["Rt"] = at_ * _ratio(1.0, integral(at_))
    u["Rb"] = ab_ * _ratio(1.0, integral(ab_))
    v.update(Rt=at_, Rb=ab_)
    return Lobes("layerlab", u, v, {"denominator": d})


#: Dielectric and conductor terms by mode.
DIELECTRIC = {"multiple-scattering": multiple_scattering_dielectric, "layerlab": layerlab}
CONDUCTOR = {"multiple-scattering": multiple_scattering_conductor,
             "layerlab": layerlab_conductor}


def lobes_for(mode: str, eta: complex, alpha: float, dist: str,
              shadowing: str = "separable") -> Lobes | None:
    """The compensation term ``mode`` of an isotropic rough interface of relative index ``eta``
    (complex: conductor), roughness ``alpha``, distribution ``dist`` and Smith term
    ``shadowing``; None for ``"none"``."""
    if mode == "none":
        return None
    eta = complex(eta)
    if eta.imag > 0:
        e1 = tables.albedos(eta.real, eta.imag, alpha, dist, unit_fresnel=True,
                            shadowing=shadowing).r_top
        return CONDUCTOR[mode](e1, tables.fresnel_average(eta.real, eta.imag))
    return DIELECTRIC[mode](tables.albedos(eta.real, 0.0, alpha, dist, shadowing=shadowing),
                            eta.real)


def layer_lobes(layer, eta_above: float) -> Lobes | None:
    """The compensation term of a validated interface ``layer`` (its ``energy_compensation``)
    under a medium of absolute index ``eta_above``; None for ``"none"`` and smooth interfaces
    (which lose nothing)."""
    # bases without a microfacet model (measured, diffuse) have no compensation field
    if getattr(layer, "energy_compensation", "none") == "none" or layer.smooth:
        return None
    return lobes_for(layer.energy_compensation, complex(layer.ior) / eta_above, layer.alpha,
                     layer.distribution, layer.shadowing)
