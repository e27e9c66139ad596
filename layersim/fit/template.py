"""Fit templates: a scene whose free values are tables ``{ fit = [lo, hi], start = x }``.

A layer field, or an element of a list field (a conductor's ``ior = [eta, k]``, one channel of
a per-channel value, one axis of an anisotropic roughness), may be such a table; every other
value is fixed. :class:`Template` finds the free parameters, names them like
``layer[1].ior[1]``, checks each one against its field (the kind must declare it ``fit = True``,
:class:`layersim.layers.fields.Field`) and builds the concrete :class:`~layersim.scene.Scene` of
a parameter vector through :meth:`Scene.from_dict`, so that the field's own parser checks every
value, the bounds included.
"""

from __future__ import annotations

import copy
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ..errors import SceneError
from ..layers import kind_named
from ..scene import Scene

__all__ = ["Parameter", "Template"]

#: Keys of a free value's table.
FIT_KEYS = ("fit", "start")


@dataclass(frozen=True)
class Parameter:
    """One free value of a template.

    Attributes
    ----------
    name : str
        ``layer[i].field`` or ``layer[i].field[j]`` (``[j][k]`` for nested lists).
    path : tuple
        Keys from the scene dict to the value: ``("layer", i, field, j, ...)``.
    lo, hi : float
        Bounds (the field's unit, ``docs/conventions.md``).
    start : float
        The first value the optimiser tries (the midpoint by default).
    """

    name: str
    path: tuple
    lo: float
    hi: float
    start: float


def _is_free(value: Any) -> bool:
    return isinstance(value, Mapping) and "fit" in value


def _name(path: tuple) -> str:
    out = f"layer[{path[1]}].{path[2]}"
    for key in path[3:]:
        out += f"[{key}]" if isinstance(key, int) else f".{key}"
    return out


def _number(value: Any, what: str, source) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise SceneError(f"{what} must be a finite number, got {value!r}", source=source)
    return float(value)


def _parameter(path: tuple, table: Mapping, source) -> Parameter:
    """The parameter of the free table ``table`` at ``path``, its bounds and start checked."""
    name = _name(path)
    unknown = sorted(set(table) - set(FIT_KEYS))
    if unknown:
        raise SceneError(f"{name}: unknown key {unknown[0]!r} of a free value (allowed: fit, "
                         "start)", source=source)
    bounds = table["fit"]
    if not isinstance(bounds, (list, tuple)) or len(bounds) != 2:
        raise SceneError(f"{name}: fit must be [lo, hi], got {bounds!r}", source=source)
    lo = _number(bounds[0], f"{name}: fit lo", source)
    hi = _number(bounds[1], f"{name}: fit hi", source)
    if not lo < hi:
        raise SceneError(f"{name}: fit = [{lo:g}, {hi:g}] needs lo < hi", source=source)
    start = _number(table.get("start", 0.5 * (lo + hi)), f"{name}: start", source)
    if not lo <= start <= hi:
        raise SceneError(f"{name}: start = {start:g} is outside fit = [{lo:g}, {hi:g}]",
                         source=source)
    return Parameter(name, path, lo, hi, start)


def _walk(value: Any, path: tuple, source) -> list:
    """The free parameters within ``value`` (a field's value) at ``path``."""
    if _is_free(value):
        return [_parameter(path, value, source)]
    if isinstance(value, (list, tuple)):
        return [p for j, v in enumerate(value) for p in _walk(v, path + (j,), source)]
    if isinstance(value, Mapping):
        return [p for k, v in value.items() for p in _walk(v, path + (k,), source)]
    return []


def _refuse_free_outside_layers(data: Mapping, source) -> None:
    for section, table in data.items():
        if section == "layer" or not isinstance(table, Mapping):
            continue
        for key, value in table.items():
            if _is_free(value) or _walk(value, ("layer", 0, key), source):
                raise SceneError(f"[{section}] {key}: only layer fields can be fitted",
                                 source=source)


