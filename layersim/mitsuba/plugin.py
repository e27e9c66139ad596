"""The ``layersim`` BSDF plug-in class for Mitsuba 3 (built per variant).

Mitsuba 3 defines a Python BSDF as a subclass of the current variant's ``mi.BSDF`` with
``sample``, ``eval``, ``pdf`` and ``eval_pdf`` (Mitsuba 3 documentation, "Custom plugins in
Python"); the class therefore exists once per variant (:func:`plugin_class`). Its methods
convert the call's Dr.Jit values to numpy once (:mod:`layersim.mitsuba.drjit_io`), compute on
the whole wavefront with layersim (:mod:`layersim.mitsuba.wavefront`) and convert back.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..solved.bsdf import BSDF
from ..errors import LayersimError
from . import drjit_io as io
from . import wavefront as wf

_CLASSES: dict = {}
_LOADED: dict = {}


def load_stack(path: str) -> BSDF:
    """The solved stack in ``path`` (``.lsim``), cached by resolved path and modification
    time: Mitsuba may instantiate the plug-in many times for one file."""
    p = Path(path).resolve()
    key = (str(p), p.stat().st_mtime_ns)
    if key not in _LOADED:
        _LOADED[key] = BSDF.load(p)
    return _LOADED[key]


def delta_sides(bsdf, probes: int = 16) -> tuple[bool, bool]:
    """Whether the stack has delta reflection and delta transmission, found by evaluating
    :meth:`BSDF.specular` from ``probes`` elevations on each side it can be lit from."""
    mu = np.cos(np.linspace(0.0, 0.5 * np.pi, probes + 2)[1:-1])
    sides = (1.0,) if bsdf.opaque else (1.0, -1.0)
    wi = np.concatenate([np.stack([np.sqrt(1 - mu**2), 0 * mu, s * mu], 1) for s in sides])
    spec = bsdf.specular(wi)
    up = wi[:, 2] > 0
    energy = {s: np.asarray(spec[s][0]).reshape(len(wi), -1).max(axis=1) for s in spec}
    refl = np.where(up, energy["top"], energy["bottom"])
    trans = np.where(up, energy["bottom"], energy["top"])
    return bool(np.any(refl > 0)), bool(np.any(trans > 0))


def refuse_rgb_in_jit_spectral(variant: str, bsdf, filename: str) -> None:
    """Refuse a three-channel stack in a JIT spectral variant: Mitsuba's RGB-to-spectrum model
    (``mi.srgb_model_fetch``) takes one scalar colour per call from Python, which would be a
    Python loop per ray; scalar_spectral calls it once per ray as Mitsuba does."""
    if "spectral" in variant and not variant.startswith("scalar") and bsdf.channels == 3:
        raise LayersimError(
            f"layersim BSDF {filename}: a three-channel (RGB) stack in the JIT spectral "
            f"variant {variant!r} is not supported (Mitsuba's RGB-to-spectrum model is "
            "callable only per ray from Python); use an rgb variant or scalar_spectral")


def component_flags(mi, bsdf) -> list:
    """The four components' ``BSDFFlags`` (:data:`layersim.mitsuba.wavefront.GLOSSY_R` ...),
    ``BSDFFlags.Empty`` for those the stack lacks."""
    F = mi.BSDFFlags
    sides = F.FrontSide if bsdf.opaque else F.FrontSide | F.BackSide
    extra = F.Anisotropic if bsdf.anisotropic else F.Empty
    d_r, d_t = delta_sides(bsdf)
    trans = not bsdf.opaque
    return [F.GlossyReflection | sides | extra,
            (F.GlossyTransmission | sides | extra | F.NonSymmetric) if trans else F.Empty,
            (F.DeltaReflection | sides) if d_r else F.Empty,
            (F.DeltaTransmission | sides | F.NonSymmetric) if d_t else F.Empty]


def enabled_components(ctx, flags) -> list:
    """Which components ``ctx`` enables, as ``BSDFContext.is_enabled`` decides (a component
    index of ``2^32 - 1`` means all; the type mask must share a bit with the component's
    flags); computed here because the combined flags are plain ints that ``is_enabled`` does
    not take from Python."""
    mask, comp = int(ctx.type_mask), int(ctx.component)
    return [(comp in (0xFFFFFFFF, k)) and (mask & int(f)) != 0 for k, f in enumerate(flags)]


def plugin_class(mi):
    """The plug-in class of the current variant (built once per variant)."""
    variant = mi.variant()
    if variant not in _CLASSES:
        _CLASSES[variant] = _make_class(mi)
    return _CLASSES[variant]


def _make_class(mi):
    """A subclass of the current variant's ``mi.BSDF`` (module docstring)."""

    class LayersimBSDF(mi.BSDF):
        """A solved layersim stack (``filename``: a ``.lsim`` file) as a Mitsuba 3 BSDF."""

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            if "filename" not in props:
                raise ValueError("layersim BSDF: the 'filename' property (a .lsim file "
                                 "written by 'layersim solve' or BSDF.save) is missing")
            name = str(props["filename"])
            resolved = str(mi.file_resolver().resolve(name))
            self.filename = resolved if os.path.exists(resolved) else name
            self.stack = load_stack(self.filename)
            refuse_rgb_in_jit_spectral(mi.variant(), self.stack, self.filename)
            flags = component_flags(mi, self.stack)
            self.component_flags = flags        # m_components reads back as plain ints
            self.m_components = flags
            union = mi.BSDFFlags.Empty
            for f in flags:
                union = union | f
            self.m_flags = union

        def _enabled(self, ctx) -> list:
            return enabled_components(ctx, self.component_flags)

        def _radiance(self, ctx) -> bool:
            return ctx.mode == mi.TransportMode.Radiance

        def _inputs(self, si, wo, active):
            n = max(io.width(si.wi), io.width(wo), io.width(active))
            return n, io.unit_rows(si.wi, n), io.unit_rows(wo, n), io.mask(active, n)

        def _eval_pdf(self, ctx, si, wo, active, want):
            n, a, b, act = self._inputs(si, wo, active)
            value, pdf = wf.eval_pdf(self.stack, a, b, act, self._radiance(ctx),
                                     self._enabled(ctx), want)
            w = io.Writer(mi, si, n)
            return w.spectrum(value), w.float(pdf)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active, (True, True))

        def eval(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active, (True, False))[0]

        def pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(ctx, si, wo, active, (False, True))[1]

        def sample(self, ctx, si, sample1, sample2, active=True):
            n = max(io.width(si.wi), io.width(sample1), io.width(sample2), io.width(active))
            s = wf.sample(self.stack, io.unit_rows(si.wi, n), io.rows(sample1, n, 0),
                          io.rows(sample2, n, 2), io.mask(active, n), self._radiance(ctx),
                          self._enabled(ctx))
            w = io.Writer(mi, si, n)
            flags = np.array([int(f) for f in self.component_flags], np.int64)
            bs = mi.BSDFSample3f() if w.scalar else mi.BSDFSample3f(dr_zeros(mi, n))
            bs.wo = w.vector(s["wo"])
            bs.pdf = w.float(s["pdf"])
            bs.eta = w.float(s["eta"])
            bs.sampled_component = w.uint(s["component"])
            bs.sampled_type = w.uint(np.where(s["pdf"] > 0, flags[s["component"]], 0))
            return bs, w.spectrum(s["weight"])

        def to_string(self):
            return f"LayersimBSDF[filename={self.filename!r}, {self.stack!r}]"

    return LayersimBSDF


def dr_zeros(mi, n: int):
    """A zero-initialised wavefront of ``n`` BSDF samples (JIT variants)."""
    import drjit as dr
    return dr.zeros(mi.BSDFSample3f, n)
