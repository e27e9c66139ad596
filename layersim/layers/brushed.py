"""Brushed near-specular top coats: the narrow axis near-specular, the wide axis rough.

A dielectric top coat whose narrower roughness is at most
:data:`~layersim.solved.lobe.NEAR_SPECULAR_ALPHA` and whose wider one exceeds
:data:`~layersim.solved.lobe.NEAR_SPECULAR_WIDE_MAX` (up to :data:`BRUSHED_WIDE_MAX`) needs many
ordinates for its narrow axis and many coupled modes for its ratio: (0.03, 0.3) over gold asks
for n = 650, ms = 26 and 14 GiB. In the adding equations (Grant & Hunt 1969; Zeltner & Jakob
2018, eq. (12)) the top interface's own reflection enters the stack's only additively::

    Rt = Rt1 + Tbt1 (I - Rt2 Rb1)^-1 Rt2 Ttb1

so the route splits the coat (:func:`projected_scene`, :func:`without_reflection`):

* its direct reflection ``Rt1`` is the exact anisotropic microfacet lobe (Walter et al. 2007,
  eq. 20; :class:`layersim.solved.lobe.NearSpecularLobe`), evaluated where the BSDF is
  (``BSDF.lobes["top"]``), and left out (zeroed) of the projected operator;
* everything that enters the coat is the Fourier solve of the stack in which the coat's
  narrow roughness is raised to a floor (the wide axis kept), extrapolated to the coat's own
  roughness from the solves at the floors :data:`BRUSHED_FLOORS` (below). Raising it widens
  the refraction blur of the narrow axis from ``alpha |1 - 1/eta|`` to ``alpha_f |1 - 1/eta|``
  (0.033 rad at eta 1.5), which a base that scatters over ``2 alpha_b`` (alpha_b >=
  :data:`BRUSHED_BASE_MIN`) hides: in slope space the variances add (Heitz 2014, sec. 5;
  Belcour 2018), and the base's lobe variance changes by about
  ``(alpha_f^2 - alpha^2) (1 - 1/eta)^2 / (2 alpha_b)^2`` (0.7 % for gold of 0.2). At
  oblique incidence the blur is wider than that, and the walk shows it (below).

Blurring by a narrow kernel changes a smooth result by a term proportional to the kernel's
variance to first order, and slope variances add, so the raised coat's operator (linear in its
BSDF) moves with the added variance ``v - v0``, ``v = floor^2``, ``v0 = alpha_narrow^2``, and
so, to first order, does the stack added with it. The route projects the coat at each floor of
:data:`BRUSHED_FLOORS` on one discretisation (the plan of the lowest floor, the finest),
combines the raised operators with the weights of Richardson extrapolation to ``v0``
(:func:`extrapolation_weights`, :func:`coat_operator`) and adds the stack once: one ordinary
Fourier BSDF. (Extrapolating the added stacks instead is equally first-order and costs an
adding per floor; measured, it is no more accurate: ``benchmarks/features/brushed_coats.txt``.)
The exact lobe does not depend on the floor and the weights sum to one, so it is kept as it is.

The error against the Monte Carlo walk (exact for any roughness) is measured by
``benchmarks/features/brushed_coats.py`` and printed by the plan (:data:`MEASURED_ERROR`). A coat
whose base does not blur (smooth or near-specular, or nothing opaque below) keeps the exact
projection, which the plan refuses for memory with the reason (:func:`why_not`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sps

from ..ingredients.energy_match import match_kept_energy
from ..operators.combine import linear_combination
from ..solved.lobe import NEAR_SPECULAR_ALPHA, NEAR_SPECULAR_WIDE_MAX, NearSpecularLobe

__all__ = ["BRUSHED_FLOORS", "BRUSHED_WIDE_MAX", "BRUSHED_BASE_MIN", "MEASURED_ERROR",
           "is_brushed", "why_not", "raised", "projected_scene", "extrapolation_weights",
           "projected", "annotate", "coat_operator", "without_reflection",
           "lobe_params"]

#: Narrow roughnesses at which a brushed coat is projected, all on the discretisation of the
#: lowest (the finest plan), and extrapolated to the coat's own (:func:`extrapolation_weights`).
#: Measured (``benchmarks/features/brushed_richardson.txt``, 1e7 walk paths, five coats over
#: gold of 0.2, the solved stacks extrapolated): one floor misses issue 33's accuracy bar
#: (albedo within 1e-3, 97 % of bins within 3 sigma) everywhere (0.1: 1.6-3.4e-3, 21-53 % at
#: the worst incidence); (0.12, 0.1) meets it on four of the five (narrow 0.001: 96.7 % of
#: bins at 70 deg); (0.15, 0.1) on three; (0.15, 0.12, 0.1) on all five at 1.5 times the cost.
#: With the coat's operators extrapolated before one adding (the route as built,
#: ``brushed_coats.txt``, six coats: 11-100 s on the 2-core VM) (0.12, 0.1) meets it on all.
#: Each floor on its own plan is worse: the plan's n, md and ms jump with the floor and their
#: error is not smooth in it.
BRUSHED_FLOORS = (0.12, 0.1)

#: Widest roughness of a brushed coat: at (0.1, 0.5) the projected stack over gold needs
#: n = 196, md = 601, ms = 14, 0.7 GiB and about 50 s on the 2-core VM (``layersim plan``).
BRUSHED_WIDE_MAX = 0.5

#: Narrowest lobe (radians of slope spread, :meth:`layersim.layers.base.Layer.lobe_width`)
#: that every interface below a brushed coat must have: at 0.1 the raised blur changes the
#: base's lobe variance by about 2.8 % at normal incidence (eta 1.5, floor 0.1); measured only
#: over gold of 0.2.
BRUSHED_BASE_MIN = 0.1

#: Measured error of the route against Monte Carlo (``benchmarks/features/brushed_coats.txt``,
#: 1e7 paths per direction, incidence 0-70 deg, 10 x 12 bins per side): ``(narrow alpha,
#: largest |albedo difference|, smallest fraction of populated bins within 3 sigma)`` of its
#: six cases over gold of 0.2 (wide 0.3-0.5, eta 1.3-1.7, one rotated, one RGB).
MEASURED_ERROR = (
    (0.03, 5.0e-4, 0.983),
    (0.001, 5.9e-4, 0.983),
    (0.01, 2.1e-4, 0.983),
    (0.02, 3.3e-4, 0.992),
    (0.03, 6.2e-4, 0.983),
    (0.03, 3.2e-4, 0.983),
)


def is_brushed(layer) -> bool:
    """True for a rough dielectric interface (analytic NDF, no film) whose narrow roughness is
    near-specular and whose wide one lies in (:data:`~layersim.solved.lobe.
    NEAR_SPECULAR_WIDE_MAX`, :data:`BRUSHED_WIDE_MAX`]."""
    if layer.kind != "dielectric" or layer.ndf is not None or layer.film is not None:
        return False
    lo, hi = min(layer.alpha_u, layer.alpha_v), max(layer.alpha_u, layer.alpha_v)
    return 0.0 < lo <= NEAR_SPECULAR_ALPHA and NEAR_SPECULAR_WIDE_MAX < hi <= BRUSHED_WIDE_MAX


def why_not(mono) -> str | None:
    """Why the one-channel scene ``mono``, whose top layer is brushed (:func:`is_brushed`),
    cannot take the route (None if it can): nothing opaque below, or an interface below that
    scatters narrower than :data:`BRUSHED_BASE_MIN` and so shows the coat's raised blur."""
    below = mono.layers[1:]
    if not below or not below[-1].opaque:
        return "nothing opaque below it scatters what enters it"
    for j, x in enumerate(below, start=1):
        if x.is_interface and x.lobe_width() < BRUSHED_BASE_MIN:
            return (f"layer {j} ({x.kind}) below it scatters narrower than alpha "
                    f"{BRUSHED_BASE_MIN:g} and would show the coat's own refraction blur")
    return None


