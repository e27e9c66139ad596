"""The fields a layer kind declares, and the parsers that validate them.

A kind lists its fields once (:class:`Field`: name, what it means, unit, bounds through its
parser, default, whether it may differ per channel, whether ``fit`` may free it); the scene
parser checks every layer against that list (unknown and missing fields) and parses each value
with the field's parser. Every error is one line naming the layer, its kind and the field
(:class:`~layersim.errors.SceneError`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping

from ..errors import SceneError

__all__ = ["Ctx", "Field", "parse_fields", "real", "per_channel", "roughness", "conductor_ior",
           "film", "MAX_IOR", "MAX_K", "MAX_ROUGHNESS", "FILM_THICKNESS", "FILM_IOR"]

# Guard rails against inputs that are valid numbers but physically meaningless.
MAX_IOR = 100.0           # absolute index (real part), dielectric or conductor eta
MAX_K = 100.0             # conductor extinction coefficient
MAX_ROUGHNESS = 10.0      # Beckmann/GGX alpha; alpha > 1 is already very rough
#: Bounds of a thin film's thickness (nm; 10 um is far past where interference colours wash
#: out) and of its real index.
FILM_THICKNESS = (0.0, 10_000.0)
FILM_IOR = (1.0, 4.0)


class Ctx:
    """Where the parser is (source file, layer index, kind), to name the place in errors."""

    def __init__(self, source, layer=None, kind=None):
        self.source, self.layer, self.kind = source, layer, kind

    def error(self, fld, message) -> SceneError:
        return SceneError(message, layer=self.layer, kind=self.kind, field=fld,
                          source=self.source)


@dataclass(frozen=True)
class Field:
    """One field of a layer kind, declared once.

    Attributes
    ----------
    name : str
        The key in the scene file.
    doc : str
        What the value means (one line).
    unit : str
        Its unit ("" when dimensionless).
    parse : callable or None
        ``parse(ctx, name, value) -> value`` for one channel's value; None when the kind reads
        the field itself (a field whose meaning depends on another one).
    required : bool
    default : object
        The value of an absent optional field (before parsing).
    per_channel : bool
        A list of 3 (R, G, B) values is accepted (each parsed with ``parse``).
    fit : bool
        ``layersim.fit`` may free it.
    """

    name: str
    doc: str
    unit: str = ""
    parse: Callable | None = None
    required: bool = False
    default: Any = None
    per_channel: bool = False
    fit: bool = False


def parse_fields(ctx: Ctx, kind: str, fields: tuple, raw: Mapping[str, Any]) -> dict:
    """The values of ``raw`` (one ``[[layer]]`` table of kind ``kind``) for every declared field
    with a parser, in declaration order: a per-channel field gives a list of 1 or 3 values, any
    other field one value; an absent optional field its parsed default (or None).

    Raises
    ------
    SceneError
        For an undeclared key (naming the allowed ones), a missing required field, or a value
        its parser refuses.
    """
    declared = {f.name for f in fields}
    unknown = set(raw) - declared - {"kind"}
    if unknown:
        name = sorted(unknown)[0]
        raise ctx.error(name, f"unknown field for a {kind} layer (allowed: "
                              + ", ".join(sorted(declared)) + ")")
    missing = sorted(f.name for f in fields if f.required and f.name not in raw)
    if missing:
        raise ctx.error(missing[0], "is required")
    values = {}
    for f in fields:
        if f.parse is None:
            continue
        value = raw.get(f.name, f.default)
        if value is None:
            values[f.name] = None
        elif f.per_channel:
            values[f.name] = per_channel(ctx, f.name, value, f.parse)
        else:
            values[f.name] = f.parse(ctx, f.name, value)
    return values


def real(lo=None, hi=None, lo_open=False, hi_open=False) -> Callable:
    """A parser of a finite real number within ``[lo, hi]`` (open ends where asked)."""
    def parse(ctx: Ctx, fld: str, value: Any) -> float:
        return real_value(ctx, fld, value, lo, hi, lo_open, hi_open)
    return parse


def real_value(ctx: Ctx, fld: str, value: Any, lo=None, hi=None, lo_open=False,
               hi_open=False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ctx.error(fld, f"must be a number, got {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise ctx.error(fld, f"must be finite, got {value!r}")
    if lo is not None and (x < lo or (lo_open and x == lo)):
        raise ctx.error(fld, f"must be {'>' if lo_open else '>='} {lo:g}, got {x:g}")
    if hi is not None and (x > hi or (hi_open and x == hi)):
        raise ctx.error(fld, f"must be {'<' if hi_open else '<='} {hi:g}, got {x:g}")
    return x


def per_channel(ctx: Ctx, fld: str, value: Any, parse_one) -> list:
    """A scalar (shared by all channels) or a list of 3 per-channel values."""
    if isinstance(value, (list, tuple)):
        if len(value) != 3:
            raise ctx.error(fld, f"must be one value or a list of 3 (R, G, B) values, "
                                 f"got a list of {len(value)}")
        return [parse_one(ctx, f"{fld}[{c}]", v) for c, v in enumerate(value)]
    return [parse_one(ctx, fld, value)]


def roughness(ctx: Ctx, fld: str, value: Any) -> tuple[float, float]:
    """``alpha`` (isotropic) or ``[alpha_u, alpha_v]``: both zero (smooth) or both positive."""
    parse = real(lo=0.0, hi=MAX_ROUGHNESS)
    if isinstance(value, (list, tuple)):
        if len(value) != 2:
            raise ctx.error(fld, "must be one value (isotropic) or [alpha_u, alpha_v], "
                                 f"got a list of {len(value)}")
        au, av = parse(ctx, f"{fld}[0]", value[0]), parse(ctx, f"{fld}[1]", value[1])
        if (au == 0.0) != (av == 0.0):
            raise ctx.error(fld, f"[{au:g}, {av:g}] is smooth along one axis only; "
                                 "use 0 for both (smooth) or positive values for both")
        return au, av
    a = parse(ctx, fld, value)
    return a, a


def conductor_ior(ctx: Ctx, fld: str, value: Any) -> complex:
    """A conductor's complex index ``[eta, k]`` (k > 0)."""
    if isinstance(value, complex):
        eta, k = value.real, value.imag
        real_value(ctx, fld, eta)
        real_value(ctx, fld, k)
    elif isinstance(value, (list, tuple)) and len(value) == 2 and not any(
            isinstance(v, (list, tuple)) for v in value):
        eta, k = value
    else:
        raise ctx.error(fld, "a conductor index must be [eta, k] with k > 0 (or three [eta, k] "
                             f"pairs for R, G, B), got {value!r}")
    eta = real_value(ctx, fld + ".eta", eta, lo=0.0, hi=MAX_IOR)
    k = real_value(ctx, fld + ".k", k, lo=0.0, hi=MAX_K, lo_open=True)
    return complex(eta, k)


