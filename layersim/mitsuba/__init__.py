"""Mitsuba 3 BSDF plug-in for solved layersim stacks.

After :func:`register`, a Mitsuba 3 scene may use ``{"type": "layersim", "filename":
"x.lsim"}`` (or ``<bsdf type="layersim"><string name="filename" value="x.lsim"/></bsdf>``) to
render a stack solved by ``layersim solve`` or :meth:`layersim.solved.bsdf.BSDF.save`.

What it does: ``eval``, ``pdf``, ``eval_pdf`` and ``sample`` from the solved Fourier series
(reflection and transmission, isotropic and anisotropic stacks, near-specular lobes as part of
the glossy component), the delta parts of smooth interfaces and unscattered transmission as
Mitsuba delta components, Mitsuba's local shading frame, ``eval`` with the cosine
``|cos theta_o|``, and the ``TransportMode`` factor ``(eta_wi / eta_wo)^2`` in radiance mode
(:mod:`layersim.mitsuba.wavefront` states the conventions).

Variants (tested with Mitsuba 3.9.1, tests/test_mitsuba_plugin.py):

* ``scalar_rgb``: works; one ray per call (Mitsuba's scalar model), about a millisecond of
  Python and Warp per call (benchmarks/features/mitsuba_plugin.txt).
* ``scalar_spectral``: works; one-channel stacks are flat spectra, three-channel (RGB) stacks
  are upsampled with Mitsuba's RGB-to-spectrum model (:mod:`layersim.mitsuba.drjit_io`), exact
  for grey and an approximation of the stack's own spectral response otherwise (solve it per
  wavelength for that).
* ``llvm_ad_rgb`` and ``llvm_ad_mono`` (the luminance) are tested; ``llvm_ad_spectral``
  takes one-channel stacks and refuses RGB ones (:func:`layersim.mitsuba.plugin.
  refuse_rgb_in_jit_spectral`); the ``cuda_ad_*`` variants take the same code path, untested.
  Whole wavefronts are converted to numpy once per call. LLVM >= 16 is needed
  (``DRJIT_LIBLLVM_PATH``). Calls must be evaluated, not recorded: integrators that trace
  symbolic loops or virtual calls need ``dr.set_flag(dr.JitFlag.SymbolicLoops, False)`` and
  ``dr.set_flag(dr.JitFlag.SymbolicCalls, False)``. No gradients flow through the plug-in.
* ``*_polarized`` variants are refused by :func:`register` (layersim solves intensities, not
  Mueller matrices).
"""

from __future__ import annotations

from ..errors import LayersimError

#: Name of the plug-in in Mitsuba scenes.
PLUGIN_NAME = "layersim"


def register(name: str = PLUGIN_NAME) -> None:
    """Register the plug-in with Mitsuba 3 for the current variant (call after
    ``mi.set_variant``, again after switching variants).

    Raises
    ------
    LayersimError
        If mitsuba is not installed, no variant is set, or the variant is polarized.
    """
    try:
        import mitsuba as mi
    except ImportError as exc:
        raise LayersimError(f"the Mitsuba 3 plug-in needs the 'mitsuba' package ({exc}); "
                            "pip install mitsuba") from None
    variant = mi.variant()
    if variant is None:
        raise LayersimError("set a Mitsuba variant first (mi.set_variant('scalar_rgb')), then "
                            "call layersim.mitsuba.register()")
    if "polarized" in variant:
        raise LayersimError(f"Mitsuba variant {variant!r} is polarized: the layersim plug-in "
                            "returns unpolarized values; use a non-polarized variant")
    from .plugin import plugin_class
    cls = plugin_class(mi)
    mi.register_bsdf(name, lambda props: cls(props))
