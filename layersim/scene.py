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

from . import merl
from .errors import SceneError
from .ndf import table as ndf_table

__all__ = [
    "Layer", "Dielectric", "Conductor", "Medium", "Diffuse", "Measured", "Discretization",
    "Scene", "QUADRATURES", "DISTRIBUTIONS", "COMPENSATIONS", "as_scene",
]

#: Microfacet normal distributions understood by the solver and the random walk.
DISTRIBUTIONS = ("beckmann", "ggx", "tabulated")
#: Energy-loss compensation terms of rough interfaces (``energy_compensation``, in [stack] or
#: per layer; :mod:`layersim.compensation`).
COMPENSATIONS = ("none", "layerlab", "multiple-scattering")
#: Quadrature rules on mu in [-1, 1] (see :mod:`layersim.quadrature`).
QUADRATURES = ("gauss-lobatto", "gauss-legendre", "simpson38")

# Guard rails against inputs that are valid numbers but physically meaningless.
_MAX_IOR = 100.0          # absolute index (real part), dielectric or conductor eta
_MAX_K = 100.0            # conductor extinction coefficient
_MAX_ROUGHNESS = 10.0     # Beckmann/GGX alpha; alpha > 1 is already very rough
_MAX_N = 4096             # ordinates
#: Fourier orders a scene may ask for (``[discretization] md``): the planner's limit
#: (:data:`layersim.plan.MD_MAX`), so that the validator and the solver refuse the same values.
MAX_ORDERS = 20_000


# --------------------------------------------------------------------------------------------
# Layers (monochromatic: one channel's values)
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Layer:
    """Base class of the monochromatic layer records. ``kind`` is the scene-file name."""

    kind = "layer"

    @property
    def opaque(self) -> bool:
        return False

    @property
    def anisotropic(self) -> bool:
        return False


@dataclass(frozen=True)
class _Interface(Layer):
    ior: complex = 1.0
    """Absolute index of the medium below the interface (complex ``eta + i k`` for conductors)."""
    alpha_u: float = 0.0
    alpha_v: float = 0.0
    distribution: str = "beckmann"
    rotation: float = 0.0
    """Rotation of the tangent frame (radians) about the normal: alpha_u acts along
    ``(cos rotation, sin rotation, 0)``."""
    energy_compensation: str = "none"
    """Energy-loss compensation of a rough interface (:data:`COMPENSATIONS`;
    :mod:`layersim.compensation`), applied by the solver and the Monte Carlo walk alike."""
    ndf: Any = field(default=None, compare=False)
    """The :class:`layersim.ndf.NDFTable` of ``distribution = "tabulated"`` (its ``alpha_u``,
    ``alpha_v`` are then the table's equivalent Beckmann roughness, which sizes the plan)."""

    @property
    def smooth(self) -> bool:
        return self.alpha_u == 0.0 and self.alpha_v == 0.0

    @property
    def anisotropic(self) -> bool:
        # a table is projected with coupled modes whatever its shape (it may depend on phi)
        return self.alpha_u != self.alpha_v or self.ndf is not None

    @property
    def alpha(self) -> float:
        """Isotropic roughness; valid only when ``alpha_u == alpha_v``."""
        if self.anisotropic:
            raise ValueError("alpha is undefined for an anisotropic interface; use alpha_u/alpha_v")
        return self.alpha_u


@dataclass(frozen=True)
class Dielectric(_Interface):
    """Rough (or smooth) interface into a dielectric of real index ``ior``."""

    kind = "dielectric"


@dataclass(frozen=True)
class Conductor(_Interface):
    """Rough (or smooth) opaque conductor with complex index ``ior = eta + i k``."""

    kind = "conductor"

    @property
    def opaque(self) -> bool:
        return True


@dataclass(frozen=True)
class Medium(Layer):
    """Homogeneous slab: optical thickness ``tau``, single-scattering ``albedo``, Henyey-Greenstein
    asymmetry ``g`` (0 = isotropic)."""

    kind = "medium"
    albedo: float = 0.0
    g: float = 0.0
    tau: float = 0.0


@dataclass(frozen=True)
class Diffuse(Layer):
    """Opaque Lambertian reflector with reflectance ``albedo``."""

    kind = "diffuse"
    albedo: float = 0.0

    @property
    def opaque(self) -> bool:
        return True


