"""What a layer kind is: its record (one channel's values), and what each stage of the pipeline
needs from it.

scene -> plan -> operators -> adding -> BSDF, and scene -> walk records -> walk: every stage asks
the layer's kind (:class:`LayerKind`, found in :mod:`layersim.layers.registry` by the record's
``kind``) rather than branching on it, so that a kind lives in one module of
:mod:`layersim.layers` with its fields, validation, plan, operator, walk record and statistical
atom side by side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..errors import SceneError
from .fields import Ctx, parse_fields

__all__ = ["Layer", "LayerKind", "LayerPlan", "Survey", "OperatorJob", "WalkBoundary",
           "N_PER_WIDTH"]

#: Ordinates per unit of inverse lobe width: a lobe ``width`` radians wide that a kind reports
#: in :attr:`Survey.widths` gets ``N_PER_WIDTH / width`` ordinates (:mod:`layersim.plan.
#: ordinates`; set so that alpha = 0.1, eta = 1.5 gives layerlab's n = 196).
N_PER_WIDTH = 6.5


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

    @property
    def is_interface(self) -> bool:
        """An interface between two media (it has a relative index)."""
        return False

    def index_below(self, eta_above: float) -> float:
        """Absolute index of the medium below the layer, given the one above it."""
        return eta_above

    def lobe_width(self) -> float:
        """Angular width (radians) of the narrowest lobe the layer scatters into: infinite
        for a layer that scatters over the hemisphere (a Lambertian base)."""
        return math.inf


@dataclass
class LayerPlan:
    """What the solve does with one layer of the stack.

    Attributes
    ----------
    index : int
        Position in the stack (0 = top).
    kind : str
        The scene layer's kind (``"dielectric"``, ``"conductor"``, ``"medium"``, ``"diffuse"``).
    action : str
        ``"project"``, ``"project (coupled modes)"``, ``"adding-doubling"``, ``"diffuse"`` or
        ``"left out"``.
    detail : str
        One line of what the action depends on, for the report.
    width : float or None
        Narrowest angular lobe of the layer (radians), when it competes to set ``n``.
    orders : int
        Fourier orders the layer needs (from the projection's pre-pass for interfaces).
    ms : int
        Coupling half-width of an anisotropic interface (0 otherwise).
    blocks : tuple of str or None
        The blocks of an interface that the solve projects, where not all (a brushed coat's
        own reflection is its exact lobe instead: :mod:`layersim.layers.brushed`); the
        pre-pass and the cost count only these.
    """

    index: int
    kind: str
    action: str
    detail: str = ""
    width: float | None = None
    orders: int = 1
    ms: int = 0
    blocks: tuple | None = None


@dataclass
class Survey:
    """The per-layer actions of a stack and what they imply for the discretisation.

    Attributes
    ----------
    layers : list of LayerPlan
    left_out : list of str
        What the solve leaves out, and why (report lines).
    widths : list of (float, int, str, str)
        ``(width in radians, layer index, kind, lobe)`` of every lobe that competes to set
        ``n``.
    media_orders : int
        Fourier orders the media's phase functions need (counted once the grid is known).
    scaled : list of LayerPlan
        The layers whose representation is decided once the grid is known
        (:meth:`LayerKind.on_grid`).
    boundary : dict
        Smooth dielectric boundaries, ``{"top" | "bottom": index outside}``
        (:mod:`layersim.solved.boundary`).
    snell_eta : float or None
        Their relative index (inside / outside), which sets the Snell-matched grid.
    lobes : dict
        Near-specular boundaries, ``{"top": parameters of layersim.solved.lobe.NearSpecularLobe}``.
    near_specular : tuple of int
        The layers solved by a near-specular split.
    brushed : dict or None
        A brushed top coat projected with its narrow roughness raised, its own reflection
        left to its exact lobe (:mod:`layersim.layers.brushed`): ``{"floor", "floors",
        "weights", "alpha_u", "alpha_v"}`` (the lowest raised roughness, every one solved,
        their extrapolation weights, and the coat's own); None without one.
    inner_mirrors : dict or None
        Near-specular inner interfaces split over their raised transmission, their reflection
        from above a mirror or projected at their own roughness
        (:mod:`layersim.layers.near_specular_inner`): ``{"floor", "layers": {index: (alpha_u,
        alpha_v)}, "exact": (index, ...)}`` (the raised roughness, their own, and those whose
        reflection from above is projected at it); None without one.
    hints : list of str
        What would make a refused plan affordable (added to the refusal's message).
    """

    layers: list = field(default_factory=list)
    left_out: list = field(default_factory=list)
    widths: list = field(default_factory=list)
    media_orders: int = 1
    scaled: list = field(default_factory=list)
    boundary: dict = field(default_factory=dict)
    snell_eta: float | None = None
    lobes: dict = field(default_factory=dict)
    near_specular: tuple = ()
    brushed: dict | None = None
    inner_mirrors: dict | None = None
    hints: list = field(default_factory=list)


@dataclass
class OperatorJob:
    """What the solver hands a kind to build the operator of layer ``index`` of ``scene`` (one
    channel): the plan and its grid, the projection's statistics and options, the coupled
    adding's workspace, ``notes`` for the BSDF's ``info["notes"]``, and ``blocks``: the blocks
    of a coupled projection to project (None: all; the others are left empty, for a kind that
    takes them from elsewhere, as a brushed coat does: :mod:`layersim.layers.brushed`)."""

    plan: Any
    grid: Any
    scene: Any
    index: int
    stats: Any
    projection: str = "numeric"
    device: Any = None
    workspace: Any = None
    notes: list = field(default_factory=list)
    blocks: tuple | None = None

    @property
    def layer(self):
        return self.scene.layers[self.index]

    @property
    def eta_above(self) -> float:
        return self.scene.ior_above(self.index)

    @property
    def layer_plan(self):
        return next(lp for lp in self.plan.layers if lp.index == self.index)


@dataclass(frozen=True)
class WalkBoundary:
    """A boundary record of the random walk (:mod:`layersim.kernels.walk`): three ints (kind
    code, distribution code, shadowing code), :data:`~layersim.kernels.walk.BND_F` floats,
    and a table packed after the records (an object with ``packed(dtype)``, or None)."""

    ints: tuple
    floats: tuple
    table: Any = None


class LayerKind:
    """A kind of layer: its fields, and what each stage of the pipeline needs from it.

    Subclasses set :attr:`name`, :attr:`record` and :attr:`fields`, implement :meth:`build`,
    and the hooks of the stages the kind takes part in. The defaults refuse with a message
    naming the kind, so a kind that the walk or the statistical model does not know is refused
    there, clearly.
    """

    #: The scene file's ``kind``.
    name: str = "layer"
    #: The dataclass of one channel's values.
    record: type = Layer
    #: The declared fields (:class:`~layersim.layers.fields.Field`).
    fields: tuple = ()
    #: How the walk sees the layer: ``"boundary"`` (an interaction) or ``"slab"`` (a medium).
    walk_role: str = "boundary"

    # ---- scene -----------------------------------------------------------------------------

    def parse(self, ctx: Ctx, raw: Mapping[str, Any], defaults: Mapping[str, Any]) -> list:
        """The records (one per channel, or one for all) of a ``[[layer]]`` table: the
        declared fields parsed (:func:`~layersim.layers.fields.parse_fields`), then
        :meth:`build`. ``defaults`` holds the ``[stack]`` values that layers inherit."""
        values = parse_fields(ctx, self.name, self.fields, raw)
        return self.build(ctx, values, raw, defaults)

    def build(self, ctx: Ctx, values: dict, raw: Mapping[str, Any],
              defaults: Mapping[str, Any]) -> list:
        raise NotImplementedError

    def describe(self, per_channel: tuple) -> str:
        """One line for the CLI and reports (``per_channel``: the layer's records)."""
        return self.name

    def to_raw(self, per_channel: tuple) -> dict:
        """The ``[[layer]]`` table (scene-file values) that parses back to ``per_channel``
        (the layer's records, one per channel); refused by default, naming the kind."""
        raise SceneError(f"a {self.name} layer cannot be written back as a scene table",
                         kind=self.name)

    @staticmethod
    def channel_value(per_channel: tuple, get):
        """``get(record)`` of the channels as a scene file writes it: one value when every
        channel has it, else the list of the channels' values."""
        vals = [get(x) for x in per_channel]
        return vals[0] if all(v == vals[0] for v in vals) else vals

    @staticmethod
    def values(per_channel: tuple, text) -> str:
        """``text(record)`` of one channel, or of each channel in parentheses where they
        differ."""
        vals = [text(x) for x in per_channel]
        return vals[0] if len(set(vals)) == 1 else "(" + ", ".join(vals) + ")"

    # ---- plan ------------------------------------------------------------------------------

    def survey(self, scene, i: int, survey: Survey) -> None:
        """Add what the solve does with layer ``i`` of ``scene`` (RGB channels share it) to
        ``survey``: a :class:`LayerPlan`, lobe widths that compete to set ``n``, what is left
        out."""
        raise SceneError(f"the solver does not solve a {self.name} layer", layer=i,
                         kind=self.name)

    def on_grid(self, scene, lp: LayerPlan, grid) -> int:
        """For a layer in ``survey.scaled``: decide its representation on ``grid`` and return
        the Fourier orders it needs."""
        return 1

    def equivalent_lobe(self, layer):
        """The analytic Beckmann interface whose series lengths size the plan of a projected
        layer (the layer itself where it is one)."""
        return layer

    # ---- solve -----------------------------------------------------------------------------

    def operator(self, job: OperatorJob):
        """The operator of the job's layer on the plan's grid."""
        raise SceneError(f"the solver has no operator for a {self.name} layer",
                         layer=job.index, kind=self.name)

    def evaluated_lobes(self, plan, scene, i: int) -> dict:
        """Lobes the BSDF evaluates exactly in place of layer ``i``'s operator
        (:attr:`layersim.BSDF.lobes`, ``{"top": NearSpecularLobe parameters}``); none by
        default."""
        return {}

    # ---- walk ------------------------------------------------------------------------------

    def walk_boundary(self, scene, i: int) -> WalkBoundary:
        """The walk's boundary record of layer ``i`` (``walk_role == "boundary"``)."""
        raise SceneError(f"the Monte Carlo walk has no record for a {self.name} layer",
                         layer=i, kind=self.name)

    def walk_slab(self, layer) -> tuple:
        """The walk's slab record ``(tau, albedo, g)`` of a layer (``walk_role == "slab"``)."""
        raise SceneError(f"the Monte Carlo walk has no slab for a {self.name} layer",
                         kind=self.name)

    # ---- statistical model -----------------------------------------------------------------

    def statistical_atom(self, layer, refuse):
        """Belcour's atom of the layer: ``("interface", complex ior, alpha)`` or
        ``("absorber", tau)``; ``refuse(field, why)`` builds the error for what the model does
        not represent."""
        raise refuse("kind", f"a {self.name} layer is not represented")

    # ---- fitting ---------------------------------------------------------------------------

    def fit_parameters(self) -> tuple:
        """Names of the fields ``layersim.fit`` may free."""
        return tuple(f.name for f in self.fields if f.fit)
