"""Import a pbrt-v4 material as a layersim scene (``Scene.from_pbrt``, ``layersim import-pbrt``).

pbrt-v4's ``coatedconductor`` and ``coateddiffuse`` materials (``LayeredBxDF``, Guo et al. 2018's
position-free random walk) and its ``conductor``, ``dielectric`` and ``diffuse`` materials map
onto stacks of this package's layers with the same parameters (Pharr, Jakob, Humphreys,
"Physically Based Rendering", 4th ed., sec. 9.2-9.6 and 14.3; pbrt-v4's ``materials.cpp``):

* roughness: ``roughness`` or ``uroughness`` / ``vroughness`` (``interface.`` / ``conductor.``
  prefixed in a coated conductor); with ``remaproughness`` true (pbrt's default) the GGX
  ``alpha = sqrt(roughness)`` (``TrowbridgeReitzDistribution::RoughnessToAlpha``);
* every microfacet interface is GGX with the height-correlated Smith term that pbrt-v4 uses
  (``shadowing = "height-correlated"``, :func:`layersim.kernels.physics.smith_g2`), except
  where its roughness is near-specular (alpha <= 0.03; the separable term there, and a note);
* ``thickness`` is an optical depth (pbrt's layers have ``sigma_t = 1``), ``albedo`` and ``g``
  the medium's single-scattering albedo and Henyey-Greenstein asymmetry (a layer of zero
  thickness is left out);
* a conductor's ``eta`` / ``k`` are absolute (layersim divides by the coat's index as pbrt's
  ``CoatedConductorMaterial`` does); a conductor given by ``reflectance`` r has ``eta = 1``,
  ``k = 2 sqrt(r) / sqrt(1 - r)`` (pbrt-v4's ``ConductorMaterial``);
* values are numbers (``float``, ``rgb``, or a ``spectrum`` given as one constant); named or
  sampled spectra are refused with the parameter named; ``maxdepth`` and ``nsamples`` (the
  stochastic evaluation's path depth and sample count) are reported as not needed.

The result is a plain dict in the scene format of ``docs/conventions.md`` plus a list of notes.
"""

from __future__ import annotations

import math
import re

from .errors import SceneError
from .solved.lobe import NEAR_SPECULAR_ALPHA

__all__ = ["pbrt_to_dict", "MATERIALS"]

#: The pbrt-v4 material types this importer reads.
MATERIALS = ("coatedconductor", "coateddiffuse", "conductor", "dielectric", "diffuse")
#: Parameters of each type that this importer uses (the rest of pbrt's are refused).
_PARAMS = {
    "coatedconductor": {"interface.roughness", "interface.uroughness", "interface.vroughness",
                        "interface.eta", "thickness", "albedo", "g", "conductor.roughness",
                        "conductor.uroughness", "conductor.vroughness", "conductor.eta",
                        "conductor.k", "reflectance", "remaproughness", "maxdepth", "nsamples"},
    "coateddiffuse": {"roughness", "uroughness", "vroughness", "eta", "thickness", "albedo", "g",
                      "reflectance", "remaproughness", "maxdepth", "nsamples"},
    "conductor": {"roughness", "uroughness", "vroughness", "eta", "k", "reflectance",
                  "remaproughness"},
    "dielectric": {"roughness", "uroughness", "vroughness", "eta", "remaproughness"},
    "diffuse": {"reflectance"},
}
_TOKEN = re.compile(r'"[^"]*"|\[|\]|[^\s\[\]"#]+|#[^\n]*')


def _tokens(text: str) -> list[str]:
    return [t for t in _TOKEN.findall(text) if not t.startswith("#")]


def _materials(text: str) -> list[tuple[str, dict]]:
    """``(type, {name: (type, values)})`` of every ``Material`` and ``MakeNamedMaterial``."""
    toks, out, i = _tokens(text), [], 0
    while i < len(toks):
        directive = toks[i]
        i += 1
        if directive not in ("Material", "MakeNamedMaterial"):
            continue
        if i < len(toks) and toks[i].startswith('"') and directive == "MakeNamedMaterial":
            i += 1                          # the material's name
        mtype = toks[i].strip('"') if directive == "Material" else None
        i += 1 if directive == "Material" else 0
        params = {}
        while i + 1 < len(toks) and toks[i].startswith('"') and " " in toks[i].strip('"'):
            ptype, name = toks[i].strip('"').split(None, 1)
            i, values = _values(toks, i + 1)
            params[name] = (ptype, values)
        if mtype is None:
            mtype = params.pop("type", ("string", [None]))[1][0]
        out.append((mtype, params))
    return out


def _values(toks, i):
    if toks[i] == "[":
        j = toks.index("]", i)
        return j + 1, [_literal(t) for t in toks[i + 1:j]]
    return i + 1, [_literal(toks[i])]


def _literal(token: str):
    if token.startswith('"'):
        return token.strip('"')
    if token in ("true", "false"):
        return token == "true"
    return float(token)


def _number(params, name, default, per_channel=True):
    """A numeric parameter: a float, an rgb triple (one value when all three agree) or a
    constant spectrum; named or sampled spectra are refused."""
    if name not in params:
        return default
    ptype, values = params[name]
    if any(isinstance(v, str) for v in values) or ptype not in ("float", "rgb", "spectrum"):
        raise SceneError(f"pbrt parameter \"{ptype} {name}\" {values!r}: only numeric values "
                         "(float, rgb or a constant spectrum) are imported; named spectra are "
                         "not", field=name)
    if ptype == "spectrum" and len(values) != 1:
        raise SceneError(f"pbrt parameter \"spectrum {name}\": a sampled spectrum is not "
                         "imported; give a float or rgb value", field=name)
    if ptype == "rgb" and per_channel:
        if len(values) != 3:
            raise SceneError(f"pbrt parameter \"rgb {name}\" needs 3 values", field=name)
        return values[0] if values[0] == values[1] == values[2] else list(values)
    return values[0]


