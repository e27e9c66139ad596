"""Per-layer actions: what the solve does with each layer, and the lobes that set ``n``.

Interfaces are projected (with coupled modes if anisotropic); media are added by
adding-doubling with the Fourier orders of their phase function; a diffuse base needs order 0
only. Index-matched interfaces and empty media are exact no-ops and are left out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..aniso import plan as aplan
from ..errors import InfeasibleError
from ..ingredients.medium import G_EXACT_MAX, hg_scaling
from ..lobe import (NEAR_SPECULAR_ALPHA, NEAR_SPECULAR_BASE_ALPHA, NEAR_SPECULAR_WIDE_MAX,
                    near_specular_conductor_error, near_specular_error)
from ..operator import Grid
from ..scene import Conductor, Dielectric, Diffuse, Measured, Medium, Scene
from .model import LayerPlan
from .ordinates import N_PER_WIDTH
from .tabulated import measured_plan, tabulated_plan

#: Legendre moments a delta-M scaled medium needs (the accuracy target that sets its share of
#: ``n``): for g = 0.99, tau 5, albedo 0.95 the albedo at normal incidence moves by 3e-5 from
#: N = 31 to N = 195 moments (by 2.3e-4 from 15 to 31); ``benchmarks/features/forward_media.py``. A
#: grid of ``n`` Gauss-Lobatto ordinates represents ``n - 1`` moments, so the planner's
#: smallest grid (64) already meets it.
DELTA_M_MOMENTS = 32


@dataclass
class Survey:
    """The per-layer actions of a stack and what they imply for the discretisation.

    Attributes
    ----------
    layers : list of LayerPlan
    left_out : list of str
        What the solve leaves out, and why (report lines).
    widths : list of (float, int, str, str)
        ``(width in radians, layer index, kind, lobe)`` of every lobe that competes to set
        ``n``.
    media_orders : int
        Fourier orders the media's phase functions need (counted by :func:`scale_media`, once
        the grid is known).
    scaled : list of LayerPlan
        The scattering media, whose phase-function representation (whole series or delta-M
        scaled) :func:`scale_media` decides once the grid is known.
    hints : list of str
        What would make a refused plan affordable (added to the refusal's message).
    boundary : dict
        Smooth dielectric boundaries, ``{"top" | "bottom": index outside}``
        (:mod:`layersim.boundary`).
    snell_eta : float or None
        Their relative index (inside / outside), which sets the Snell-matched grid.
    """

    layers: list = field(default_factory=list)
    left_out: list = field(default_factory=list)
    widths: list = field(default_factory=list)
    media_orders: int = 1
    scaled: list = field(default_factory=list)
    boundary: dict = field(default_factory=dict)
    snell_eta: float | None = None
    lobes: dict = field(default_factory=dict)
    near_specular: tuple = ()
    hints: list = field(default_factory=list)


def survey_layers(scene: Scene) -> Survey:
    """The action of every layer of ``scene`` (RGB channels share it: the geometry is the
    first channel's, and a layer is left out only if it is a no-op in every channel).

    Raises
    ------
    InfeasibleError
        For a smooth dielectric interface inside the stack (only the top and bottom ones can
        be matched by the ordinates; :func:`_smooth`).
    """
    survey = Survey()
    mono = scene.channel(0)
    for i, layer in enumerate(mono.layers):
        if isinstance(layer, (Dielectric, Conductor)):
            _interface(scene, i, layer, survey)
        elif isinstance(layer, Medium):
            _medium(scene, i, layer, survey)
        elif isinstance(layer, Diffuse):
            survey.layers.append(LayerPlan(i, layer.kind, "diffuse", "order 0 only"))
        elif isinstance(layer, Measured):
            survey.widths.append((layer.alpha, i, layer.kind, "measured lobe"))
            survey.layers.append(measured_plan(i, layer))
    if scene.opaque:
        survey.left_out.append("transmission blocks (Ttb, Tbt) and bottom reflection: the "
                               "base is opaque")
    return survey


def _channels(scene: Scene):
    return [scene.channel(c) for c in range(scene.channels)]


def _interface(scene: Scene, i: int, layer, survey: Survey) -> None:
    kind = layer.kind
    if isinstance(layer, Dielectric) and all(s.relative_ior(i) == 1.0 for s in _channels(scene)):
        survey.left_out.append(f"layer {i} (dielectric): index-matched interface (relative "
                               "index 1) is an exact no-op")
        survey.layers.append(LayerPlan(i, kind, "left out", "index-matched"))
        return
    if layer.smooth:
        _smooth(scene, i, layer, survey)
        return
    if _near_specular(scene, i, layer, survey) or _near_specular_conductor(scene, i, layer, survey):
        return
    eta_rel = scene.channel(0).relative_ior(i)
    width, what = interface_width(layer, eta_rel)
    survey.widths.append((width, i, kind, what))
    if layer.ndf is not None:
        survey.layers.append(tabulated_plan(i, layer, eta_rel, width))
    elif layer.anisotropic:
        ms = aplan.ms_for_layer(layer)
        rot = f", rotated {math.degrees(layer.rotation):g} deg" if layer.rotation else ""
        survey.layers.append(LayerPlan(
            i, kind, "project (coupled modes)",
            f"{layer.distribution} alpha=({layer.alpha_u:g}, {layer.alpha_v:g}){rot}, "
            f"relative index {_fmt_eta(eta_rel)}; ratio {aplan.anisotropy_ratio(layer):.3g} "
            f"-> ms = {ms}", width=width, ms=ms))
    else:
        survey.layers.append(LayerPlan(i, kind, "project",
                                       f"{layer.distribution} alpha={layer.alpha_u:g}, relative "
                                       f"index {_fmt_eta(eta_rel)}"
                                       + compensation_text(layer), width=width))


def _medium(scene: Scene, i: int, layer, survey: Survey) -> None:
    kind = layer.kind
    if all(s.layers[i].tau == 0.0 for s in _channels(scene)):
        survey.left_out.append(f"layer {i} (medium): tau = 0 is an exact no-op")
        survey.layers.append(LayerPlan(i, kind, "left out", "tau = 0"))
        return
    # a per-channel g: every channel's representation is decided on the grid (scale_media);
    # the most forward-peaked channel that keeps the whole series sets the lobe width
    channels = [s.layers[i] for s in _channels(scene)]
    gs = [x.g for x in channels]
    g_text = "/".join(f"{g:g}" for g in dict.fromkeys(gs))
    tau_text = "/".join(f"{t:g}" for t in dict.fromkeys(x.tau for x in channels))
    lp = LayerPlan(i, kind, "adding-doubling", f"tau={tau_text}, g={g_text}")
    survey.layers.append(lp)
    if max(x.albedo for x in channels) == 0:
        lp.detail += ": no scattering, unscattered beam in all orders"
        return
    if max(gs) > G_EXACT_MAX:
        # delta-M scaled: the scaled phase function needs DELTA_M_MOMENTS moments, i.e. a grid
        # of DELTA_M_MOMENTS + 1 Gauss-Lobatto ordinates
        survey.widths.append((N_PER_WIDTH / (DELTA_M_MOMENTS + 1), i, kind,
                              f"delta-M scaled phase function ({DELTA_M_MOMENTS} moments)"))
    whole = [g for g in gs if g <= G_EXACT_MAX and g != 0.0]
    if whole:
        g = max(whole, key=abs)
        survey.widths.append((math.sqrt(1.0 - abs(g)), i, kind, "phase-function lobe"))
    survey.scaled.append(lp)


def scale_media(scene: Scene, survey: Survey, grid: Grid) -> int:
    """Decide the phase-function representation of every scattering medium of ``survey`` on
    ``grid`` (:func:`layersim.ingredients.medium.hg_scaling`, the same function the solve uses):
    the whole series or delta-M scaled. Sets their ``orders`` and report lines, and returns the
    Fourier orders the media need.

    Raises
    ------
    InfeasibleError
        Naming the layer and field ``g`` for a backward peak the grid cannot hold.
    """
    for lp in survey.scaled:
        try:
            scs = [hg_scaling(grid, s.layers[lp.index].g, s.layers[lp.index].albedo,
                              s.layers[lp.index].tau) for s in _channels(scene)]
        except InfeasibleError as exc:
            raise InfeasibleError(f"layer {lp.index} (medium): field 'g': {exc}") from None
        lp.orders = max(c.moments for c in scs)
        if any(c.scaled for c in scs):
            per = lambda v: "/".join(dict.fromkeys(v))      # one value, or one per channel
            lp.detail += (f": delta-M scaled (Wiscombe 1977), N = "
                          f"{per(str(c.moments) for c in scs)} moments, f = "
                          f"{per(f'{c.f:.4g}' for c in scs)}, scaled tau = "
                          f"{per(f'{c.tau:.4g}' for c in scs)}, albedo = "
                          f"{'/'.join(f'{c.albedo:.4g}' for c in scs)}; scattering in "
                          f"{lp.orders} order(s), unscattered beam (with the truncated forward "
                          "peak) in all")
        else:
            lp.detail += f": scattering in {lp.orders} order(s), unscattered beam in all"
        survey.media_orders = max(survey.media_orders, lp.orders)
    return survey.media_orders


def _smooth(scene: Scene, i: int, layer, survey: Survey) -> None:
    """A smooth interface: a conductor is a diagonal (exact on any grid); a dielectric is a
    boundary of the stack (top, or bottom of a transmissive stack) matched by the ordinates,
    and refused elsewhere."""
    kind = layer.kind
    if isinstance(layer, Conductor):
        survey.layers.append(LayerPlan(i, kind, "exact (specular delta)",
                                       "smooth: Fresnel reflectance on the diagonal of Rt in "
                                       "every order"))
        return
    mono = scene.channel(0)
    etas = {s.relative_ior(i).real for s in _channels(scene)}
    last = len(mono.layers) - 1
    side = "top" if i == 0 else "bottom" if i == last else None
    if side is None:
        raise InfeasibleError(
            f"layer {i} ({kind}): a smooth dielectric interface inside the stack refracts "
            "between two grids of ordinates that cannot both be matched to the stack's "
            "(only the top interface, and the bottom one of a transmissive stack with the "
            "same index ratio, are solved exactly); give it a roughness > 0, or use "
            "layersim.montecarlo")
    if len(etas) > 1:
        raise InfeasibleError(
            f"layer {i} ({kind}): a smooth dielectric boundary needs the same index in every "
            "channel (the ordinates are matched to one refraction); give one ior, or a "
            "roughness > 0")
    outside = scene.top_ior if side == "top" else layer.ior.real
    inside = mono.ior_above(i) if side == "bottom" else layer.ior.real
    ratio = inside / outside
    if ratio <= 1.0:
        raise InfeasibleError(
            f"layer {i} ({kind}): a smooth {side} boundary needs a denser medium inside the "
            f"stack (index {inside:g}) than outside ({outside:g}); give it a roughness > 0")
    if survey.snell_eta is not None and abs(survey.snell_eta - ratio) > 1e-12 * ratio:
        raise InfeasibleError(
            f"layer {i} ({kind}): the smooth bottom boundary has index ratio {ratio:g}, the "
            f"smooth top one {survey.snell_eta:g}; one grid of ordinates matches only one "
            "ratio: give one of them a roughness > 0")
    if side == "bottom" and survey.boundary and len(mono.layers) == 2:
        raise InfeasibleError(
            f"layer {i} ({kind}): two smooth boundaries with nothing between them trap the "
            "light beyond the critical angle forever (a singular adding step); put a medium "
            "(tau > 0) between them")
    survey.snell_eta = ratio
    survey.boundary[side] = outside
    survey.layers.append(LayerPlan(
        i, kind, f"smooth {side} boundary (Snell-matched ordinates)",
        f"relative index {ratio:.4g}: inside nodes in the escape cone are the refracted "
        "outside nodes; Fresnel reflection (TIR: 1) on the diagonal, transmission applied "
        "at evaluation"))


def _near_specular(scene: Scene, i: int, layer, survey: Survey) -> bool:
    """Plan a nearly smooth dielectric top interface as a smooth boundary plus its lobe
    (:mod:`layersim.lobe`) and return True; False where the split does not apply, leaving it
    to the exact projection: not the top interface, too rough, a boundary the smooth machinery
    refuses, or a base that would show the refraction blur the split leaves out (the split
    needs an opaque base that scatters wider than that blur: diffuse, or a conductor rougher
    than :data:`~layersim.lobe.NEAR_SPECULAR_ALPHA`)."""
    lo, hi = min(layer.alpha_u, layer.alpha_v), max(layer.alpha_u, layer.alpha_v)
    if layer.ndf is not None:       # the lobe of layersim.lobe is analytic
        return False
    base = scene.channel(0).layers[-1]
    wide_base = isinstance(base, (Diffuse, Measured)) or (
        isinstance(base, Conductor) and min(base.alpha_u, base.alpha_v) > NEAR_SPECULAR_ALPHA)
    if (not isinstance(layer, Dielectric) or i != 0 or lo > NEAR_SPECULAR_ALPHA
            or hi > NEAR_SPECULAR_WIDE_MAX or not wide_base):
        return False
    if layer.energy_compensation != "none":
        # the split's lobe has no compensation term, and the exact projection of so narrow a
        # lobe is far over the memory limit
        raise InfeasibleError(
            f"layer {i} (dielectric): field 'energy_compensation': a near-specular coat (alpha "
            f"<= {NEAR_SPECULAR_ALPHA:g}) is solved by the smooth split, which has no "
            "compensation term; set energy_compensation = \"none\" on this layer (at alpha "
            "0.03 the hemispherical single-scattering loss is 4e-4)")
    try:
        _smooth(scene, i, layer, survey)
    except InfeasibleError:
        return False
    lp = survey.layers[-1]
    lp.action = "near-specular split (smooth top boundary + lobe)"
    lp.detail = (f"{layer.distribution} alpha=({layer.alpha_u:g}, {layer.alpha_v:g}), relative "
                 f"index {survey.snell_eta:.4g}: Snell-matched smooth transport with the rough "
                 "transmittance; the direct reflection is the microfacet lobe (layersim.lobe); "
                 f"{near_specular_error(hi)}")
    survey.lobes["top"] = {"eta": survey.snell_eta, "alpha_u": layer.alpha_u,
                           "alpha_v": layer.alpha_v, "distribution": layer.distribution,
                           "rotation": layer.rotation, "k": 0.0}
    survey.near_specular = (*survey.near_specular, i)
    return True


def _blurred_below(scene: Scene, i: int) -> bool:
    """True if a rough dielectric interface that the solve projects (not smooth, not
    near-specular) lies above layer ``i``: it blurs what layer ``i`` reflects by more than a
    near-specular lobe's width."""
    return any(isinstance(x, Dielectric) and min(x.alpha_u, x.alpha_v) > NEAR_SPECULAR_ALPHA
               for x in scene.channel(0).layers[:i])


def _near_specular_conductor(scene: Scene, i: int, layer, survey: Survey) -> bool:
    """Plan a nearly smooth conductor as a mirror (Fresnel diagonal) whose reflectance is the
    rough interface's reflected energy ``E_R`` (azimuth average, single-scattering loss
    included; :meth:`layersim.lobe.NearSpecularLobe.reflectance`), and return True; False
    where it is left to the exact projection.

    Alone (the top layer), the conductor is the whole BSDF: ``eval``, ``albedo`` and
    ``bin_energies`` use its exact microfacet lobe, and the mirror only stands for it when the
    BSDF is added to other layers. Under other layers its lobe (about ``2 alpha`` wide) must be
    blurred by a rough interface above it (:func:`_blurred_below`) and both its roughnesses be
    at most :data:`~layersim.lobe.NEAR_SPECULAR_BASE_ALPHA`; behind a smooth or near-specular coat
    the lobe is seen directly, and near the coat's critical angle part of it is trapped, which
    a mirror does not reproduce (``benchmarks/features/near_specular.txt``)."""
    if not isinstance(layer, Conductor):
        return False
    lo, hi = min(layer.alpha_u, layer.alpha_v), max(layer.alpha_u, layer.alpha_v)
    if lo > NEAR_SPECULAR_ALPHA:
        return False
    if i > 0 and (hi > NEAR_SPECULAR_BASE_ALPHA or not _blurred_below(scene, i)):
        why = (f"its wider roughness exceeds {NEAR_SPECULAR_BASE_ALPHA:g}"
               if hi > NEAR_SPECULAR_BASE_ALPHA else "no rough interface above it blurs its lobe")
        survey.hints.append(
            f"layer {i} (conductor) is near-specular but is projected exactly, at a cost that "
            f"grows like 1 / alpha: it is split into a mirror only under a rough interface "
            f"(alpha > {NEAR_SPECULAR_ALPHA:g}) and with both roughnesses at most "
            f"{NEAR_SPECULAR_BASE_ALPHA:g}, and here {why}; use layersim.montecarlo for this "
            "stack")
        return False
    if layer.energy_compensation != "none":
        # the mirror and its lobe have no compensation term (as near-specular coats)
        raise InfeasibleError(
            f"layer {i} (conductor): field 'energy_compensation': a near-specular conductor "
            f"(alpha <= {NEAR_SPECULAR_ALPHA:g}) is solved as a mirror with its lobe, which has "
            "no compensation term; set energy_compensation = \"none\" on this layer (its "
            "single-scattering loss is negligible but near grazing: a mirror of alpha 0.03 "
            "loses 1e-6 at 78 degrees, 1.6 % at 85)")
    where = ("alone: eval, albedo and bin_energies use its exact microfacet lobe "
             "(layersim.lobe)" if i == 0 else
             f"the rough interface above blurs its lobe; {near_specular_conductor_error(hi)}")
    survey.layers.append(LayerPlan(
        i, layer.kind, "near-specular conductor (mirror with the rough reflectance)",
        f"{layer.distribution} alpha=({layer.alpha_u:g}, {layer.alpha_v:g}): Fresnel diagonal "
        f"scaled to the rough reflected energy; {where}"))
    survey.near_specular = (*survey.near_specular, i)
    return True


def compensation_text(layer) -> str:
    """The plan's words for a rough interface's energy compensation (empty for none)."""
    mode = layer.energy_compensation
    if mode == "none":
        return ""
    what = {"multiple-scattering": "Kulla & Conty 2017 multiple-scattering lobe",
            "layerlab": "layerlab's near-diffuse correction"}[mode]
    return f"; energy compensation {mode!r} ({what}, order 0, solver and Monte Carlo)"


def interface_width(layer, eta_rel: complex) -> tuple[float, str]:
    """Angular width (radians) of the narrowest lobe of a rough interface and its name: about
    ``alpha`` in reflection, ``alpha |1 - 1/eta|`` in refraction (the refracted direction moves
    by that fraction of the facet tilt); infinite for an index-matched dielectric."""
    alpha = min(layer.alpha_u, layer.alpha_v)
    if isinstance(layer, Conductor):
        return alpha, "reflection lobe"
    eta = eta_rel.real
    if eta == 1.0:
        return math.inf, ""
    return alpha * abs(1.0 - 1.0 / max(eta, 1.0 / eta)), "refraction lobe"


def _fmt_eta(eta: complex) -> str:
    return f"{eta.real:.4g}" if eta.imag == 0 else f"{eta.real:.4g}+{eta.imag:.4g}i"
