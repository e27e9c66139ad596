"""Warp kernels (installed as ``layersim.kernels``): the per-interface and per-medium physics
(:mod:`.physics`), BSDF sampling for Fourier projection (:mod:`.projection`), and the particle
random walk used by :mod:`layersim.montecarlo` (:mod:`.walk`, with :mod:`.sampling` and the
Philox generator :mod:`.rng`). Kernels run on Warp's CPU device and on CUDA; the walk also runs
on OpenCL devices through C source generated from the same functions (:mod:`.opencl_codegen`)."""