def raised(layer, floor: float):
    """``layer`` with its narrow roughness raised to ``floor`` (never above the wide one); the
    wide axis, rotation and everything else kept."""
    au, av = layer.alpha_u, layer.alpha_v
    wide = max(au, av)
    lift = lambda a: max(a, min(floor, wide))
    return replace(layer, alpha_u=lift(au), alpha_v=lift(av))


def projected_scene(scene):
    """The scene the Fourier solve projects, and the hints of a route not taken.

    Returns
    -------
    (Scene, bool, list of str)
        ``scene`` with a brushed top coat raised to the lowest of :data:`BRUSHED_FLOORS`
        (read when called; its plan is the solve's, :func:`coat_operator` projects the coat
        at each floor) in every channel
        (itself where the route does not apply), True if it was, and a report line for a
        brushed coat left to the exact projection (why, from :func:`why_not`).
    """
    mono = scene.channel(0)
    top = mono.layers[0]
    if not is_brushed(top):
        return scene, False, []
    why = why_not(mono)
    if why is not None:
        return scene, False, [
            f"layer 0 (dielectric) is a brushed near-specular coat (alpha=({top.alpha_u:g}, "
            f"{top.alpha_v:g})) but is projected exactly, at a cost that grows like 1 / alpha: "
            f"{why}; use layersim.montecarlo for this stack"]
    floor = min(BRUSHED_FLOORS)
    stacks = tuple((raised(s[0], floor),) + tuple(s[1:]) for s in scene.stacks)
    return replace(scene, stacks=stacks), True, []