@dataclass(frozen=True)
class Measured(Layer):
    """Opaque base with a measured isotropic BRDF (MERL layout, :mod:`layersim.merl`): channel
    ``channel`` of ``data``. ``alpha`` is the width (radians) of its specular lobe
    (:meth:`layersim.merl.MERLTable.equivalent_alpha`), which sizes the plan as a Beckmann
    lobe of that roughness would."""

    kind = "measured"
    data: Any = field(default=None, compare=False)
    channel: int = 0
    alpha: float = 0.5 * math.pi

    @property
    def opaque(self) -> bool:
        return True

    @property
    def alpha_u(self) -> float:
        return self.alpha

    @property
    def alpha_v(self) -> float:
        return self.alpha


@dataclass(frozen=True)
class Discretization:
    """User overrides of the discretisation plan; ``None`` = let the planner choose.

    n : number of ordinates on mu in [-1, 1] (even); md : number of Fourier orders in the azimuth
    difference (cosine orders 0..md-1, or complex modes -(md-1)..md-1); ms : coupling half-width
    in the azimuth sum (modes -ms..ms; 0 for isotropic stacks); quadrature : one of
    :data:`QUADRATURES`; tol : relative error of bin energies that :func:`layersim.solve`
    solves to (:mod:`layersim.accuracy`; not with ``n`` or ``md``); theta_full : elevation
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
    """

    stacks: tuple[tuple[Layer, ...], ...]
    top_ior: float = 1.0
    discretization: Discretization = field(default_factory=Discretization)
    name: str = "scene"
    source: str | None = None

    # ---- construction ------------------------------------------------------------------

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
                       name=self.name if self.channels == 1 else f"{self.name}[{'RGB'[c]}]")

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
            if isinstance(layer, Dielectric):
                eta = layer.ior.real
        return eta

    def relative_ior(self, i: int) -> complex:
        """Index of the medium below interface ``i`` relative to the medium above it."""
        layer = self.layers[i]
        if not isinstance(layer, _Interface):
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
                 f"{self.top_ior:g}, {self.channels} channel(s)"]
        for i, layers in enumerate(zip(*self.stacks)):
            lines.append(f"  [{i}] " + _describe_layer(layers))
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


def _describe_layer(per_channel: tuple[Layer, ...]) -> str:
    layer = per_channel[0]

    def vals(text) -> str:
        values = [text(x) for x in per_channel]
        return values[0] if len(set(values)) == 1 else "(" + ", ".join(values) + ")"

    if isinstance(layer, _Interface):
        rough = ("smooth" if layer.smooth else
                 f"alpha={layer.alpha_u:g}" if not layer.anisotropic else
                 f"alpha=({layer.alpha_u:g}, {layer.alpha_v:g})")
        if isinstance(layer, Conductor):
            ior = vals(lambda x: f"{x.ior.real:g}+{x.ior.imag:g}i")
        else:
            ior = vals(lambda x: f"{x.ior.real:g}")
        extra = f", {layer.distribution}" if not layer.smooth else ""
        if layer.ndf is not None:
            rough, extra = layer.ndf.describe(), ""
        if layer.rotation:
            extra += f", rotated {math.degrees(layer.rotation):g} deg"
        if layer.energy_compensation != "none" and not layer.smooth:
            extra += f", energy compensation {layer.energy_compensation}"
        return f"{layer.kind} ior={ior}, {rough}{extra}"
    if isinstance(layer, Medium):
        return (f"medium tau={vals(lambda x: f'{x.tau:g}')}, "
                f"albedo={vals(lambda x: f'{x.albedo:g}')}, "
                f"g={vals(lambda x: f'{x.g:g}')}")
    if isinstance(layer, Diffuse):
        return f"diffuse albedo={vals(lambda x: f'{x.albedo:g}')}"
    if isinstance(layer, Measured):
        return (f"measured BRDF {layer.data.source} (MERL layout, 3 channels, lobe width "
                f"{math.degrees(layer.alpha):.3g} deg"
                + (f", {layer.data.missing} unmeasured samples read as 0" if layer.data.missing
                   else "") + ")")
    return layer.kind


# --------------------------------------------------------------------------------------------
# Parsing and validation
# --------------------------------------------------------------------------------------------

