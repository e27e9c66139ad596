"""Which base the bottom lobe takes when the targets leave it open.

Bati et al. 2021 design a lobe on a dielectric unless told it lies on a conductor (sec. 5.1.2
and 5.2.4). A dielectric lobe is bounded: in air a 1-layer lobe reaches at most the FGD of
index ``eta_max`` (0.36 at ``eta_max = 4``, sec. 5.2.1) and is achromatic, a 2-layer one at
most 0.53; a metal-coloured lobe such as energy (0.9, 0.7, 0.5) lies beyond both. Where the
bottom lobe's base is not given (``base`` left out of its ``[[lobe]]`` table) and no dielectric
design reaches the targets, the design takes a conductor base instead and says so in one line
(:func:`inferred_note`); a base the targets give is kept, reachable or not.
"""

from __future__ import annotations

import re
import sys
import warnings
from dataclasses import replace

from ..targets import TargetError, Targets

__all__ = ["conductor_alternative", "inferred_note", "warn", "InferredBaseWarning"]

#: The ``lobe K: field 'F': `` prefix of a :class:`TargetError` message.
_PREFIX = re.compile(r"^lobe \d+: (field '[^']*': )?")


class InferredBaseWarning(UserWarning):
    """:func:`layersim.design` took a conductor base that the targets did not ask for."""


def conductor_alternative(targets: Targets) -> Targets | None:
    """``targets`` with a conductor base under the bottom lobe, or None where its base is
    given or already a conductor (nothing to infer)."""
    last = targets.lobes[-1]
    if last.base_given or last.base == "conductor":
        return None
    return replace(targets, lobes=targets.lobes[:-1] + (replace(last, base="conductor"),))


def _first_reason(exc: TargetError) -> str:
    """The first bound of ``exc``'s message without its lobe and field (a lobe tried with 1
    and 2 layers names both bounds)."""
    return _PREFIX.sub("", str(exc).split("; with 2 layers:")[0])


def inferred_note(targets: Targets, dielectric_error: TargetError) -> str:
    """The line that says the bottom lobe got a conductor base and why: the bound the
    dielectric design ran into."""
    k = len(targets.lobes)
    last = targets.lobes[k - 1]
    energy = "/".join(f"{e:.3g}" for e in last.energy)
    return (f"lobe {k}: base = \"conductor\" inferred: no dielectric stack reaches energy "
            f"{energy} at roughness {last.roughness:.3g} ({_first_reason(dielectric_error)}); "
            "write base = \"dielectric\" or \"conductor\" in the lobe to choose")


def warn(note: str) -> None:
    """Issue ``note`` as an :class:`InferredBaseWarning` attributed to the first caller
    outside layersim (``layersim.design`` reaches the design through a wrapper)."""
    level, frame = 2, sys._getframe(1)
    while frame is not None and frame.f_globals.get("__name__", "").startswith("layersim"):
        level, frame = level + 1, frame.f_back
    warnings.warn(note, InferredBaseWarning, stacklevel=level)
