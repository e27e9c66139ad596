"""The coupling width ``ms``: coupled modes only where a layer is anisotropic.

Each anisotropic interface is projected with the ``ms`` its roughness ratio needs
(:func:`layersim.aniso.plan.ms_for_layer`); the stack's ``ms`` is the largest of them.
Isotropic layers keep their cosine-series operators and are converted only when added to a
coupled one.
"""

from __future__ import annotations

from ..aniso import plan as aplan
from ..scene import Discretization


def needed_ms(layers: list, left_out: list, notes: list) -> int:
    """The stack's ``ms`` (0 for an isotropic stack), with the report lines that say why
    (appended to ``left_out`` and ``notes``)."""
    ms = max((lp.ms for lp in layers), default=0)
    if not ms:
        left_out.append("anisotropic coupling (ms = 0): every projected layer is isotropic"
                        + (" (the anisotropy of near-specular layers is applied at evaluation,"
                           " layersim.solved.lobe, or averaged over the azimuth in a mirror)"
                           if any("near-specular" in lp.action for lp in layers) else ""))
        return 0
    iso = [lp for lp in layers if lp.action not in ("left out", "project (coupled modes)")]
    if iso:
        left_out.append("coupling in the isotropic layers (" + ", ".join(
            f"{lp.index}" for lp in iso) + "): they keep cosine-series operators and are "
            "converted (block diagonal) only when added to an anisotropic one")
    driver = max((lp for lp in layers if lp.ms), key=lambda lp: lp.ms)
    notes.append(f"coupled modes: ms = {ms} set by layer {driver.index} "
                 f"({driver.kind}), roughness ratio -> ms = ceil({aplan.MS_SLOPE} r "
                 f"{aplan.MS_OFFSET:+g}) (Zeltner & Jakob 2018, eq. (25)), +1 above alpha "
                 f"{aplan.MS_ROUGH:g} (benchmarks/accuracy/ms_study.py): relative L2 error < 1 %; "
                 f"+{aplan.MS_MARGIN} modes for bin energies to ~2e-4; "
                 f"coefficients below {aplan.COUPLED_RELERR:g} of their ordinate pair's "
                 "largest are dropped (layersim.aniso.plan.COUPLED_RELERR)")
    return ms


def choose_ms(disc: Discretization, layers: list, ms_needed: int, notes: list,
              overridden: dict) -> int:
    """``ms`` of the solve: the scene's override (which then also sets every coupled layer's
    ``ms``; at least 1) or ``ms_needed``. An isotropic stack keeps ``ms = 0``."""
    if disc.ms is None:
        return ms_needed
    overridden["ms"] = disc.ms
    anisotropic = ms_needed > 0
    if anisotropic and disc.ms < ms_needed:
        notes.append(f"ms = {disc.ms} from the scene is below the {ms_needed} the "
                     "anisotropy needs (relative L2 error above 1 %)")
    for lp in layers:
        if lp.ms:
            lp.ms = max(1, disc.ms) if anisotropic else 0
    return disc.ms if anisotropic else 0
