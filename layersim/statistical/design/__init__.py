"""Inverse design of layered appearance (Bati et al. 2021): from target lobes at normal
incidence to layer stacks, checked against Belcour's forward model.

    scenes = layersim.design([{"energy": [0.04, 0.04, 0.04], "roughness": 0.05},
                              {"energy": [0.3, 0.2, 0.1], "roughness": 0.2,
                               "base": "conductor"}])

returns candidate :class:`~layersim.Scene` objects, preferred first (see
:mod:`.stacking` for which member of each equivalence class each candidate takes). An
unreachable target raises :class:`~layersim.statistical.targets.TargetError` (a ValueError)
naming the lobe and the bound.
"""

from __future__ import annotations

from ..targets import TargetError, parse_targets
from .scene_out import Design, to_scene
from .stacking import design_stack

#: Equivalence-class choices tried, the preferred first.
CHOICES = ("centre", "low", "high")


def designs(targets, eta_max: float | None = None) -> list[Design]:
    """The candidate designs (:class:`Design`: scene, lobe groups, choice), preferred first,
    without duplicates."""
    parsed = parse_targets(targets, eta_max)
    out, seen = [], set()
    for choice in CHOICES:
        try:
            stacks, groups = design_stack(parsed, choice)
        except TargetError:
            if choice == CHOICES[0]:
                raise
            continue
        d = to_scene(stacks, groups, parsed, choice)
        key = d.toml()
        if key not in seen:
            seen.add(key)
            out.append(d)
    return out


def design(targets, eta_max: float | None = None) -> list:
    """Candidate scenes for ``targets`` (a list of lobe dicts, a dict with ``lobe`` entries or
    a TOML path), preferred first.

    Raises
    ------
    TargetError
        For malformed or unreachable targets (names the lobe and the field or bound).
    """
    return [d.scene for d in designs(targets, eta_max)]


__all__ = ["design", "designs", "Design", "TargetError"]
