"""The fit template of a statistical design: its parameters freed around their statistical
values (``{ fit = [lo, hi], start = value }``, :mod:`layersim.fit.template`).

What is freed, per layer of the design (Bati et al. 2021's stacks: GGX interfaces and
Beer-Lambert media):

- a rough dielectric interface: its index and its roughness. The index stays on its side of
  the index above it (the interface never passes through index matching, where its lobe
  vanishes and its sign of contrast flips): its contrast ``ior - above`` may halve or double,
  within ``[1, eta_max]`` (Bati et al.'s design domain);
- a rough conductor: ``k`` per channel within a factor 3 of its design value (``k <= 100``,
  the largest the designs use), and its roughness. ``eta`` stays: at a given reflectance it
  is the design's choice in the conductor's equivalence class (its edge tint, Bati et al.
  2021 eq. 9-10), which the lobes at normal incidence barely see: freed too (at the fit's
  default tolerance), eta and k of "coat over copper-like conductor" came out with standard
  errors of 120 and 280 (eta 4.6, k 23, correlated), eta at its bound in two channels, after
  259 solves (57 with eta kept, at tolerance 1e-6);
- roughness: within a factor 2 either way, below 1 (exact transport moves a 2-layer lobe's
  width from the coat to the base: within a factor 1.5, "rough gold-like conductor" ended with
  its coat and base roughnesses and the red k on their bounds, 10.6 % off in energy);
- an absorbing medium: each channel's optical thickness that the design makes positive,
  within ``[0, 3 tau]``; a channel the design leaves clear (``tau = 0``: the channel of
  largest attenuated energy, Bati et al. 2021 sec. 5.1.1) stays clear;
- smooth interfaces stay as designed: their lobe is a Fresnel mirror, the same in the
  statistical model and in exact transport, and their delta is not in ``eval``, which the
  fit compares.
"""

from __future__ import annotations

import copy

__all__ = ["refine_template", "has_free", "CONTRAST_FACTOR", "ROUGHNESS_FACTOR", "CONDUCTOR_FACTOR"]

#: How far the index contrast with the medium above may shrink or grow (a factor).
CONTRAST_FACTOR = 2.0
#: How far a roughness may shrink or grow (a factor).
ROUGHNESS_FACTOR = 2.0
#: How far a conductor's k may shrink or grow (a factor).
CONDUCTOR_FACTOR = 3.0
#: Largest free k of a conductor (the bound of :mod:`..design.invert`).
K_MAX = 100.0
#: Largest free roughness.
ALPHA_MAX = 0.95


def _free(value: float, lo: float, hi: float) -> dict:
    return {"fit": [float(lo), float(hi)], "start": float(value)}


def _dielectric_index(ior: float, above: float, eta_max: float) -> dict | float:
    contrast = ior - above
    if contrast == 0.0:
        return ior
    ends = (above + contrast / CONTRAST_FACTOR, above + contrast * CONTRAST_FACTOR)
    lo, hi = max(min(ends), 1.0), min(max(ends), eta_max)
    return _free(ior, min(lo, ior), max(hi, ior))


def _factor(value: float, factor: float, hi: float) -> dict:
    return _free(value, value / factor, min(value * factor, max(hi, value)))


def _conductor_index(ior) -> list:
    """``[eta, k]`` or three such pairs, ``k`` freed by :data:`CONDUCTOR_FACTOR`."""
    if isinstance(ior[0], (list, tuple)):
        return [_conductor_index(pair) for pair in ior]
    eta, k = ior
    return [eta, _factor(k, CONDUCTOR_FACTOR, K_MAX)]


def _tau(tau):
    if isinstance(tau, (list, tuple)):
        return [_tau(t) for t in tau]
    return _free(tau, 0.0, 3.0 * tau) if tau > 0.0 else tau


def _free_medium(layer: dict, above: float, eta_max: float) -> tuple:
    return {**layer, "tau": _tau(layer["tau"])}, above


def _free_dielectric(layer: dict, above: float, eta_max: float) -> tuple:
    if layer.get("roughness", 0.0) <= 0.0:
        return layer, float(layer["ior"])
    return ({**layer, "roughness": _factor(layer["roughness"], ROUGHNESS_FACTOR, ALPHA_MAX),
             "ior": _dielectric_index(layer["ior"], above, eta_max)}, float(layer["ior"]))


def _free_conductor(layer: dict, above: float, eta_max: float) -> tuple:
    if layer.get("roughness", 0.0) <= 0.0:
        return layer, above
    return {**layer, "roughness": _factor(layer["roughness"], ROUGHNESS_FACTOR, ALPHA_MAX),
            "ior": _conductor_index(layer["ior"])}, above


#: Per kind of a designed layer: ``(layer, index above, eta_max) -> (template layer, index
#: below)``.
FREE = {"medium": _free_medium, "dielectric": _free_dielectric, "conductor": _free_conductor}


def refine_template(data: dict, free, eta_max: float = 4.0) -> dict:
    """The template dict of the designed scene dict ``data`` (:class:`~layersim.statistical.
    design.Design`'s ``data``, or a cut of it), the parameters of the layers whose indices
    are in ``free`` freed as the module docstring says; the others fixed."""
    out = copy.deepcopy(data)
    above = float(out.get("stack", {}).get("top_ior", 1.0))
    for i, layer in enumerate(out["layer"]):
        freed, below = FREE[layer["kind"]](layer, above, eta_max)
        out["layer"][i] = freed if i in free else layer
        above = below
    return out


def has_free(template: dict) -> bool:
    """Whether the template dict holds a free value."""
    if isinstance(template, dict):
        return "fit" in template or any(has_free(v) for v in template.values())
    if isinstance(template, (list, tuple)):
        return any(has_free(v) for v in template)
    return False