def film(ctx: Ctx, fld: str, value: Any) -> tuple[float, float]:
    """A thin film ``{ thickness = d, ior = n }``: ``(d, n)`` with ``d`` in nm within
    :data:`FILM_THICKNESS` and the real index ``n`` within :data:`FILM_IOR`."""
    if not isinstance(value, Mapping):
        raise ctx.error(fld, "must be a table { thickness = <nm>, ior = <real index> }, got "
                             f"{value!r}")
    unknown = sorted(set(value) - {"thickness", "ior"})
    if unknown:
        raise ctx.error(f"{fld}.{unknown[0]}", "unknown key of a film (allowed: thickness, ior)")
    for key in ("thickness", "ior"):
        if key not in value:
            raise ctx.error(f"{fld}.{key}", "is required (a film is { thickness = <nm>, ior = "
                                            "<real index> })")
    d = real_value(ctx, f"{fld}.thickness", value["thickness"], *FILM_THICKNESS)
    n = real_value(ctx, f"{fld}.ior", value["ior"], *FILM_IOR)
    return d, n


def choice(options: tuple, what: str) -> Callable:
    """A parser of one of ``options`` (named ``what`` in the error)."""
    def parse(ctx: Ctx, fld: str, value: Any):
        if value not in options:
            raise ctx.error(fld, f"unknown {what} {value!r}; expected one of "
                                 + ", ".join(options))
        return value
    return parse
