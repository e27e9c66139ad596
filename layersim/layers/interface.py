"""What dielectric and conductor interfaces share: the record (index, roughness, distribution,
shadowing, rotation, energy compensation, NDF table, thin film), its fields, and how a rough
interface is planned, projected and walked.

A rough interface is projected onto the Fourier basis (numerically or semi-analytically,
:mod:`layersim.ingredients.numeric`, :mod:`layersim.ingredients.microfacet`; with coupled modes
where it is anisotropic or tabulated, :mod:`layersim.ingredients.aniso_microfacet`), its energy
checked, and its compensation lobe added (:mod:`layersim.compensation`). The variants live in
their own modules: :mod:`.smooth` (roughness 0), :mod:`.near_specular` (roughness up to 0.03),
:mod:`.tabulated` (a measured NDF); :mod:`.dielectric` and :mod:`.conductor` choose among them.

An interface may carry a thin dielectric film (``film = { thickness, ior }``): its Airy
reflectance replaces the Fresnel reflectance of the interface (and of every microfacet) at the
channel's wavelength (``[stack] wavelengths``), in the solver and the walk alike
(:func:`layersim.kernels.physics.fresnel_interface`; Belcour & Barla 2017).

The Smith shadowing-masking term is separable (``G1(wi) G1(wo)``, the default) or
height-correlated (``shadowing = "height-correlated"``, as pbrt-v4 uses;
:func:`layersim.kernels.physics.smith_g2`), in the projection and the walk alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..aniso import plan as aplan
from ..aniso.plan import COUPLED_RELERR
from ..operators.energy import check_operator_energy
from ..ingredients import tabulated as tabulated_projection
from ..ingredients.aniso_microfacet import aniso_interface_operator
from ..ingredients.compensation import compensate
from ..ingredients.microfacet import interface_operator
from ..ingredients.numeric import numeric_interface_operator
from ..kernels import walk
from ..kernels.physics import DISTRIBUTION_CODES, SHADOWING_CODES
from ..kernels.tabulated import TABULATED
from ..solved.lobe import NEAR_SPECULAR_ALPHA
from . import tabulated
from .base import Layer, LayerKind, LayerPlan, WalkBoundary
from .fields import Field, choice, film, real, roughness

__all__ = ["Interface", "InterfaceKind", "Film", "DISTRIBUTIONS", "COMPENSATIONS", "SHADOWINGS"]

#: Microfacet normal distributions understood by the solver and the random walk.
DISTRIBUTIONS = ("beckmann", "ggx", "tabulated")
#: Energy-loss compensation terms of rough interfaces (``energy_compensation``, in [stack] or
#: per layer; :mod:`layersim.compensation`).
COMPENSATIONS = ("none", "layerlab", "multiple-scattering")
#: Smith shadowing-masking terms of rough interfaces (``shadowing``, in [stack] or per layer;
#: :func:`layersim.kernels.physics.smith_g2`).
SHADOWINGS = ("separable", "height-correlated", "height-correlated-beta")


@dataclass(frozen=True)
class Film:
    """A thin dielectric film on an interface, at one channel's wavelength.

    Attributes
    ----------
    thickness : float
        Geometric thickness ``d`` (nm), > 0.
    ior : float
        Absolute real index ``n`` of the film.
    wavelength : float
        Vacuum wavelength ``lambda`` (nm) of the channel the record belongs to.
    """

    thickness: float
    ior: float
    wavelength: float

    @property
    def phase_scale(self) -> float:
        """``4 pi n d / lambda``: the round-trip phase through the film at normal incidence
        inside it (:func:`layersim.kernels.physics.airy_reflectance`)."""
        return 4.0 * math.pi * self.ior * self.thickness / self.wavelength


@dataclass(frozen=True)
class Interface(Layer):
    ior: complex = 1.0
    """Absolute index of the medium below the interface (complex ``eta + i k`` for conductors)."""
    alpha_u: float = 0.0
    alpha_v: float = 0.0
    distribution: str = "beckmann"
    shadowing: str = "separable"
    """Smith shadowing-masking term (:data:`SHADOWINGS`): ``G1(wi) G1(wo)`` or a
    height-correlated ``G2`` (:func:`layersim.kernels.physics.smith_g2`)."""
    rotation: float = 0.0
    """Rotation of the tangent frame (radians) about the normal: alpha_u acts along
    ``(cos rotation, sin rotation, 0)``."""
    energy_compensation: str = "none"
    """Energy-loss compensation of a rough interface (:data:`COMPENSATIONS`;
    :mod:`layersim.compensation`), applied by the solver and the Monte Carlo walk alike."""
    ndf: Any = field(default=None, compare=False)
    """The :class:`layersim.ndf.NDFTable` of ``distribution = "tabulated"`` (its ``alpha_u``,
    ``alpha_v`` are then the table's equivalent Beckmann roughness, which sizes the plan)."""
    film: Film | None = None
    """The thin film on the interface at this channel's wavelength (None: a bare interface)."""

    @property
    def is_interface(self) -> bool:
        return True

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

    def lobe_width(self) -> float:
        """The narrower roughness (radians of slope spread)."""
        return min(self.alpha_u, self.alpha_v)

    def film_params(self, eta_above: float) -> tuple[float, float] | None:
        """The film as the kernels take it: ``(index relative to the medium above, phase
        scale 4 pi n d / lambda)``, or None without a film."""
        if self.film is None:
            return None
        return self.film.ior / eta_above, self.film.phase_scale


class InterfaceKind(LayerKind):
    """Dielectric and conductor interfaces; subclasses declare ``ior`` and choose the smooth and
    near-specular variants."""

    #: The fields both interfaces declare (a subclass adds ``ior`` in front).
    common_fields = (
        Field("roughness", "microfacet roughness alpha, or [alpha_u, alpha_v] (anisotropic)",
              parse=roughness, default=0.0, fit=True),
        Field("distribution", "microfacet normal distribution",
              parse=choice(DISTRIBUTIONS, "distribution"), default="beckmann"),
        Field("shadowing", "Smith shadowing-masking term of a rough interface: \"separable\" "
                           "G1(wi) G1(wo), \"height-correlated\" 1 / (1 + Lambda(wi) + "
                           "Lambda(wo)) (pbrt-v4's) or \"height-correlated-beta\" (the Beta "
                           "function in transmission) (default: [stack] shadowing)"),
        Field("ndf", "the NDF table of distribution = \"tabulated\": an .npz path or an inline "
                     "{theta, phi, D} table"),
        Field("rotation", "rotation of the tangent frame about the normal", unit="degrees",
              parse=real(lo=-360.0, hi=360.0), default=0.0, fit=True),
        Field("energy_compensation", "energy-loss compensation of the rough interface "
                                     "(default: [stack] energy_compensation)"),
        Field("film", "a thin dielectric film on the interface, { thickness = d, ior = n }: d in "
                      "nm within [0, 10000] (0: no film), n its real index within [1, 4]; "
                      "needs [stack] wavelengths (its Airy reflectance replaces Fresnel's at each "
                      "channel's wavelength)", unit="nm", parse=film),
    )

    # ---- scene -----------------------------------------------------------------------------

    def build(self, ctx, values, raw, defaults) -> list:
        au, av = values["roughness"]
        dist = values["distribution"]
        table = tabulated.parse_ndf(ctx, raw, dist)
        if table is not None:
            au, av = table.equivalent_alpha()
        rot = math.radians(values["rotation"])
        comp = self._compensation(ctx, raw.get("energy_compensation",
                                               defaults.get("energy_compensation", "none")),
                                  au, av)
        if table is not None and comp != "none":
            raise ctx.error("energy_compensation",
                            f"{comp!r} is not available for a tabulated NDF (its albedo tables "
                            "are those of Beckmann and GGX interfaces): set "
                            "energy_compensation = \"none\" on this layer")
        shadow = self._parse_shadow_choice(
            ctx, raw.get("shadowing", defaults.get("shadowing", "separable")), au, av)
        iors = self.parse_ior(ctx, raw["ior"])
        films = self._films(ctx, values["film"], defaults.get("wavelengths"), dist, comp)
        if len(iors) == 1:
            iors = iors * len(films)
        elif len(films) == 1:
            films = films * len(iors)
        elif len(films) != len(iors):
            raise ctx.error("ior", f"gives {len(iors)} per-channel values but [stack] "
                                   f"wavelengths has {len(films)}: give one value per "
                                   "wavelength")
        return [self.record(ior=e, alpha_u=au, alpha_v=av, distribution=dist, shadowing=shadow,
                            rotation=rot, energy_compensation=comp, ndf=table, film=f)
                for e, f in zip(iors, films)]

    @staticmethod
    def _films(ctx, value, wavelengths, dist: str, comp: str) -> list:
        """The film of each channel (``[None]`` without one, or with thickness 0: exactly the
        bare interface); refused without wavelengths, on a tabulated NDF and with an energy
        compensation, which have no film."""
        if value is None or value[0] == 0.0:
            return [None]
        d, n = value
        if not wavelengths:
            raise ctx.error("film", "needs the channels' wavelengths: add [stack] wavelengths "
                                    "(nm), e.g. wavelengths = [650, 550, 450]")
        if dist == "tabulated":
            raise ctx.error("film", "is not available with a tabulated NDF; use distribution = "
                                    "\"beckmann\" or \"ggx\"")
        if comp != "none":
            raise ctx.error("energy_compensation",
                            f"{comp!r} is not available with a film (its albedo tables are "
                            "those of bare interfaces): set energy_compensation = \"none\" on "
                            "this layer")
        return [Film(d, n, lam) for lam in wavelengths]

    @staticmethod
    def _parse_shadow_choice(ctx, value, au: float, av: float) -> str:
        """A value of ``shadowing``; a height-correlated term is refused for a near-specular
        roughness, whose lobe tables (:mod:`layersim.solved.lobe`) use the separable one."""
        if value not in SHADOWINGS:
            raise ctx.error("shadowing", f"unknown shadowing {value!r}; expected one of "
                                         + ", ".join(SHADOWINGS))
        if value == "separable" or (au == 0.0 and av == 0.0):
            return value
        if min(au, av) <= NEAR_SPECULAR_ALPHA:
            raise ctx.error("shadowing", f"{value!r} is not available for roughness "
                                         f"<= {NEAR_SPECULAR_ALPHA:g} (the near-specular lobe "
                                         "tables use the separable term)")
        return value

    @staticmethod
    def _compensation(ctx, value, au: float, av: float) -> str:
        """A value of ``energy_compensation``; anisotropic roughness is refused (the albedo
        tables are those of isotropic interfaces)."""
        if value not in COMPENSATIONS:
            raise ctx.error("energy_compensation", f"unknown compensation {value!r}; expected "
                                                   "one of " + ", ".join(COMPENSATIONS))
        if value != "none" and au != av:
            raise ctx.error("energy_compensation",
                            f"{value!r} is not available for anisotropic roughness "
                            f"[{au:g}, {av:g}]: set energy_compensation = \"none\" on this "
                            "layer (or use an isotropic roughness)")
        return value

    def parse_ior(self, ctx, value) -> list:
        """The per-channel indices of the ``ior`` field."""
        raise NotImplementedError

    def raw_ior(self, per_channel):
        """The ``ior`` field's value of the records (the inverse of :meth:`parse_ior`)."""
        raise NotImplementedError

    def to_raw(self, per_channel) -> dict:
        layer = per_channel[0]
        raw = {"kind": self.name, "ior": self.raw_ior(per_channel)}
        if layer.ndf is not None:
            raw["distribution"] = "tabulated"
            raw["ndf"] = {"theta": np.degrees(layer.ndf.theta).tolist(),
                          "phi": np.degrees(layer.ndf.phi).tolist(), "D": layer.ndf.D.tolist()}
        else:
            raw["roughness"] = (layer.alpha_u if layer.alpha_u == layer.alpha_v
                                else [layer.alpha_u, layer.alpha_v])
            raw["distribution"] = layer.distribution
        raw["shadowing"] = layer.shadowing
        raw["rotation"] = math.degrees(layer.rotation)
        raw["energy_compensation"] = layer.energy_compensation
        if layer.film is not None:
            raw["film"] = {"thickness": layer.film.thickness, "ior": layer.film.ior}
        return raw

    def describe(self, per_channel) -> str:
        layer = per_channel[0]
        rough = ("smooth" if layer.smooth else
                 f"alpha={layer.alpha_u:g}" if not layer.anisotropic else
                 f"alpha=({layer.alpha_u:g}, {layer.alpha_v:g})")
        extra = f", {layer.distribution}" if not layer.smooth else ""
        if layer.ndf is not None:
            rough, extra = layer.ndf.describe(), ""
        if layer.rotation:
            extra += f", rotated {math.degrees(layer.rotation):g} deg"
        if layer.energy_compensation != "none" and not layer.smooth:
            extra += f", energy compensation {layer.energy_compensation}"
        if layer.film is not None:
            extra += ", " + film_text(per_channel)
        if layer.shadowing != "separable" and not layer.smooth:
            extra += f", {layer.shadowing} shadowing"
        return f"{layer.kind} ior={self.describe_ior(per_channel)}, {rough}{extra}"

    def describe_ior(self, per_channel) -> str:
        raise NotImplementedError

    # ---- plan ------------------------------------------------------------------------------

    def survey(self, scene, i, survey) -> None:
        layer = scene.channel(0).layers[i]
        self.plan_layer(scene, i, layer, survey)
        if layer.film is not None:      # the film changes no lobe width, only the Fresnel term
            text = film_text([scene.channel(c).layers[i] for c in range(scene.channels)])
            for lp in survey.layers:
                if lp.index == i:
                    lp.detail += "; " + text

    def plan_layer(self, scene, i: int, layer, survey) -> None:
        """The plan of layer ``i`` (``layer``: its record in channel 0), its film aside."""
        if self.plan_special(scene, i, layer, survey):
            return
        eta_rel = scene.channel(0).relative_ior(i)
        width, what = self.lobe(layer, eta_rel)
        survey.widths.append((width, i, self.name, what))
        if layer.ndf is not None:
            survey.layers.append(tabulated.plan(i, layer, eta_rel, width))
        elif layer.anisotropic:
            ms = aplan.ms_for_layer(layer)
            rot = f", rotated {math.degrees(layer.rotation):g} deg" if layer.rotation else ""
            survey.layers.append(LayerPlan(
                i, self.name, "project (coupled modes)",
                f"{layer.distribution} alpha=({layer.alpha_u:g}, {layer.alpha_v:g}){rot}, "
                f"relative index {_fmt_eta(eta_rel)}; ratio "
                f"{aplan.anisotropy_ratio(layer):.3g} -> ms = {ms}" + shadowing_text(layer),
                width=width, ms=ms))
        else:
            survey.layers.append(LayerPlan(i, self.name, "project",
                                           f"{layer.distribution} alpha={layer.alpha_u:g}, "
                                           f"relative index {_fmt_eta(eta_rel)}"
                                           + shadowing_text(layer)
                                           + compensation_text(layer), width=width))

    def plan_special(self, scene, i: int, layer, survey) -> bool:
        """Plan the kind's exact variants (index-matched, smooth, near-specular) and return
        True, or False to leave the layer to the projection."""
        return False

    def lobe(self, layer, eta_rel: complex) -> tuple[float, str]:
        """Angular width (radians) of the narrowest lobe of the rough interface and its name."""
        raise NotImplementedError

    def equivalent_lobe(self, layer):
        return layer if layer.ndf is None else tabulated.equivalent_lobe(layer)

    # ---- solve -----------------------------------------------------------------------------

    def operator(self, job):
        layer, plan, eta_above = job.layer, job.plan, job.eta_above
        special = self.special_operator(job)
        if special is not None:
            return special
        if layer.anisotropic:
            lp = job.layer_plan
            op = aniso_interface_operator(
                job.grid, plan.md, lp.ms, layer, eta_above, job.stats, relerr=COUPLED_RELERR,
                workspace=job.workspace,
                projector=None if layer.ndf is None else
                tabulated_projection.projector(layer, eta_above, job.device), only=job.blocks)
            job.notes += check_operator_energy(op, job.index, layer, plan.n)
            return op
        if job.projection == "numeric":
            op = numeric_interface_operator(job.grid, plan.md, layer, eta_above, job.stats,
                                            device=job.device, blocks=job.blocks)
        else:
            op = interface_operator(job.grid, plan.md, layer, eta_above, job.stats,
                                    blocks=job.blocks)
        # the compensation fills what the (energy-limited) single-scattering operator loses
        job.notes += check_operator_energy(op, job.index, layer, plan.n)
        op, note = compensate(op, layer, eta_above)
        job.notes += [f"layer {job.index}: {note}"] if note else []
        return op

    def special_operator(self, job):
        """The operator of an exact variant planned by :meth:`plan_special`, or None."""
        return None

    # ---- walk ------------------------------------------------------------------------------

    def walk_boundary(self, scene, i) -> WalkBoundary:
        layer = scene.layers[i]
        eta = scene.relative_ior(i)
        film = layer.film_params(scene.ior_above(i)) or (0.0, 0.0)
        floats = (eta.real, eta.imag if layer.opaque else 0.0, layer.alpha_u, layer.alpha_v,
                  math.cos(layer.rotation), math.sin(layer.rotation), 0.0, 0.0, *film)
        code = walk.CONDUCTOR if layer.opaque else walk.DIELECTRIC
        if layer.ndf is not None:       # alpha_u's slot gets the table's offset in flatten()
            return WalkBoundary((code, TABULATED, SHADOWING_CODES[layer.shadowing]), floats,
                                layer.ndf)
        return WalkBoundary((code, DISTRIBUTION_CODES[layer.distribution],
                             SHADOWING_CODES[layer.shadowing]), floats)

    # ---- statistical model -----------------------------------------------------------------

    def statistical_atom(self, layer, refuse):
        if layer.film is not None:
            raise refuse("film", "a thin film is not represented (the model's atoms have bare "
                                 "Fresnel terms)")
        if layer.shadowing != "separable":
            raise refuse("shadowing", f"'{layer.shadowing}' is not represented (the FGD table "
                                      "is that of the separable Smith term)")
        if layer.distribution != "ggx":
            raise refuse("distribution", f"'{layer.distribution}' is not represented; use "
                                         "distribution = \"ggx\"")
        if layer.anisotropic:
            raise refuse("roughness", "anisotropic roughness is not represented")
        if layer.alpha_u > 1.0:
            raise refuse("roughness", f"{layer.alpha_u:g} is beyond the FGD table (<= 1)")
        return ("interface", complex(layer.ior), layer.alpha_u)


def shadowing_text(layer) -> str:
    """The plan's words for a height-correlated Smith term (empty for the separable one)."""
    if layer.shadowing == "separable":
        return ""
    return f"; {layer.shadowing} Smith term (solver and Monte Carlo)"


def compensation_text(layer) -> str:
    """The plan's words for a rough interface's energy compensation (empty for none)."""
    mode = layer.energy_compensation
    if mode == "none":
        return ""
    what = {"multiple-scattering": "Kulla & Conty 2017 multiple-scattering lobe",
            "layerlab": "layerlab's near-diffuse correction"}[mode]
    return f"; energy compensation {mode!r} ({what}, order 0, solver and Monte Carlo)"


def film_text(per_channel) -> str:
    """The plan's and the description's words for the film of an interface (its records, one
    per channel)."""
    f = per_channel[0].film
    lams = ", ".join(f"{x.film.wavelength:g}" for x in per_channel)
    return (f"thin film d = {f.thickness:g} nm, n = {f.ior:g} (Airy reflectance at {lams} "
            "nm)")


def _fmt_eta(eta: complex) -> str:
    return f"{eta.real:.4g}" if eta.imag == 0 else f"{eta.real:.4g}+{eta.imag:.4g}i"
