"""Designed stacks as scenes that :func:`layersim.solve` and the Monte Carlo reference accept:
GGX interfaces (``distribution = "ggx"``) and Beer-Lambert media (``albedo = 0``, ``tau`` per
channel)."""

from __future__ import annotations

from dataclasses import dataclass

from ...scene import Scene
from ..atomic import Absorber


def _value(values):
    return values[0] if all(v == values[0] for v in values) else list(values)


def _layer_dict(per_channel) -> dict:
    first = per_channel[0]
    if isinstance(first, Absorber):
        return {"kind": "medium", "albedo": 0.0, "tau": _value([a.tau for a in per_channel])}
    if first.ior.imag > 0.0:
        iors = [[a.ior.real, a.ior.imag] for a in per_channel]
        ior = iors[0] if all(i == iors[0] for i in iors) else iors
        return {"kind": "conductor", "ior": ior, "roughness": first.alpha,
                "distribution": "ggx"}
    return {"kind": "dielectric", "ior": first.ior.real, "roughness": first.alpha,
            "distribution": "ggx"}


@dataclass(frozen=True)
class Design:
    """A designed stack: ``data`` (the scene dict), ``scene``, ``groups`` (per target lobe,
    the indices of its interfaces among the scene's layers), ``choice`` (the member of the
    equivalence classes taken) and ``notes`` (one line each: a base inferred, a refinement)."""

    data: dict
    scene: Scene
    groups: list
    choice: object
    notes: tuple = ()

    def toml(self) -> str:
        """The scene as TOML text (``layersim solve`` reads it)."""
        lines = [f"# designed by layersim design (Bati et al. 2021), position {self.choice} in "
                 "the equivalence classes (0: low end, 0.5: middle, 1: high end)"]
        lines += [f"# {note}" for note in self.notes]
        lines += ["[stack]", f"name = \"{self.data['stack']['name']}\"", ""]
        for layer in self.data["layer"]:
            lines.append("[[layer]]")
            for key, value in layer.items():
                lines.append(f"{key} = {_toml(value)}")
            lines.append("")
        return "\n".join(lines)


def _toml(value) -> str:
    if isinstance(value, str):
        return f"\"{value}\""
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return repr(float(value))


def to_scene(stacks, groups, targets, choice) -> Design:
    """The :class:`Design` of per-channel atom lists ``stacks``."""
    layers = [_layer_dict([s[i] for s in stacks]) for i in range(len(stacks[0]))]
    data = {"stack": {"name": "design"}, "layer": layers}
    return Design(data, Scene.from_dict(data), groups, choice)
