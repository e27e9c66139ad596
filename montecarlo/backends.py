"""Where the random walk runs: Warp (CPU or CUDA) or OpenCL (through pyopencl).

Both backends launch the same walk, :func:`layersim.kernels.walk.walk_thread`: Warp compiles it
directly, the OpenCL backend compiles the C source that :mod:`layersim.kernels.opencl_codegen`
generates from it. A backend here only allocates buffers, launches one batch of particles and
returns the integer tallies of that batch, summed over the kernel's replicas.

Backends
--------
``"warp-cpu"``   Warp's CPU device (always present; runs a launch on one core).
``"warp-cuda"``  Warp on the first CUDA device.
``"opencl"``     the OpenCL device named by ``$PYOPENCL_CTX`` if set, else the first GPU that
                 can build the walk, else the first device that can (PoCL's CPU device uses
                 every core); devices are checked once per process by
                 :mod:`.opencl_device`.
``"auto"``       the fastest one present: warp-cuda; else opencl on a GPU, or on a CPU device
                 with at least :data:`OPENCL_CPU_MIN_UNITS` compute units, that can build the
                 walk; else warp-cpu.

Why the CPU threshold: PoCL's float32 math library is several times slower than Warp's, so per
core PoCL reaches well under half of warp-cpu's paths/s (``benchmarks/montecarlo/mc_throughput.py``;
figures in docs/performance.md) and only beats single-threaded warp-cpu with three or more
cores; four keeps a margin.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import BackendUnavailableError
from ..kernels import walk
from ..kernels.opencl_codegen import Program, parameters
from ..kernels.runtime import ensure_init
from .opencl_device import (build_options, device_label, opencl_device, opencl_device_named,
                            opencl_device_names)
from .stack import StackArrays

__all__ = ["BACKENDS", "BackendUnavailableError", "Launch", "available_backends", "check_device",
           "device_names", "make_runner", "resolve_backend", "why_unavailable"]

BACKENDS = ("auto", "warp-cpu", "warp-cuda", "opencl")
#: An OpenCL CPU device needs this many compute units to be preferred over warp-cpu by "auto".
OPENCL_CPU_MIN_UNITS = 4

#: Registers per thread of the CUDA walk kernel: 64 lets four blocks of 256 threads share a
#: multiprocessor (three at the compiler's 72-80), 6-12 % more paths/s on an H100; 56 and
#: below spill (``benchmarks/montecarlo/walk_tuning_h100.txt``).
CUDA_MAX_REGISTERS = 64
#: Particles each GPU thread walks one after the other (amortises the thread's counter atomics).
GPU_PARTICLES_PER_THREAD = 8

#: Kernel parameters of the walk, in order (the thread index excluded).
_PARAMS = [name for name, _ in parameters(walk.walk_thread)[1:]]


@dataclass(frozen=True)
class Launch:
    """Everything a backend needs for a run (one channel, one incident direction)."""

    stack: StackArrays
    wi: np.ndarray            # float32 (3,)
    mu_edges: np.ndarray      # float32
    phi_edges: np.ndarray     # float32
    seed: int
    max_steps: int

    @property
    def n_bins(self) -> int:
        """Bins per side including the total."""
        return (len(self.mu_edges) - 1) * (len(self.phi_edges) - 1) + 1


# ------------------------------------------------------------------------------------------------
# Discovery
# ------------------------------------------------------------------------------------------------


def _cuda_count() -> int:
    ensure_init()
    import warp as wp
    return wp.get_cuda_device_count()


def available_backends() -> list[str]:
    """Backends that can run here, fastest first."""
    out = []
    if _cuda_count() > 0:
        out.append("warp-cuda")
    try:
        device = opencl_device()
    except BackendUnavailableError:
        device = None
    fast_opencl = device is not None and (
        not _is_cpu(device) or device.max_compute_units >= OPENCL_CPU_MIN_UNITS)
    if fast_opencl:
        out.append("opencl")
    out.append("warp-cpu")
    if device is not None and not fast_opencl:
        out.append("opencl")
    return out


def why_unavailable(backend: str) -> str | None:
    """Why a backend cannot run here (one line naming the device and the reason), or None."""
    try:
        if backend == "opencl":
            opencl_device()
        elif backend == "warp-cuda" and _cuda_count() == 0:
            return ("backend 'warp-cuda': Warp sees no CUDA device; install an NVIDIA driver "
                    "(and a CUDA build of warp-lang), or use backend='opencl' or 'warp-cpu'")
    except BackendUnavailableError as exc:
        return str(exc)
    return None


def _is_cpu(device) -> bool:
    import pyopencl as cl
    return bool(device.type & cl.device_type.CPU)


def resolve_backend(backend: str) -> str:
    """Validate a backend name and resolve ``"auto"``."""
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; expected one of {', '.join(BACKENDS)}")
    if backend == "auto":
        return available_backends()[0]
    return backend


def make_runner(backend: str, launch: Launch, device: str | None = None):
    """A runner for a resolved backend name: ``runner.run(first, count) -> (tally, counters)``.

    ``device`` names the device: a Warp CUDA device (``"cuda:1"``) for ``"warp-cuda"``,
    ``"cpu"`` for ``"warp-cpu"``, ``"opencl:K"`` (:func:`.opencl_device.opencl_device_names`)
    for ``"opencl"``; None is the backend's default device."""
    check_device(backend, device)
    if backend == "opencl":
        return _OpenCLRunner(launch, None if device is None else opencl_device_named(device))
    return _WarpRunner(launch, cuda=(backend == "warp-cuda"), device=device)