def extrapolation_weights(v0: float, vs) -> np.ndarray:
    """Richardson extrapolation in the added slope variance: the weights ``w`` such that
    ``sum_i w_i X(v_i)`` is the polynomial through the solves' outputs ``X(v_i)`` evaluated at
    ``v0``.

    Blurring by a narrow kernel changes a smooth result by a term proportional to the kernel's
    variance to first order (its Taylor expansion; the second moment is the variance), and
    slope-space variances add under convolution (Heitz 2014, sec. 5; Belcour 2018, sec. 5), so
    an output of the raised solve is, to first order, linear in ``v = floor^2``; the Lagrange
    weights at ``v0`` cancel that term (two points) or also the next (three) (Richardson 1911).

    Parameters
    ----------
    v0 : float
        Slope variance to extrapolate to: the coat's narrow ``alpha^2`` (dimensionless).
    vs : sequence of float, length m >= 1
        Slope variances of the solves (``floor^2``), distinct.

    Returns
    -------
    ndarray, shape (m,)
        ``w_i = prod_{j != i} (v0 - v_j) / (v_i - v_j)``; they sum to one. For m = 2,
        ``w . X = X_2 + (v0 - v_2) (X_1 - X_2) / (v_1 - v_2)``.
    """
    vs = np.asarray(vs, float)
    return np.array([np.prod([(v0 - vj) / (vi - vj) for j, vj in enumerate(vs) if j != i])
                     for i, vi in enumerate(vs)])


def projected(scene, plan):
    """The scene the Fourier solve of ``scene`` projects on ``plan``: its brushed coat
    (``plan.brushed``) raised to the lowest floor (:func:`coat_operator` projects it at each),
    or ``scene`` itself."""
    return scene if plan.brushed is None else projected_scene(scene)[0]