def _roughness(params, prefix, remap):
    """GGX ``alpha`` (one value or ``[alpha_u, alpha_v]``) of ``prefix`` roughness."""
    r = _number(params, prefix + "roughness", 0.0, per_channel=False)
    u = _number(params, prefix + "uroughness", r, per_channel=False)
    v = _number(params, prefix + "vroughness", r, per_channel=False)
    au, av = (math.sqrt(u), math.sqrt(v)) if remap else (u, v)
    return au if au == av else [au, av]


def _interface(kind, ior, alpha, notes, what):
    layer = {"kind": kind, "ior": ior, "roughness": alpha}
    lo = min(alpha) if isinstance(alpha, list) else alpha
    if lo > 0:
        layer["distribution"] = "ggx"
        if lo <= NEAR_SPECULAR_ALPHA:
            layer["shadowing"] = "separable"
            notes.append(f"{what}: alpha {lo:g} is near-specular (<= {NEAR_SPECULAR_ALPHA:g}); "
                         "its lobe uses the separable Smith term (pbrt-v4: height-correlated)")
    return layer


def _conductor_ior(params, prefix):
    if prefix + "eta" in params or prefix + "k" in params:
        if prefix + "eta" not in params or prefix + "k" not in params:
            missing = prefix + ("k" if prefix + "eta" in params else "eta")
            raise SceneError(f"pbrt parameter {missing} is missing (a conductor needs both "
                             "eta and k, or reflectance)", field=missing)
        eta, k = _number(params, prefix + "eta", None), _number(params, prefix + "k", None)
    elif "reflectance" in params:
        r = _number(params, "reflectance", None)
        rs = r if isinstance(r, list) else [r]
        eta, k = [1.0] * len(rs), [2 * math.sqrt(x) / math.sqrt(max(1 - x, 1e-4)) for x in rs]
    else:
        raise SceneError(f"pbrt's default conductor is the named spectrum metal-Cu-eta / -k: "
                         f"give numeric {prefix}eta and {prefix}k (or reflectance)",
                         field=prefix + "eta")
    etas, ks = (eta if isinstance(eta, list) else [eta]), (k if isinstance(k, list) else [k])
    if len(etas) == len(ks) == 1:
        return [etas[0], ks[0]]
    etas, ks = etas * (3 // len(etas)), ks * (3 // len(ks))
    return [[e, x] for e, x in zip(etas, ks)]


def _layers(mtype, params, notes) -> list:
    remap = params.get("remaproughness", ("bool", [True]))[1][0]
    if not isinstance(remap, bool):
        raise SceneError(f"pbrt parameter remaproughness must be true or false, got {remap!r}",
                         field="remaproughness")
    if mtype == "diffuse":
        return [{"kind": "diffuse", "albedo": _number(params, "reflectance", 0.5)}]
    if mtype == "dielectric":
        return [_interface("dielectric", _number(params, "eta", 1.5, per_channel=False),
                           _roughness(params, "", remap), notes, "dielectric")]
    if mtype == "conductor":
        return [_interface("conductor", _conductor_ior(params, ""), _roughness(params, "", remap),
                           notes, "conductor")]
    coated = mtype == "coatedconductor"
    pre = "interface." if coated else ""
    layers = [_interface("dielectric", _number(params, pre + "eta", 1.5, per_channel=False),
                         _roughness(params, pre, remap), notes, "coat")]
    tau = _number(params, "thickness", 0.01, per_channel=False)
    if tau > 0:
        layers.append({"kind": "medium", "tau": tau, "albedo": _number(params, "albedo", 0.0),
                       "g": _number(params, "g", 0.0, per_channel=False)})
    if coated:
        layers.append(_interface("conductor", _conductor_ior(params, "conductor."),
                                 _roughness(params, "conductor.", remap), notes, "base"))
    else:
        layers.append({"kind": "diffuse", "albedo": _number(params, "reflectance", 0.5)})
    return layers


def pbrt_to_dict(text: str, name: str = "pbrt") -> tuple[dict, list]:
    """The scene (dict in the format of ``docs/conventions.md``) of the one material of a
    pbrt-v4 scene text, and the notes on what was not needed or changed.

    Raises
    ------
    SceneError
        No material, several, an unsupported type or parameter, or a non-numeric value (the
        message names the parameter).
    """
    found = _materials(text)
    if len(found) != 1:
        raise SceneError(f"the pbrt text has {len(found)} Material / MakeNamedMaterial "
                         "directives; import one at a time")
    mtype, params = found[0]
    if mtype not in MATERIALS:
        raise SceneError(f"pbrt material type {mtype!r} is not imported (types: "
                         + ", ".join(MATERIALS) + ")", field="type")
    unknown = sorted(set(params) - _PARAMS[mtype])
    if unknown:
        raise SceneError(f"pbrt parameter {unknown[0]!r} of a {mtype} material is not imported "
                         "(imported: " + ", ".join(sorted(_PARAMS[mtype])) + ")",
                         field=unknown[0])
    notes = [f"{p}: not needed (the solve is deterministic: no path depth or sample count)"
             for p in ("maxdepth", "nsamples") if p in params]
    if mtype.startswith("coated"):
        notes.append("pbrt-v4's layered materials are two-sided; the scene is the stack seen "
                     "from its coated side")
    layers = _layers(mtype, params, notes)
    stack = {"name": name}
    if any(x.get("distribution") == "ggx" for x in layers):
        stack["shadowing"] = "height-correlated"
    return {"stack": stack, "layer": layers}, notes