def check_device(backend: str, device: str | None) -> None:
    """Refuse a device name of another backend (one line naming both)."""
    if device is None:
        return
    fits = {"warp-cuda": lambda d: d == "cuda" or d.startswith("cuda:"),
            "warp-cpu": lambda d: d == "cpu",
            "opencl": lambda d: d.startswith("opencl:")}
    if not isinstance(device, str) or not fits.get(backend, lambda d: False)(device):
        want = {"warp-cuda": "'cuda:K'", "warp-cpu": "'cpu'", "opencl": "'opencl:K'"}
        raise ValueError(f"device {device!r} is not a device of backend {backend!r} "
                         f"(expected {want.get(backend, 'none')})")


def device_names(backend: str) -> list[str]:
    """Every device of a resolved backend here, by the names :func:`make_runner` takes:
    ``["cuda:0", "cuda:1", ...]`` (Warp's CUDA devices), ``["cpu"]``, or ``["opencl:0", ...]``
    (the OpenCL devices that can build the walk; ``$PYOPENCL_CTX``, which picks the one device
    of a plain ``"opencl"`` run, is not consulted)."""
    if backend == "warp-cuda":
        if _cuda_count() == 0:
            return []
        import warp as wp
        return [d.alias for d in wp.get_cuda_devices()]
    if backend == "opencl":
        return opencl_device_names()
    return ["cpu"]


def _kernel_args(launch: Launch, n_threads: int, per_thread: int, first: int, count: int,
                 n_copies: int) -> dict:
    st = launch.stack
    return dict(
        n_threads=n_threads, per_thread=per_thread, first=first, count=count,
        seed_lo=launch.seed & 0xFFFFFFFF, seed_hi=(launch.seed >> 32) & 0xFFFFFFFF,
        wi=launch.wi, n_slabs=st.n_slabs, max_steps=launch.max_steps,
        n_mu_edges=len(launch.mu_edges), n_phi_edges=len(launch.phi_edges), n_copies=n_copies)