_LAYER_FIELDS = {
    "dielectric": {"kind", "ior", "roughness", "distribution", "rotation", "ndf",
                   "energy_compensation"},
    "conductor": {"kind", "ior", "roughness", "distribution", "rotation", "ndf",
                  "energy_compensation"},
    "medium": {"kind", "albedo", "g", "tau"},
    "diffuse": {"kind", "albedo"},
    "measured": {"kind", "file"},
}
_REQUIRED = {
    "dielectric": {"ior"},
    "conductor": {"ior"},
    "medium": {"albedo", "tau"},
    "diffuse": {"albedo"},
    "measured": {"file"},
}
_TOP_FIELDS = {"layer", "stack", "discretization"}
_STACK_FIELDS = {"top_ior", "name", "energy_compensation"}
_DISC_FIELDS = {"n", "md", "ms", "quadrature", "tol", "theta_full"}


class _Ctx:
    """Where we are while parsing, to name the place in errors."""

    def __init__(self, source, layer=None, kind=None):
        self.source, self.layer, self.kind = source, layer, kind

    def error(self, fld, message):
        return SceneError(message, layer=self.layer, kind=self.kind, field=fld,
                          source=self.source)


def _real(ctx: _Ctx, fld: str, value: Any, lo=None, hi=None, lo_open=False, hi_open=False) -> float:
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


def _per_channel(ctx: _Ctx, fld: str, value: Any, parse_one) -> list:
    """A scalar (shared by all channels) or a list of 3 per-channel values."""
    if isinstance(value, (list, tuple)):
        if len(value) != 3:
            raise ctx.error(fld, f"must be one value or a list of 3 (R, G, B) values, "
                                 f"got a list of {len(value)}")
        return [parse_one(ctx, f"{fld}[{c}]", v) for c, v in enumerate(value)]
    return [parse_one(ctx, fld, value)]


def _roughness(ctx: _Ctx, value: Any) -> tuple[float, float]:
    parse = lambda c, f, v: _real(c, f, v, lo=0.0, hi=_MAX_ROUGHNESS)
    if isinstance(value, (list, tuple)):
        if len(value) != 2:
            raise ctx.error("roughness", "must be one value (isotropic) or [alpha_u, alpha_v], "
                                         f"got a list of {len(value)}")
        au, av = parse(ctx, "roughness[0]", value[0]), parse(ctx, "roughness[1]", value[1])
        if (au == 0.0) != (av == 0.0):
            raise ctx.error("roughness", f"[{au:g}, {av:g}] is smooth along one axis only; "
                                         "use 0 for both (smooth) or positive values for both")
        return au, av
    a = parse(ctx, "roughness", value)
    return a, a


def _conductor_ior(ctx: _Ctx, fld: str, value: Any) -> complex:
    if isinstance(value, complex):
        eta, k = value.real, value.imag
        _real(ctx, fld, eta)
        _real(ctx, fld, k)
    elif isinstance(value, (list, tuple)) and len(value) == 2 and not any(
            isinstance(v, (list, tuple)) for v in value):
        eta, k = value
    else:
        raise ctx.error(fld, "a conductor index must be [eta, k] with k > 0 (or three [eta, k] "
                             f"pairs for R, G, B), got {value!r}")
    eta = _real(ctx, fld + ".eta", eta, lo=0.0, hi=_MAX_IOR)
    k = _real(ctx, fld + ".k", k, lo=0.0, hi=_MAX_K, lo_open=True)
    return complex(eta, k)


def _compensation(ctx: _Ctx, fld: str, value: Any, au: float = 0.0, av: float = 0.0) -> str:
    """A value of ``energy_compensation``; anisotropic roughness is refused (the albedo tables
    are those of isotropic interfaces)."""
    if value not in COMPENSATIONS:
        raise ctx.error(fld, f"unknown compensation {value!r}; expected one of "
                             + ", ".join(COMPENSATIONS))
    if value != "none" and au != av:
        raise ctx.error(fld, f"{value!r} is not available for anisotropic roughness "
                             f"[{au:g}, {av:g}]: set energy_compensation = \"none\" on this "
                             "layer (or use an isotropic roughness)")
    return value


