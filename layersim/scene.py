"""Scene description: a stack of layers, parsed and validated once.

A scene lists layers from top to bottom (see ``docs/conventions.md``). Both the Fourier solver and
the Monte Carlo reference consume the validated :class:`Scene`; neither re-parses or re-checks
physics parameters.

Per-channel (RGB) values: any physical value may be given as a list of three (R, G, B) values
(a conductor's ``ior`` as three ``[eta, k]`` pairs; a medium's ``albedo`` and ``g``). Such a
scene has ``channels == 3``; :meth:`Scene.channel` returns the monochromatic scene of one
channel. Roughness and rotation are shared by all channels; a per-channel ``tau`` (coloured
Beer-Lambert absorption) is planned for its largest value; the plan takes the most demanding
channel of a per-channel ``g`` (:mod:`layersim.plan.layers`).

Wavelengths: ``[stack] wavelengths`` (nm, one or three values) gives each channel its vacuum
wavelength; a thin film on an interface (``film``) needs them, and its records carry their
channel's wavelength. Per-channel values must then come one per wavelength.

Units: angles in degrees in files, radians in the dataclasses; indices of refraction are absolute
(the medium above the stack has ``top_ior``, 1 by default); ``tau`` is optical thickness along the
normal (dimensionless).
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .errors import SceneError
from .layers import (COMPENSATIONS, DISTRIBUTIONS, SHADOWINGS, Conductor, Dielectric, Diffuse,
                     Layer, Measured, Medium, kind_named, kind_of, names)
from .layers.fields import MAX_IOR as _MAX_IOR
from .layers.fields import Ctx as _Ctx
from .layers.fields import real_value as _real

__all__ = [
    "Layer", "Dielectric", "Conductor", "Medium", "Diffuse", "Measured", "Discretization",
    "Scene", "QUADRATURES", "DISTRIBUTIONS", "COMPENSATIONS", "as_scene",
]

#: Quadrature rules on mu in [-1, 1] (see :mod:`layersim.operators.quadrature`).
QUADRATURES = ("gauss-lobatto", "gauss-legendre", "simpson38")

_MAX_N = 4096             # ordinates
#: Fourier orders a scene may ask for (``[discretization] md``): the planner's limit
#: (:data:`layersim.plan.MD_MAX`), so that the validator and the solver refuse the same values.
MAX_ORDERS = 20_000


# --------------------------------------------------------------------------------------------
# Discretization
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Discretization:
    """User overrides of the discretisation plan; ``None`` = let the planner choose.

    n : number of ordinates on mu in [-1, 1] (even); md : number of Fourier orders in the azimuth
    difference (cosine orders 0..md-1, or complex modes -(md-1)..md-1); ms : coupling half-width
    in the azimuth sum (modes -ms..ms; 0 for isotropic stacks); quadrature : one of
    :data:`QUADRATURES`; tol : relative error of bin energies that :func:`layersim.solve`
    solves to (:mod:`layersim.plan.accuracy`; not with ``n`` or ``md``); theta_full : elevation
    (degrees, 80 by default) within which ordinate pairs keep every Fourier order their lobes
    need (:mod:`layersim.plan.orders`; closer to 90 keeps grazing peaks sharp at more orders).
    """

    n: int | None = None
    md: int | None = None
    ms: int | None = None
    quadrature: str | None = None
    tol: float | None = None
    theta_full: float | None = None


# --------------------------------------------------------------------------------------------
# Scene
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Scene:
    """A validated layer stack.

    Use :meth:`from_toml` or :meth:`from_dict`; the constructor does not validate.

    Attributes
    ----------
    stacks : tuple of tuple of Layer
        ``stacks[c]`` is the list of layers (top to bottom) of channel ``c``.
    top_ior : float
        Absolute index of the medium above the stack.
    discretization : Discretization
        User overrides (all ``None`` when the planner should decide).
    name : str
        Short name (file stem or ``[stack] name``).
    source : str or None
        Where the scene came from (file path), used in messages.
    wavelengths : tuple of float or None
        Vacuum wavelength (nm) of each channel (``[stack] wavelengths``), or None.
    """

    stacks: tuple[tuple[Layer, ...], ...]
    top_ior: float = 1.0
    discretization: Discretization = field(default_factory=Discretization)
    name: str = "scene"
    source: str | None = None
    wavelengths: tuple[float, ...] | None = None

    # ---- construction ------------------------------------------------------------------

    def to_dict(self) -> dict:
        """The scene as a dict with the TOML file's content (``docs/conventions.md``), which
        :meth:`from_dict` reads back to an equal scene: each layer's table from its kind
        (:meth:`layersim.layers.LayerKind.to_raw`; every field written explicitly, per-channel
        values as lists where the channels differ), ``[stack]`` and the ``[discretization]``
        overrides.

        Raises
        ------
        SceneError
            For a layer that cannot be written back (a measured base: its data come from its
            file), naming the layer and its kind.
        """
        stack = {"name": self.name, "top_ior": self.top_ior}
        if self.wavelengths is not None:
            stack["wavelengths"] = list(self.wavelengths)
        layers = []
        for i, records in enumerate(zip(*self.stacks)):
            try:
                layers.append(kind_of(records[0]).to_raw(records))
            except SceneError as exc:
                raise SceneError(str(exc).split(": ", 1)[-1], layer=i,
                                 kind=records[0].kind, source=self.source) from None
        out = {"stack": stack, "layer": layers}
        disc = {k: v for k, v in self.discretization.__dict__.items() if v is not None}
        if disc:
            out["discretization"] = disc
        return out

    @classmethod
    def from_pbrt(cls, text: str, name: str = "pbrt") -> "Scene":
        """The scene of the one material of a pbrt-v4 scene text (``coatedconductor``,
        ``coateddiffuse``, ``conductor``, ``dielectric``, ``diffuse``; GGX with pbrt-v4's
        height-correlated Smith term): :func:`layersim.pbrtimport.pbrt_to_dict`, whose notes
        say what was not needed.

        Raises
        ------
        SceneError
            An unsupported material, parameter or named spectrum (the parameter is named).
        """
        from .pbrtimport import pbrt_to_dict
        return cls.from_dict(pbrt_to_dict(text, name)[0])

    @classmethod
    def from_toml(cls, path: str | Path) -> "Scene":
        """Read and validate a TOML scene file (see ``docs/conventions.md`` for the format).

        Raises
        ------
        TypeError
            If ``path`` is not a path (str or os.PathLike); a dict goes to :meth:`from_dict`.
        SceneError
            If the file cannot be read, is not UTF-8 TOML text, or describes an invalid scene
            (the message names the file, the layer, its kind and the field).
        """
        if not isinstance(path, (str, os.PathLike)):
            hint = "; for a dict use Scene.from_dict" if isinstance(path, Mapping) else ""
            raise TypeError("Scene.from_toml takes the path (str or pathlib.Path) of a TOML "
                            f"scene file, got {type(path).__name__}{hint}")
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise SceneError(f"cannot read scene file: {exc.strerror or exc}", source=str(path))
        except UnicodeDecodeError:
            raise SceneError("not a scene: the file is not UTF-8 text (a scene is a TOML "
                             "file; saved BSDFs and .bsdf files go to 'layersim info', 'eval', "
                             "'plot')", source=str(path)) from None
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise SceneError(f"not valid TOML: {exc}", source=str(path))
        return cls.from_dict(data, source=str(path), default_name=path.stem)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str | None = None,
                  default_name: str = "scene") -> "Scene":
        """Validate a scene given as a dict with the same content as the TOML file."""
        return _parse_scene(data, source, default_name)

    # ---- channels ----------------------------------------------------------------------

    @property
    def channels(self) -> int:
        return len(self.stacks)

    @property
    def layers(self) -> tuple[Layer, ...]:
        """Layers of a monochromatic scene (for RGB scenes use :meth:`channel`)."""
        if self.channels != 1:
            raise ValueError(f"scene '{self.name}' has {self.channels} channels; "
                             "use scene.channel(c).layers")
        return self.stacks[0]

    def channel(self, c: int) -> "Scene":
        """The monochromatic scene of channel ``c``."""
        if not 0 <= c < self.channels:
            raise IndexError(f"channel {c} out of range for a {self.channels}-channel scene")
        return replace(self, stacks=(self.stacks[c],),
                       name=self.name if self.channels == 1 else f"{self.name}[{'RGB'[c]}]",
                       wavelengths=None if self.wavelengths is None else
                       (self.wavelengths[c],))

    def with_layer(self, i: int, layer: Layer) -> "Scene":
        """The monochromatic scene with layer ``i`` replaced by ``layer`` (a route's variant
        of it: raised, or at its own roughness)."""
        layers = self.layers
        return replace(self, stacks=(layers[:i] + (layer,) + layers[i + 1:],))

    # ---- derived optics (monochromatic) ------------------------------------------------

    @property
    def opaque(self) -> bool:
        """True if the bottom layer is opaque (no transmission out of the stack)."""
        return self.stacks[0][-1].opaque

    @property
    def anisotropic(self) -> bool:
        return any(layer.anisotropic for layer in self.stacks[0])

    def ior_above(self, i: int) -> float:
        """Absolute (real) index of the medium directly above layer ``i``."""
        eta = self.top_ior
        for layer in self.layers[:i]:
            eta = layer.index_below(eta)
        return eta

    def relative_ior(self, i: int) -> complex:
        """Index of the medium below interface ``i`` relative to the medium above it."""
        layer = self.layers[i]
        if not layer.is_interface:
            raise ValueError(f"layer {i} ({layer.kind}) is not an interface")
        return layer.ior / self.ior_above(i)

    @property
    def bottom_ior(self) -> float | None:
        """Absolute index of the medium below the stack, or None when the stack is opaque."""
        if self.opaque:
            return None
        return self.ior_above(len(self.layers))

    def describe(self) -> str:
        """One line per layer, for the CLI and reports."""
        lines = [f"scene '{self.name}': {len(self.stacks[0])} layer(s), top index "
                 f"{self.top_ior:g}, {self.channels} channel(s)"
                 + ("" if self.wavelengths is None else
                    " at " + ", ".join(f"{x:g}" for x in self.wavelengths) + " nm")]
        for i, layers in enumerate(zip(*self.stacks)):
            lines.append(f"  [{i}] " + kind_of(layers[0]).describe(layers))
        return "\n".join(lines)


def as_scene(value, caller: str = "solve()") -> Scene:
    """``value`` as a :class:`Scene`: a Scene itself, a path read with :meth:`Scene.from_toml`
    or a dict validated with :meth:`Scene.from_dict`, as the functions that take a scene
    (``caller``) accept.

    Raises
    ------
    TypeError
        For anything else, saying what to pass.
    """
    if isinstance(value, Scene):
        return value
    if isinstance(value, (str, os.PathLike)):
        return Scene.from_toml(value)
    if isinstance(value, Mapping):
        return Scene.from_dict(value)
    raise TypeError(f"{caller} takes a Scene (layersim.Scene.from_toml or from_dict), the path "
                    f"of a TOML scene file or a dict of the same content, got "
                    f"{type(value).__name__}")


# --------------------------------------------------------------------------------------------
# Parsing and validation
# --------------------------------------------------------------------------------------------

_TOP_FIELDS = {"layer", "stack", "discretization"}
_STACK_FIELDS = {"top_ior", "name", "energy_compensation", "wavelengths", "shadowing"}
#: Vacuum wavelengths (nm) a scene may give its channels.
WAVELENGTH_RANGE = (100.0, 20_000.0)
_DISC_FIELDS = {"n", "md", "ms", "quadrature", "tol", "theta_full"}


def _parse_layer(ctx: _Ctx, raw: Any, defaults: Mapping[str, Any]) -> list[Layer]:
    """The records of one ``[[layer]]`` table, parsed by its kind (:mod:`layersim.layers`)."""
    if not isinstance(raw, Mapping):
        raise ctx.error(None, f"must be a table with a 'kind', got {type(raw).__name__}")
    if "kind" not in raw:
        raise ctx.error("kind", "is missing; one of " + ", ".join(names()))
    kind = kind_named(raw["kind"]) if isinstance(raw["kind"], str) else None
    if kind is None:
        raise ctx.error("kind", f"unknown kind {raw['kind']!r}; expected one of "
                                + ", ".join(names()))
    ctx.kind = kind.name
    return kind.parse(ctx, raw, defaults)


def _parse_int(ctx: _Ctx, fld: str, value: Any, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ctx.error(fld, f"must be an integer, got {value!r}")
    if not lo <= value <= hi:
        raise ctx.error(fld, f"must be within [{lo}, {hi}], got {value}")
    return value


def _parse_scene(data: Mapping[str, Any], source: str | None, default_name: str) -> Scene:
    if not isinstance(data, Mapping):
        raise SceneError(f"a scene must be a table/dict, got {type(data).__name__}", source=source)
    unknown = set(data) - _TOP_FIELDS
    if unknown:
        raise SceneError(f"unknown top-level entry '{sorted(unknown)[0]}' (allowed: "
                         "[[layer]], [stack], [discretization])", source=source)
    top_ior, name, defaults = _parse_stack(data.get("stack", {}), source, default_name)
    stacks = _parse_layers(data.get("layer"), source, defaults)
    disc = _parse_discretization(data.get("discretization", {}), source)
    return Scene(stacks=stacks, top_ior=top_ior, discretization=disc, name=name, source=source,
                 wavelengths=defaults["wavelengths"])


def _parse_stack(stack: Any, source: str | None, default_name: str) -> tuple:
    """``(top_ior, name, defaults)`` of the ``[stack]`` table; ``defaults`` holds the values
    layers inherit."""
    if not isinstance(stack, Mapping):
        raise SceneError("[stack] must be a table", source=source)
    unknown = set(stack) - _STACK_FIELDS
    if unknown:
        raise SceneError(f"unknown field '{sorted(unknown)[0]}' in [stack] (allowed: top_ior, "
                         "name, energy_compensation, wavelengths, shadowing)", source=source)
    ctx = _Ctx(source)
    top_ior = _real(ctx, "stack.top_ior", stack.get("top_ior", 1.0), lo=0.0, hi=_MAX_IOR,
                    lo_open=True)
    name = stack.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise SceneError("[stack] name must be a non-empty string", source=source)
    compensation = stack.get("energy_compensation", "none")
    if compensation not in COMPENSATIONS:
        raise SceneError(f"[stack] energy_compensation: unknown compensation {compensation!r}; "
                         "expected one of " + ", ".join(COMPENSATIONS), source=source)
    shadowing = stack.get("shadowing", "separable")
    if shadowing not in SHADOWINGS:
        raise SceneError(f"[stack] shadowing: unknown shadowing {shadowing!r}; expected one of "
                         + ", ".join(SHADOWINGS), source=source)
    wavelengths = _parse_wavelengths(ctx, stack.get("wavelengths"))
    return top_ior, name, {"energy_compensation": compensation, "wavelengths": wavelengths,
                           "shadowing": shadowing}


def _parse_layers(raw_layers: Any, source: str | None, defaults: Mapping[str, Any]) -> tuple:
    """The per-channel stacks of the ``[[layer]]`` tables (an opaque layer only at the
    bottom)."""
    if raw_layers is None:
        raise SceneError("no layers: add at least one [[layer]] table", source=source)
    if not isinstance(raw_layers, (list, tuple)) or not raw_layers:
        raise SceneError("'layer' must be a non-empty list of [[layer]] tables", source=source)
    per_layer = [_parse_layer(_Ctx(source, layer=i), raw, defaults)
                 for i, raw in enumerate(raw_layers)]
    for i, versions in enumerate(per_layer):
        if versions[0].opaque and i != len(per_layer) - 1:
            raise SceneError(f"an opaque {versions[0].kind} layer must be the bottom layer; "
                             f"{len(per_layer) - 1 - i} layer(s) below it would never receive "
                             "light", layer=i, kind=versions[0].kind, field="kind",
                             source=source)
    wavelengths = defaults.get("wavelengths")
    if wavelengths is not None:
        _check_channels(raw_layers, per_layer, wavelengths, source)
    channels = len(wavelengths) if wavelengths else max(len(v) for v in per_layer)
    return tuple(tuple(v[c] if len(v) == channels else v[0] for v in per_layer)
                 for c in range(channels))


def _check_channels(raw_layers, per_layer, wavelengths, source) -> None:
    """Every layer gives one value, or one per wavelength, of its per-channel fields."""
    for i, (raw, versions) in enumerate(zip(raw_layers, per_layer)):
        if len(versions) not in (1, len(wavelengths)):
            kind = kind_of(versions[0])
            # the field listing the values (a measured base's channels come from its file)
            fld = next((f.name for f in kind.fields if f.per_channel
                        and isinstance(raw.get(f.name), (list, tuple))
                        and len(raw[f.name]) == len(versions)),
                       kind.fields[0].name if kind.fields else None)
            raise SceneError(f"gives {len(versions)} per-channel values but [stack] "
                             f"wavelengths has {len(wavelengths)}: give one value per "
                             "wavelength", layer=i, kind=kind.name, field=fld, source=source)


def _parse_discretization(disc_raw: Any, source: str | None) -> Discretization:
    """The ``[discretization]`` overrides."""
    if not isinstance(disc_raw, Mapping):
        raise SceneError("[discretization] must be a table", source=source)
    unknown = set(disc_raw) - _DISC_FIELDS
    if unknown:
        raise SceneError(f"unknown field '{sorted(unknown)[0]}' in [discretization] (allowed: "
                         "n, md, ms, quadrature, tol, theta_full)", source=source)
    dctx = _Ctx(source)
    n = disc_raw.get("n")
    if n is not None:
        n = _parse_int(dctx, "discretization.n", n, 4, _MAX_N)
        if n % 2:
            raise dctx.error("discretization.n", f"must be even (n/2 ordinates per hemisphere), "
                                                 f"got {n}")
    md = disc_raw.get("md")
    if md is not None:
        md = _parse_int(dctx, "discretization.md", md, 1, MAX_ORDERS)
    ms = disc_raw.get("ms")
    if ms is not None:
        ms = _parse_int(dctx, "discretization.ms", ms, 0, MAX_ORDERS)
    quad = disc_raw.get("quadrature")
    if quad is not None and quad not in QUADRATURES:
        raise dctx.error("discretization.quadrature", f"unknown rule {quad!r}; expected one of "
                                                      + ", ".join(QUADRATURES))
    if quad == "simpson38" and n is not None and (n - 1) % 3:
        raise dctx.error("discretization.n", "composite Simpson 3/8 needs n = 3k + 1 nodes "
                                             f"(k odd), got n = {n}")
    tol = disc_raw.get("tol")
    if tol is not None:
        if isinstance(tol, bool) or not isinstance(tol, (int, float)) or not 0.0 < tol < 1.0:
            raise dctx.error("discretization.tol", "must be a relative error in (0, 1) (e.g. "
                                                   f"1e-3), got {tol!r}")
        if n is not None or md is not None:
            raise dctx.error("discretization.tol", "chooses n and md itself: give tol, or n "
                                                   "and md, not both")
        tol = float(tol)
    theta_full = disc_raw.get("theta_full")
    if theta_full is not None:
        theta_full = _real(dctx, "discretization.theta_full", theta_full, 0.0, 90.0,
                           lo_open=True, hi_open=True)
    return Discretization(n=n, md=md, ms=ms, quadrature=quad, tol=tol, theta_full=theta_full)


def _parse_wavelengths(ctx: _Ctx, value: Any) -> tuple[float, ...] | None:
    """``[stack] wavelengths``: one or three vacuum wavelengths (nm) within
    :data:`WAVELENGTH_RANGE`, one per channel (a scene has 1 or 3 channels); None if absent."""
    if value is None:
        return None
    if not isinstance(value, (list, tuple)) or len(value) not in (1, 3):
        raise ctx.error("stack.wavelengths", "must be a list of one or three wavelengths (nm), "
                                             "one per channel, e.g. [650, 550, 450], got "
                                             f"{value!r}")
    return tuple(_real(ctx, f"stack.wavelengths[{c}]", v, *WAVELENGTH_RANGE)
                 for c, v in enumerate(value))
