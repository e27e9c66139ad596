"""What a plan says: the discretisation chosen, what each layer gets, and why."""

from __future__ import annotations

from dataclasses import dataclass, field

from ..layers.base import LayerPlan
from ..operators.operator import Grid

__all__ = ["LayerPlan", "Plan"]


@dataclass
class Plan:
    """What :func:`layersim.solve` will compute (see :mod:`layersim.plan`).

    ``memory_bytes`` is the estimated peak memory of the solve and ``seconds`` the time
    model's estimate by part (:func:`layersim.plan.budget.estimate_seconds`), ``work`` its work
    units (:mod:`layersim.plan.cost`); ``seconds`` and ``work`` are None for a plan refused
    before the pre-pass.
    """

    rule: str
    n: int
    md: int
    ms: int = 0
    representation: str = "isotropic"
    layers: list = field(default_factory=list)
    left_out: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    memory_bytes: int = 0
    seconds: dict | None = None
    work: dict | None = None
    overridden: dict = field(default_factory=dict)
    #: Why the solve refuses this plan (over the memory limit), or None; set only by
    #: ``make_plan(scene, refuse=False)``.
    refused: str | None = None
    #: Smooth dielectric boundaries of the stack, ``{"top" | "bottom": index outside}``
    #: (:mod:`layersim.solved.boundary`).
    boundary: dict = field(default_factory=dict)
    #: Near-specular rough boundaries among them, ``{"top": parameters}`` of
    #: :class:`layersim.solved.lobe.NearSpecularLobe`, and the layer indices they stand for.
    lobes: dict = field(default_factory=dict)
    near_specular: tuple = ()
    #: A brushed top coat projected with its narrow roughness raised (its own reflection left
    #: out, evaluated as its exact lobe; :mod:`layersim.layers.brushed`): ``{"floor"`` (the
    #: lowest, whose plan this is), ``"floors"``, ``"weights"`` (their extrapolation weights),
    #: ``"alpha_u", "alpha_v"}`` (the coat's own), or None. The memory and time count a solve
    #: per floor.
    brushed: dict | None = None
    #: Near-specular inner interfaces under a rough one, split: their transmission and
    #: reflection from below projected at a raised roughness, their reflection from above a
    #: mirror or projected at their own roughness (:mod:`layersim.layers.near_specular_inner`):
    #: ``{"floor", "layers": {index: (alpha_u, alpha_v)}, "exact": (index, ...)}`` (their own
    #: roughnesses, and those whose reflection from above is projected at it), or None. This
    #: plan is that of the raised stack, with ``n`` resolving the projected reflection lobes.
    inner_mirrors: dict | None = None

    @property
    def grid(self) -> Grid:
        return Grid.make(self.rule, self.n)

    def report(self) -> str:
        """Human-readable summary (printed by ``layersim plan`` and ``layersim solve``)."""
        if self.representation == "specular-paths":
            return self._paths_report()
        src = lambda k: " (from the scene)" if k in self.overridden else ""
        basis = ("(cosine series in the azimuth difference)" if self.representation == "isotropic"
                 else "(Fourier series in phi_d and phi_s, coupled modes, Zeltner & Jakob 2018, "
                      "eq. (7)-(10))")
        lines = [
            f"representation: {self.representation} {basis}",
            f"ordinates: n = {self.n}{src('n')}, {self.rule}{src('quadrature')} "
            f"({self.n // 2} per hemisphere)",
            f"Fourier orders: md = {self.md}{src('md')}" + (f", ms = {self.ms}{src('ms')}"
                                                          if self.representation != "isotropic"
                                                          else ", ms = 0"),
            f"estimated memory: {self.memory_bytes / 2**20:.1f} MiB",
            "estimated time: " + ("not estimated (refused before the pre-pass)"
                                  if self.seconds is None else
                                  f"{self.seconds['total']:.2g} s (projection "
                                  f"{self.seconds['projection']:.2g} s, media "
                                  f"{self.seconds['media']:.2g} s, adding "
                                  f"{self.seconds['adding']:.2g} s; calibrated on a 2-core "
                                  "VM)"),
        ]
        for lp in self.layers:
            lines.append(f"  layer {lp.index} ({lp.kind}): {lp.action}"
                         + (f" -- {lp.detail}" if lp.detail else ""))
        for item in self.left_out:
            lines.append(f"  left out: {item}")
        for note in self.notes:
            lines.append(f"  note: {note}")
        if self.refused:
            lines.append(f"refused: {self.refused}")
        return "\n".join(lines)

    def _paths_report(self) -> str:
        """:meth:`report` of a stack solved by specular paths (:mod:`layersim.plan.route`)."""
        lines = ["representation: specular paths (flat interfaces and clear media; "
                 "layersim.specular_paths)",
                 f"estimated memory: {self.memory_bytes / 2**20:.1f} MiB"]
        lines += [f"  layer {lp.index} ({lp.kind}): {lp.action}" for lp in self.layers]
        lines += [f"  note: {note}" for note in self.notes]
        return "\n".join(lines)