def _parse_layer(ctx: _Ctx, raw: Any, compensation: str = "none") -> list[Layer]:
    if not isinstance(raw, Mapping):
        raise ctx.error(None, f"must be a table with a 'kind', got {type(raw).__name__}")
    if "kind" not in raw:
        raise ctx.error("kind", "is missing; one of " + ", ".join(sorted(_LAYER_FIELDS)))
    kind = raw["kind"]
    if kind not in _LAYER_FIELDS:
        raise ctx.error("kind", f"unknown kind {kind!r}; expected one of "
                                + ", ".join(sorted(_LAYER_FIELDS)))
    ctx.kind = kind
    unknown = set(raw) - _LAYER_FIELDS[kind]
    if unknown:
        name = sorted(unknown)[0]
        raise ctx.error(name, f"unknown field for a {kind} layer (allowed: "
                              + ", ".join(sorted(_LAYER_FIELDS[kind] - {'kind'})) + ")")
    missing = _REQUIRED[kind] - set(raw)
    if missing:
        raise ctx.error(sorted(missing)[0], "is required")

    if kind in ("dielectric", "conductor"):
        au, av = _roughness(ctx, raw.get("roughness", 0.0))
        dist = raw.get("distribution", "beckmann")
        if dist not in DISTRIBUTIONS:
            raise ctx.error("distribution", f"unknown distribution {dist!r}; expected one of "
                                            + ", ".join(DISTRIBUTIONS))
        table = _ndf_field(ctx, raw, dist)
        if table is not None:
            au, av = table.equivalent_alpha()
        rot = math.radians(_real(ctx, "rotation", raw.get("rotation", 0.0), lo=-360.0, hi=360.0))
        comp = _compensation(ctx, "energy_compensation",
                             raw.get("energy_compensation", compensation), au, av)
        if table is not None and comp != "none":
            raise ctx.error("energy_compensation",
                            f"{comp!r} is not available for a tabulated NDF (its albedo tables "
                            "are those of Beckmann and GGX interfaces): set "
                            "energy_compensation = \"none\" on this layer")
        if kind == "dielectric":
            iors = _per_channel(ctx, "ior", raw["ior"], lambda c, f, v: complex(
                _real(c, f, v, lo=0.0, hi=_MAX_IOR, lo_open=True)))
            return [Dielectric(ior=e, alpha_u=au, alpha_v=av, distribution=dist, rotation=rot,
                               energy_compensation=comp, ndf=table) for e in iors]
        value = raw["ior"]
        if (isinstance(value, (list, tuple)) and len(value) == 3
                and all(isinstance(v, (list, tuple, complex)) for v in value)):
            iors = [_conductor_ior(ctx, f"ior[{c}]", v) for c, v in enumerate(value)]
        else:
            iors = [_conductor_ior(ctx, "ior", value)]
        return [Conductor(ior=e, alpha_u=au, alpha_v=av, distribution=dist, rotation=rot,
                          energy_compensation=comp, ndf=table) for e in iors]

    if kind == "medium":
        albedos = _per_channel(ctx, "albedo", raw["albedo"],
                               lambda c, f, v: _real(c, f, v, lo=0.0, hi=1.0))
        gs = _per_channel(ctx, "g", raw.get("g", 0.0), lambda c, f, v: _real(
            c, f, v, lo=-1.0, hi=1.0, lo_open=True, hi_open=True))
        taus = _per_channel(ctx, "tau", raw["tau"], lambda c, f, v: _real(c, f, v, lo=0.0))
        # a shared value pairs with every channel of the others
        channels = max(len(albedos), len(gs), len(taus))
        return [Medium(albedo=albedos[c % len(albedos)], g=gs[c % len(gs)],
                       tau=taus[c % len(taus)]) for c in range(channels)]

    if kind == "measured":
        value = raw["file"]
        if not isinstance(value, (str, os.PathLike)):
            raise ctx.error("file", f"must be the path of a MERL binary file, got {value!r}")
        path = Path(value)
        if not path.is_absolute() and ctx.source is not None:
            path = Path(ctx.source).parent / path
        data = merl.read_merl(path, layer=ctx.layer, kind=kind)
        alpha = data.equivalent_alpha()
        return [Measured(data=data, channel=c, alpha=alpha) for c in range(3)]

    albedos = _per_channel(ctx, "albedo", raw["albedo"],
                           lambda c, f, v: _real(c, f, v, lo=0.0, hi=1.0))
    return [Diffuse(albedo=a) for a in albedos]


