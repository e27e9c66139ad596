"""Design targets: the lobes wanted at normal incidence (Bati et al. 2021, sec. 3 and 6), read
from a TOML file or a list of dicts and validated once, with errors naming the lobe and field.

TOML layout::

    [design]                 # optional
    eta_max = 4.0            # largest dielectric index allowed (Bati et al. use 4)

    [[lobe]]                 # top lobe first
    energy = [0.04, 0.04, 0.04]   # fraction reflected in this lobe at normal incidence
    roughness = 0.05         # GGX alpha of the lobe (or: variance = Belcour's sigma)
    layers = 1               # 1 or 2 interfaces (optional: 1 where it can give the energy)
    base = "dielectric"      # or "conductor" (the bottom lobe only; left out: a conductor
                             # where no dielectric stack reaches the lobe)
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..errors import LayersimError
from .variance import roughness as to_roughness, variance as to_variance


class TargetError(LayersimError, ValueError):
    """A target that is malformed or outside what the stacks of the design can reach. Names
    the lobe (1 = top) and the field or bound."""

    def __init__(self, message: str, lobe: int | None = None, field: str | None = None,
                 source: str | None = None):
        where = [str(source)] if source else []
        if lobe is not None:
            where.append(f"lobe {lobe}")
        if field is not None:
            where.append(f"field '{field}'")
        prefix = ": ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)
        self.lobe, self.field, self.source = lobe, field, source


@dataclass(frozen=True)
class Target:
    """One wanted lobe: ``energy`` per channel (shape (C,)), Belcour ``variance`` and GGX
    ``roughness`` (equivalent), ``layers`` (1, 2 or None: choose), ``base`` and
    ``base_given`` (False where the targets leave the base to the design, which then takes a
    conductor where no dielectric reaches the lobe: :mod:`.design.inference`)."""

    energy: np.ndarray
    variance: float
    roughness: float
    layers: int | None = None
    base: str = "dielectric"
    base_given: bool = True


@dataclass(frozen=True)
class Targets:
    lobes: tuple
    eta_max: float = 4.0
    source: str | None = None

    @property
    def channels(self) -> int:
        return max(t.energy.size for t in self.lobes)


_LOBE_FIELDS = {"energy", "roughness", "variance", "layers", "base"}


def _number(x, lobe, fld, source, lo=None, hi=None, lo_open=False) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
        raise TargetError(f"must be a finite number, got {x!r}", lobe, fld, source)
    if lo is not None and (x < lo or (lo_open and x == lo)):
        raise TargetError(f"must be {'>' if lo_open else '>='} {lo:g}, got {x:g}", lobe, fld,
                          source)
    if hi is not None and x > hi:
        raise TargetError(f"must be <= {hi:g}, got {x:g}", lobe, fld, source)
    return float(x)


def _lobe(raw: Any, k: int, last: bool, source) -> Target:
    if not isinstance(raw, Mapping):
        raise TargetError(f"must be a table, got {type(raw).__name__}", k, None, source)
    unknown = sorted(set(raw) - _LOBE_FIELDS)
    if unknown:
        raise TargetError("unknown field (allowed: " + ", ".join(sorted(_LOBE_FIELDS)) + ")",
                          k, unknown[0], source)
    if "energy" not in raw:
        raise TargetError("is required", k, "energy", source)
    e = raw["energy"]
    values = e if isinstance(e, (list, tuple)) else [e]
    if len(values) not in (1, 3):
        raise TargetError(f"must be one value or 3 (R, G, B), got {len(values)}", k, "energy",
                          source)
    energy = np.array([_number(v, k, "energy", source, lo=0.0, hi=1.0, lo_open=True)
                       for v in values])
    if ("roughness" in raw) == ("variance" in raw):
        raise TargetError("give exactly one of 'roughness' (GGX alpha) and 'variance'", k,
                          "roughness", source)
    if "roughness" in raw:
        alpha = _number(raw["roughness"], k, "roughness", source, lo=0.0, hi=1.0)
        if alpha >= 1.0:
            raise TargetError("must be < 1 (Belcour's variance is infinite at 1)", k,
                              "roughness", source)
        var = to_variance(alpha)
    else:
        var = _number(raw["variance"], k, "variance", source, lo=0.0)
        alpha = to_roughness(var)
    layers = raw.get("layers")
    if layers is not None and (isinstance(layers, bool) or layers not in (1, 2)):
        raise TargetError(f"must be 1 or 2, got {layers!r}", k, "layers", source)
    base = raw.get("base", "dielectric")
    if base not in ("dielectric", "conductor"):
        raise TargetError(f"must be 'dielectric' or 'conductor', got {base!r}", k, "base",
                          source)
    if base == "conductor" and not last:
        raise TargetError("only the bottom lobe can have a conductor base (a conductor is "
                          "opaque)", k, "base", source)
    return Target(energy, var, alpha, layers, base, "base" in raw)


def parse_targets(value, eta_max: float | None = None) -> Targets:
    """Validate targets given as a TOML path, a dict with ``lobe`` (and ``design``) entries,
    or a list of lobe dicts (top first).

    Raises
    ------
    TargetError
        Naming the lobe (1 = top) and the field.
    """
    source = None
    if isinstance(value, (str, Path)):
        source = str(value)
        try:
            value = tomllib.loads(Path(value).read_text(encoding="utf-8"))
        except OSError as exc:
            raise TargetError(f"cannot read targets: {exc.strerror or exc}", source=source)
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise TargetError(f"not valid TOML: {exc}", source=source)
    design = {}
    if isinstance(value, Mapping):
        unknown = sorted(set(value) - {"lobe", "design"})
        if unknown:
            raise TargetError(f"unknown top-level entry '{unknown[0]}' (allowed: [[lobe]], "
                              "[design])", source=source)
        design = value.get("design", {})
        if not isinstance(design, Mapping) or set(design) - {"eta_max"}:
            raise TargetError("[design] takes only eta_max", source=source)
        value = value.get("lobe")
    if not isinstance(value, (list, tuple)) or not value:
        raise TargetError("no lobes: give a non-empty list of lobes ([[lobe]] tables)",
                          source=source)
    n = len(value)
    lobes = tuple(_lobe(raw, k + 1, k == n - 1, source) for k, raw in enumerate(value))
    if eta_max is None:
        eta_max = design.get("eta_max", 4.0)
    eta_max = _number(eta_max, None, "design.eta_max", source, lo=1.0, hi=4.0, lo_open=True)
    channels = {t.energy.size for t in lobes}
    if channels == {1, 3}:
        lobes = tuple(replace(t, energy=np.broadcast_to(t.energy, (3,)).copy()) for t in lobes)
    total = np.sum([t.energy for t in lobes], axis=0)
    if np.any(total >= 1.0):
        raise TargetError(f"the lobes' energies add up to {float(np.max(total)):.4g} >= 1 in a "
                          "channel: a passive stack reflects less than it receives",
                          None, "energy", source)
    return Targets(lobes, eta_max, source)
