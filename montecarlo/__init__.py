"""Particle Monte Carlo reference for layer stacks (installed as ``layersim.montecarlo``).

Particles walk through the stack with exactly the per-interface and per-medium physics of
:mod:`layersim.kernels.physics` (sampled by :mod:`layersim.kernels.sampling`, driven by the
Philox generator of :mod:`layersim.kernels.rng`, walk in :mod:`layersim.kernels.walk`), on Warp
(CPU, CUDA) or OpenCL (source generated from the same Warp functions). See ``docs/conventions.md``::

    import layersim.montecarlo as mc
    res = mc.simulate(scene, wi, particles, mu_edges=..., phi_edges=..., backend="auto", seed=0)
    res.reflectance, res.reflectance_stderr, res.bins["top"], res.bins_stderr["top"]

Modules: :mod:`.driver` (entry point, batching), :mod:`.checks` (input validation),
:mod:`.work` (path ranges of a walk, the unit of work anywhere), :mod:`.campaign` (resumable runs
of many walks on a pluggable executor), :mod:`.executors` (where ranges run: serially, one thread
per device, a Dask cluster), :mod:`.sweep` (sweep files: scenes x angles x channels as walks),
:mod:`.resultfile` (``layersim mc`` result files),
:mod:`.compare` (walks against a solve or other walks), :mod:`.plots` (their pictures),
:mod:`.stack` (scene -> kernel parameters), :mod:`.backends` (Warp / OpenCL launch),
:mod:`.estimates` (integer tallies -> fractions and standard errors), :mod:`.result`
(:class:`MCResult`).
"""

from .backends import BACKENDS, BackendUnavailableError, available_backends
from .result import MCResult
from .driver import simulate

__all__ = ["simulate", "MCResult", "BACKENDS", "BackendUnavailableError", "available_backends"]