def _ndf_field(ctx: _Ctx, raw: Mapping[str, Any], dist: str):
    """The NDF table of ``distribution = "tabulated"`` (None otherwise): ``ndf`` is the path
    of an ``.npz`` file (relative to the scene file) or an inline table ``{theta, phi, D}``
    with angles in degrees (:mod:`layersim.ndf.table`)."""
    if dist != "tabulated":
        if "ndf" in raw:
            raise ctx.error("ndf", 'is only used with distribution = "tabulated"')
        return None
    if "roughness" in raw:
        raise ctx.error("roughness", 'a tabulated NDF takes no roughness (the table is the '
                                     "distribution); remove it")
    value = raw.get("ndf")
    if value is None:
        raise ctx.error("ndf", 'is required with distribution = "tabulated": the path of an '
                               ".npz file (theta, phi, D) or an inline table {theta, phi, D}")
    if isinstance(value, str):
        path = Path(value)
        if not path.is_absolute() and ctx.source is not None:
            path = Path(ctx.source).parent / path
        return ndf_table.load_ndf(path, layer=ctx.layer, kind=ctx.kind)
    if isinstance(value, Mapping):
        unknown = set(value) - {"theta", "phi", "D"}
        if unknown or len(value) != 3:
            raise ctx.error("ndf", "an inline table has exactly the keys theta, phi (degrees) "
                                   "and D (1/sr, one row per theta)")
        return ndf_table.from_arrays(np.radians(_array(ctx, value["theta"])),
                                     np.radians(_array(ctx, value["phi"])),
                                     _array(ctx, value["D"]), source="inline table",
                                     layer=ctx.layer, kind=ctx.kind)
    raise ctx.error("ndf", f"must be a file path or an inline table, got {type(value).__name__}")


def _array(ctx: _Ctx, value):
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ctx.error("ndf", "inline table values must be numbers (rows of equal length)") \
            from None


def _parse_int(ctx: _Ctx, fld: str, value: Any, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ctx.error(fld, f"must be an integer, got {value!r}")
    if not lo <= value <= hi:
        raise ctx.error(fld, f"must be within [{lo}, {hi}], got {value}")
    return value


def _parse_scene(data: Mapping[str, Any], source: str | None, default_name: str) -> Scene:
    ctx = _Ctx(source)
    if not isinstance(data, Mapping):
        raise SceneError(f"a scene must be a table/dict, got {type(data).__name__}", source=source)
    unknown = set(data) - _TOP_FIELDS
    if unknown:
        raise SceneError(f"unknown top-level entry '{sorted(unknown)[0]}' (allowed: "
                         "[[layer]], [stack], [discretization])", source=source)

    stack = data.get("stack", {})
    if not isinstance(stack, Mapping):
        raise SceneError("[stack] must be a table", source=source)
    unknown = set(stack) - _STACK_FIELDS
    if unknown:
        raise SceneError(f"unknown field '{sorted(unknown)[0]}' in [stack] (allowed: top_ior, "
                         "name, energy_compensation)", source=source)
    top_ior = _real(ctx, "stack.top_ior", stack.get("top_ior", 1.0), lo=0.0, hi=_MAX_IOR,
                    lo_open=True)
    name = stack.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise SceneError("[stack] name must be a non-empty string", source=source)

    raw_layers = data.get("layer")
    if raw_layers is None:
        raise SceneError("no layers: add at least one [[layer]] table", source=source)
    if not isinstance(raw_layers, (list, tuple)) or not raw_layers:
        raise SceneError("'layer' must be a non-empty list of [[layer]] tables", source=source)

    compensation = stack.get("energy_compensation", "none")
    if compensation not in COMPENSATIONS:
        raise SceneError(f"[stack] energy_compensation: unknown compensation {compensation!r}; "
                         "expected one of " + ", ".join(COMPENSATIONS), source=source)
    per_layer = []
    for i, raw in enumerate(raw_layers):
        per_layer.append(_parse_layer(_Ctx(source, layer=i), raw, compensation))

    for i, versions in enumerate(per_layer):
        if versions[0].opaque and i != len(per_layer) - 1:
            raise SceneError(f"an opaque {versions[0].kind} layer must be the bottom layer; "
                             f"{len(per_layer) - 1 - i} layer(s) below it would never receive "
                             "light", layer=i, kind=versions[0].kind, field="kind",
                             source=source)

    channels = max(len(v) for v in per_layer)
    stacks = tuple(tuple(v[c] if len(v) == 3 else v[0] for v in per_layer)
                   for c in range(channels))

    disc_raw = data.get("discretization", {})
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
    return Scene(stacks=stacks, top_ior=top_ior,
                 discretization=Discretization(n=n, md=md, ms=ms, quadrature=quad, tol=tol,
                                               theta_full=theta_full),
                 name=name, source=source)
