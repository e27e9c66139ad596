"""Warp kernels (installed as ``layersim.kernels``): the per-interface and per-medium physics
(:mod:`.physics`) and its values on host arrays (:mod:`.pointwise`, :mod:`.fresnel`,
:mod:`.lobe`, :mod:`.fgd`), BSDF sampling for Fourier projection (:mod:`.projection`),
evaluation of tabulated Fourier series (:mod:`.fourier_eval`; 2-D series of anisotropic stacks:
:mod:`.fourier_eval2d`), and the particle random walk used by :mod:`layersim.montecarlo`
(:mod:`.walk`, with :mod:`.sampling` and the Philox generator :mod:`.rng`). Kernels run on
Warp's CPU device and on CUDA; the walk also runs on OpenCL devices through C source generated
from the same functions (:mod:`.opencl_codegen`)."""

from .runtime import ensure_init as _ensure_init

# Initialise before any module defines kernels, so the banner and notices stay silenced.
_ensure_init()