def annotate(survey, scene) -> None:
    """Mark layer 0 of ``survey`` (the survey of :func:`projected_scene`'s scene) as the
    brushed route of ``scene``'s top coat: the floors, their weights and the measured error in
    its plan line; the floors, weights and the coat's roughness in ``survey.brushed``. A floor
    above the wide roughness raises the narrow axis only to it, and its variance is that."""
    floors = tuple(sorted(BRUSHED_FLOORS, reverse=True))
    top = scene.channel(0).layers[0]
    narrow = lambda layer: min(layer.alpha_u, layer.alpha_v)
    weights = extrapolation_weights(narrow(top) ** 2, [narrow(raised(top, f)) ** 2
                                                      for f in floors])
    lp = next(x for x in survey.layers if x.index == 0)
    if lp.ms:   # coupled: its own reflection (the exact lobe replaces it) is not projected
        lp.blocks = ("Rb", "Ttb", "Tbt")
    solved = ", ".join(f"{f:g}" for f in floors)
    lp.detail = (f"brushed near-specular coat alpha=({top.alpha_u:g}, {top.alpha_v:g}): its "
                 f"direct reflection is the exact microfacet lobe (layersim.solved.lobe), left "
                 f"out of the projection; the light that enters it is projected with the narrow "
                 f"roughness raised to {solved} on one discretisation (that of "
                 f"{min(floors):g}) and extrapolated to {min(top.alpha_u, top.alpha_v):g} in the "
                 f"slope variance (weights {', '.join(f'{w:+.3f}' for w in weights)}; "
                 f"layersim.layers.brushed) -- {lp.detail}; {error_line()}")
    survey.brushed = {"floor": min(floors), "floors": floors,
                      "weights": tuple(float(w) for w in weights),
                      "alpha_u": top.alpha_u, "alpha_v": top.alpha_v}


def error_line() -> str:
    """The plan's words for :data:`MEASURED_ERROR` (its worst row)."""
    if not MEASURED_ERROR:
        return "its error against Monte Carlo is not measured"
    dr = max(row[1] for row in MEASURED_ERROR)
    frac = min(row[2] for row in MEASURED_ERROR)
    return (f"measured against Monte Carlo over rough gold, narrow alpha 0.001-0.03, wide "
            f"0.3-0.5 (benchmarks/features/brushed_coats.txt): albedo within {dr:.1e}, as few as "
            f"{100 * frac:.1f} % of 10 x 12 bins within 3 sigma of 1e7 paths at 0-70 deg; "
            "where that matters, use layersim.montecarlo")


def coat_operator(job, project):
    """The operator of the brushed coat as the stack uses it: at each floor of
    ``plan.brushed``, ``project`` (the kind's projection) of the coat raised to it, of the
    blocks its layer plan names (not its own reflection where the projection is coupled:
    :func:`annotate`), rescaled so that inside light keeps the exact coat's energy
    ``E_R + E_T`` per elevation (:func:`layersim.ingredients.energy_match.match_kept_energy`;
    the exact lobe of :func:`lobe_params` seen from inside), its own reflection left out
    (:func:`without_reflection`); the raised operators combined with the extrapolation
    weights (:func:`layersim.operators.combine.linear_combination`), so that the stack is
    added once."""
    b = job.plan.brushed
    own = replace(job.layer, alpha_u=b["alpha_u"], alpha_v=b["alpha_v"])
    kept = np.add(*NearSpecularLobe(**lobe_params(job.scene, b)).inside_energies(job.grid.mu))
    ops = []
    for floor in b["floors"]:
        op = project(replace(job, scene=job.scene.with_layer(0, raised(own, floor)),
                             workspace=None, blocks=job.layer_plan.blocks))
        ops.append(without_reflection(match_kept_energy(op, kept)[0]))
        del op
    return linear_combination(ops, b["weights"])


def without_reflection(op):
    """The coupled operator ``op`` of the raised coat with its own reflection ``Rt`` (and
    that block's delta part) left out, for the exact lobe to replace at evaluation."""
    blocks = dict(op.blocks)
    blocks["Rt"] = sps.csr_matrix(blocks["Rt"].shape)
    delta = {k: v for k, v in op.delta.items() if k != "Rt"}
    return type(op)(op.grid, op.md, blocks, op.eta_top, op.eta_bottom, delta, ms=op.ms)


def lobe_params(mono, brushed: dict) -> dict:
    """The parameters of the exact lobe (:class:`layersim.solved.lobe.NearSpecularLobe`) of
    the top coat of the one-channel scene ``mono`` (as given or as projected), with the
    coat's own roughness from ``brushed`` (:attr:`layersim.plan.Plan.brushed`)."""
    top = mono.layers[0]
    return {"eta": mono.relative_ior(0).real, "alpha_u": brushed["alpha_u"],
            "alpha_v": brushed["alpha_v"], "distribution": top.distribution,
            "rotation": top.rotation, "k": 0.0}
