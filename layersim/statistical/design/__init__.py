"""Inverse design of layered appearance (Bati et al. 2021): from target lobes at normal
incidence to layer stacks, checked against Belcour's forward model.

    scenes = layersim.design([{"energy": [0.04, 0.04, 0.04], "roughness": 0.05},
                              {"energy": [0.3, 0.2, 0.1], "roughness": 0.2,
                               "base": "conductor"}])

returns candidate :class:`~layersim.Scene` objects, preferred first (see
:mod:`.stacking` for which member of each equivalence class each candidate takes). An
unreachable target raises :class:`~layersim.statistical.targets.TargetError` (a ValueError)
naming the lobe and the bound. A bottom lobe without a ``base`` that no dielectric reaches gets
a conductor base, with a note (:mod:`.inference`).
"""

from __future__ import annotations

import itertools
from dataclasses import replace

from ..targets import TargetError, parse_targets
from .inference import InferredBaseWarning, conductor_alternative, inferred_note, warn
from .scene_out import Design, to_scene
from .stacking import design_stack

#: Equivalence-class choices tried (positions in each class, see :mod:`.stacking`), the
#: preferred first: the middle, as Bati et al. 2021 pick for conductors.
CHOICES = (0.5, 0.0, 1.0, 0.25, 0.75)


#: Per-lobe combinations of :data:`CHOICES` tried when no uniform choice succeeds (a lobe's
#: member of its class changes what the lobes below it can reach, Bati et al. 2021 sec. 8).
MAX_COMBINATIONS = 40


def _choices(lobes: int):
    yield from CHOICES
    if lobes > 1:
        combos = itertools.product(CHOICES, repeat=lobes - 1)
        for combo in itertools.islice(combos, MAX_COMBINATIONS):
            yield tuple(combo) + (0.5,)


def designs(targets, eta_max: float | None = None) -> list[Design]:
    """The candidate designs (:class:`Design`: scene, lobe groups, choice, notes), preferred
    first, without duplicates. Where the bottom lobe's base is not given and no dielectric
    design reaches the targets, those with a conductor base, each noting so in ``notes``.

    Raises
    ------
    TargetError
        Naming the first lobe that cannot be reached and the bound (where a conductor base
        was inferred and fails too, both bounds).
    """
    parsed = parse_targets(targets, eta_max)
    try:
        return _candidates(parsed)
    except TargetError as exc:
        alternative = conductor_alternative(parsed)
        if alternative is None:
            raise
        try:
            found = _candidates(alternative)
        except TargetError as other:
            raise TargetError(f"{exc}; with a conductor base: {other}") from None
        note = inferred_note(parsed, exc)
        return [replace(d, notes=d.notes + (note,)) for d in found]


def _candidates(parsed) -> list[Design]:
    """The candidates of parsed targets, bases as they stand."""
    out, seen, first_error = [], set(), None
    for choice in _choices(len(parsed.lobes)):
        if out and not isinstance(choice, float):
            break
        try:
            stacks, groups = design_stack(parsed, choice)
        except TargetError as exc:
            first_error = first_error or exc
            continue
        d = to_scene(stacks, groups, parsed, choice)
        key = repr(d.data)
        if key not in seen:
            seen.add(key)
            out.append(d)
    if not out:
        raise first_error
    return out


def design(targets, eta_max: float | None = None) -> list:
    """Candidate scenes for ``targets`` (a list of lobe dicts, a dict with ``lobe`` entries or
    a TOML path), preferred first.

    Raises
    ------
    TargetError
        For malformed or unreachable targets (names the lobe and the field or bound).

    Warns
    -----
    InferredBaseWarning
        Where the bottom lobe took a conductor base that the targets did not give (one line:
        why).
    """
    found = designs(targets, eta_max)
    for note in found[0].notes:
        warn(note)
    return [d.scene for d in found]


__all__ = ["design", "designs", "Design", "TargetError", "InferredBaseWarning"]