def _reduce(tally: np.ndarray, counters: np.ndarray, n_copies: int, n_bins: int):
    """Sum the replicas (int64, exact): tally (2 sides, 2 moments, n_bins), counters (2,)."""
    t = tally.reshape(n_copies, 2, 2, n_bins).sum(axis=0, dtype=np.int64)
    c = counters.reshape(n_copies, 2).sum(axis=0, dtype=np.int64)
    return t, c


# ------------------------------------------------------------------------------------------------
# Warp
# ------------------------------------------------------------------------------------------------


class _WarpRunner:
    def __init__(self, launch: Launch, cuda: bool, device: str | None = None):
        ensure_init()
        import warp as wp
        self.wp = wp
        if cuda:
            reason = why_unavailable("warp-cuda")
            if reason:
                raise BackendUnavailableError(reason)
            self.device = wp.get_device(device or "cuda")
        else:
            self.device = wp.get_device("cpu")
        self.name = "warp-cuda" if cuda else "warp-cpu"
        self.device_name = f"{self.device.alias} ({self.device.name})"
        self.launch = launch
        self.kernel = walk.program(launch.stack.features,
                                   CUDA_MAX_REGISTERS if cuda else None).kernel
        # compile and load the kernel's module on the device now, not at the first launch: a
        # runner is built under work.py's build lock, while launches of several device threads
        # run at the same time and must find the module loaded
        wp.load_module(self.kernel.module, device=self.device)
        # GPUs: replicas spread the atomics, a few particles per thread amortise the counters;
        # Warp's CPU device runs a launch serially on one core, so one replica suffices.
        self.n_copies = 256 if cuda else 1
        self.per_thread = GPU_PARTICLES_PER_THREAD if cuda else 1
        dev = self.device
        st = launch.stack
        self.arrays = dict(
            bnd_i=wp.array(st.bnd_i, dtype=wp.int32, device=dev),
            bnd_f=wp.array(st.bnd_f, dtype=wp.float32, device=dev),
            slab_f=wp.array(st.slab_f, dtype=wp.float32, device=dev),
            mu_edges=wp.array(launch.mu_edges, dtype=wp.float32, device=dev),
            phi_edges=wp.array(launch.phi_edges, dtype=wp.float32, device=dev),
            tally=wp.zeros(self.n_copies * 4 * launch.n_bins, dtype=wp.int64, device=dev),
            counters=wp.zeros(self.n_copies * 2, dtype=wp.int64, device=dev))

    def run(self, first: int, count: int):
        wp = self.wp
        n_threads = -(-count // self.per_thread)
        args = _kernel_args(self.launch, n_threads, self.per_thread, first, count, self.n_copies)
        args["wi"] = wp.vec3(*[float(x) for x in self.launch.wi])
        args["first"] = wp.int64(first)
        args["seed_lo"] = wp.uint32(args["seed_lo"])
        args["seed_hi"] = wp.uint32(args["seed_hi"])
        args.update(self.arrays)
        self.arrays["tally"].zero_()
        self.arrays["counters"].zero_()
        wp.launch(self.kernel, dim=n_threads, inputs=[args[p] for p in _PARAMS],
                  device=self.device)
        return _reduce(self.arrays["tally"].numpy(), self.arrays["counters"].numpy(),
                       self.n_copies, self.launch.n_bins)


# ------------------------------------------------------------------------------------------------
# OpenCL
# ------------------------------------------------------------------------------------------------

#: (id(context), features) -> the built walk program. Each runner makes its own kernel object
#: from it: a kernel's arguments are state, and runners of other threads set theirs concurrently.
_PROGRAMS: dict = {}


def opencl_source(features: walk.Features | None = None) -> str:
    """OpenCL C source of the walk kernel ``walk`` for ``features`` (default: every path),
    generated from the Warp functions."""
    prog = Program()
    prog.add_kernel(walk.program(features or walk.Features.every()).thread, name="walk")
    return prog.source()


class _OpenCLRunner:
    def __init__(self, launch: Launch, device=None):
        import pyopencl as cl
        self.cl = cl
        device = device or opencl_device()
        self.name = "opencl"
        self.device_name = device_label(device)
        self.ctx = _context_for(device)
        self.queue = cl.CommandQueue(self.ctx)
        features = launch.stack.features
        key = (id(self.ctx), features)
        if key not in _PROGRAMS:
            _PROGRAMS[key] = cl.Program(self.ctx, opencl_source(features)).build(
                options=build_options(device))
        self.kernel = cl.Kernel(_PROGRAMS[key], "walk")
        gpu = bool(device.type & cl.device_type.GPU)
        self.n_copies = 256 if gpu else 4 * max(device.max_compute_units, 1)
        self.per_thread = GPU_PARTICLES_PER_THREAD if gpu else 1
        self.launch = launch
        st = launch.stack
        mf = cl.mem_flags
        ro = mf.READ_ONLY | mf.COPY_HOST_PTR
        self.buffers = dict(
            bnd_i=cl.Buffer(self.ctx, ro, hostbuf=st.bnd_i),
            bnd_f=cl.Buffer(self.ctx, ro, hostbuf=st.bnd_f),
            slab_f=cl.Buffer(self.ctx, ro, hostbuf=st.slab_f),
            mu_edges=cl.Buffer(self.ctx, ro, hostbuf=launch.mu_edges),
            phi_edges=cl.Buffer(self.ctx, ro, hostbuf=launch.phi_edges))
        self.tally = np.zeros(self.n_copies * 4 * launch.n_bins, dtype=np.int64)
        self.counters = np.zeros(self.n_copies * 2, dtype=np.int64)
        self.buffers["tally"] = cl.Buffer(self.ctx, mf.READ_WRITE, self.tally.nbytes)
        self.buffers["counters"] = cl.Buffer(self.ctx, mf.READ_WRITE, self.counters.nbytes)

    def run(self, first: int, count: int):
        cl = self.cl
        n_threads = -(-count // self.per_thread)
        args = _kernel_args(self.launch, n_threads, self.per_thread, first, count, self.n_copies)
        scalars = dict(
            n_threads=np.int32, per_thread=np.int32, first=np.int64, count=np.int32,
            seed_lo=np.uint32, seed_hi=np.uint32, n_slabs=np.int32, max_steps=np.int32,
            n_mu_edges=np.int32, n_phi_edges=np.int32, n_copies=np.int32)
        values = {k: t(args[k]) for k, t in scalars.items()}
        values["wi"] = cl.cltypes.make_float3(*[float(x) for x in self.launch.wi])
        values.update(self.buffers)
        cl.enqueue_fill_buffer(self.queue, self.buffers["tally"], np.int64(0), 0,
                               self.tally.nbytes)
        cl.enqueue_fill_buffer(self.queue, self.buffers["counters"], np.int64(0), 0,
                               self.counters.nbytes)
        done = self.kernel(self.queue, (n_threads,), None, *[values[p] for p in _PARAMS])
        self.queue.flush()
        # Wait by polling with sleeps: a blocking wait spins in the host thread, which on a
        # CPU device (PoCL) takes a core away from the kernel's worker threads.
        while done.command_execution_status != cl.command_execution_status.COMPLETE:
            if done.command_execution_status < 0:
                raise RuntimeError(f"OpenCL walk kernel failed (status "
                                   f"{done.command_execution_status})")
            time.sleep(0.0005)
        cl.enqueue_copy(self.queue, self.tally, self.buffers["tally"])
        cl.enqueue_copy(self.queue, self.counters, self.buffers["counters"])
        self.queue.finish()
        return _reduce(self.tally, self.counters, self.n_copies, self.launch.n_bins)


_CONTEXTS: dict = {}


def _context_for(device):
    import pyopencl as cl
    key = device.int_ptr
    if key not in _CONTEXTS:
        _CONTEXTS[key] = cl.Context([device])
    return _CONTEXTS[key]
