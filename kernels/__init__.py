"""Warp kernels (installed as ``layersim.kernels``): the per-interface and per-medium physics
(:mod:`.physics`), BSDF sampling for Fourier projection (:mod:`.projection`), and the particle
random walk used by :mod:`layersim.montecarlo`. Kernels run on Warp's CPU device and on CUDA."""