def _fittable(i: int, layer: Any, key: str, source) -> None:
    """Refuse a free value in a field that its kind does not let ``fit`` free."""
    kind = kind_named(layer.get("kind")) if isinstance(layer, Mapping) else None
    if kind is None:
        return                  # Scene.from_dict names the unknown kind
    declared = {f.name: f for f in kind.fields}
    if key not in declared:
        return                  # Scene.from_dict names the unknown field
    if not declared[key].fit:
        raise SceneError(f"field {key!r} of a {kind.name} layer cannot be fitted "
                         f"(fittable: {', '.join(f.name for f in kind.fields if f.fit)})",
                         layer=i, kind=kind.name, field=key, source=source)


def find_parameters(data: Mapping, source=None) -> list:
    """The free parameters of the template dict ``data``, in file order.

    Raises
    ------
    SceneError
        A malformed free table, a free value outside ``[[layer]]`` or in a field that its kind
        does not declare fittable (the layer and field are named), or no free value at all.
    """
    _refuse_free_outside_layers(data, source)
    params = []
    for i, layer in enumerate(data.get("layer", ()) or ()):
        if not isinstance(layer, Mapping):
            continue
        for key, value in layer.items():
            found = _walk(value, ("layer", i, key), source)
            if found:
                _fittable(i, layer, key, source)
            params += found
    if not params:
        raise SceneError("a fit template needs at least one free value "
                         "(a field written { fit = [lo, hi] })", source=source)
    return params


def _set(data: dict, path: tuple, value: float) -> None:
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value


class Template:
    """A scene with free values (module docstring).

    Parameters
    ----------
    data : dict, Template or path
        The template as a dict with the TOML file's content, or the path of a TOML file.
    source : str, optional
        Where it came from (named in errors; relative file paths in it resolve against it).

    Raises
    ------
    SceneError
        From :func:`find_parameters`, or when the scene at the start values, or with any one
        parameter at either of its bounds, is not a valid scene (the field's own bounds; the
        message names the parameter, the layer and the field).
    """

    def __init__(self, data, source: str | None = None):
        if isinstance(data, (str, Path)):
            source, data = str(data), _read_toml(Path(data))
        if not isinstance(data, Mapping):
            raise TypeError(f"a fit template is a dict or a TOML path, got {type(data).__name__}")
        self.data, self.source = copy.deepcopy(dict(data)), source
        self.params = find_parameters(self.data, source)
        self.start = np.array([p.start for p in self.params])
        self.lo = np.array([p.lo for p in self.params])
        self.hi = np.array([p.hi for p in self.params])
        self._check_bounds()

    @property
    def names(self) -> list:
        return [p.name for p in self.params]

    def as_dict(self, x) -> dict:
        """The template's dict with parameter ``k`` set to ``x[k]`` (its field's unit)."""
        data = copy.deepcopy(self.data)
        for p, v in zip(self.params, np.asarray(x, dtype=float)):
            _set(data, p.path, float(v))
        return data

    def scene(self, x, discretization: Mapping | None = None) -> Scene:
        """The concrete scene of the parameter vector ``x``, shape (P,); ``discretization``
        replaces the ``[discretization]`` table's entries it names."""
        data = self.as_dict(x)
        if discretization:
            data["discretization"] = {**data.get("discretization", {}), **discretization}
        return Scene.from_dict(data, source=self.source,
                               default_name=Path(self.source).stem if self.source else "fit")

    def _check_bounds(self) -> None:
        for k, p in enumerate(self.params):
            for end, value in (("start", p.start), ("lo", p.lo), ("hi", p.hi)):
                x = self.start.copy()
                x[k] = value
                try:
                    self.scene(x)
                except SceneError as exc:
                    # another parameter's start can be the value the field refuses
                    owner = self._owner(exc) or p
                    if owner is not p:
                        end, value = "start", owner.start
                    raise SceneError(f"{owner.name}: {'fit ' * (end != 'start')}{end} = "
                                     f"{value:g} is outside what the field allows "
                                     f"({exc})") from None

    def _owner(self, exc: SceneError) -> Parameter | None:
        """The parameter in the layer and field that ``exc`` names, if one is."""
        base = (exc.field or "").split("[")[0].split(".")[0]
        return next((p for p in self.params if p.path[1] == exc.layer and p.path[2] == base),
                    None) if exc.layer is not None else None


def _read_toml(path: Path) -> dict:
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise SceneError(f"cannot read template: {exc.strerror or exc}", source=str(path))
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise SceneError(f"not a TOML template: {exc}", source=str(path)) from None
