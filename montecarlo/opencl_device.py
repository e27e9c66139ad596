"""Which OpenCL device the walk may run on: every device is checked once per process by building
a trivial program with the walk's build options, so that a device whose compiler cannot build
(a driver that does not know this CPU, a broken installation) is reported in one line and never
chosen, rather than failing later with a multi-line driver log.

Why a build and not the device list: an OpenCL runtime lists its devices whether or not its
compiler works. PoCL 3.0 as shipped by ``pocl-binary-distribution`` (PoCL 3.0-rc2 on LLVM 14)
asks LLVM for the host CPU's name; LLVM 14 does not know CPUs newer than itself (AMD family 1Ah,
Zen 5, among them) and answers ``generic``, which its own x86 back end then refuses as a target
(``error: unknown target CPU 'generic'``), for every program. That build offers no setting that
changes the CPU name. PoCL 3.1 (LLVM 15) builds on the same CPUs; docs/method.md ("OpenCL
runtimes") says how to install it.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from functools import lru_cache

from ..errors import BackendUnavailableError

__all__ = ["DeviceCheck", "checked_devices", "opencl_device", "opencl_device_names",
           "opencl_device_named", "build_options", "device_label"]

#: Extensions the walk needs: the deterministic fixed-point tallies are 64-bit atomic adds.
REQUIRED_EXTENSIONS = ("cl_khr_int64_base_atomics",)

#: The trivial program of the check; it uses what every walk uses (float math, 64-bit atomics).
_PROBE_SOURCE = """
#pragma OPENCL EXTENSION cl_khr_int64_base_atomics : enable
__kernel void probe(__global long *out, float x)
{
    atom_add(&out[get_global_id(0)], (long)(sqrt(x) * 8.0f));
}
"""

_INSTALL_HINT = ("install an OpenCL runtime that can build here (a GPU vendor's driver, or PoCL "
                 "3.1 or newer for the CPU, e.g. `apt-get install pocl-opencl-icd`; docs/method.md, "
                 "'OpenCL runtimes') or use backend='warp-cpu'")


@dataclass(frozen=True)
class DeviceCheck:
    """One OpenCL device and whether the walk can be built for it.

    Attributes
    ----------
    device : pyopencl.Device
    label : str
        The device, its platform and driver version, as one line.
    reason : str or None
        Why the walk cannot run there (the driver's first error line), or None if it can.
    """

    device: object
    label: str
    reason: str | None

    @property
    def ok(self) -> bool:
        return self.reason is None


def device_label(device) -> str:
    """``"NAME (PLATFORM, DRIVER VERSION)"`` of a pyopencl device, on one line."""
    platform = device.platform
    version = " ".join(platform.version.split())
    return f"{device.name.strip()} ({platform.name.strip()}, {version})"


def build_options(device) -> list:
    """OpenCL build options: correctly rounded single-precision divide and sqrt where the device
    offers them. OpenCL's default allows 2.5-3 ulp there (Warp's CUDA code is correctly rounded),
    which biases the exit azimuths of walks at normal incidence on NVIDIA GPUs (bins beyond 4
    sigma from warp-cuda at 1e7 paths); the option costs some throughput on the coated scenes
    (``benchmarks/montecarlo/mc_throughput.py``; figures in docs/performance.md)."""
    import pyopencl as cl
    if device.single_fp_config & cl.device_fp_config.CORRECTLY_ROUNDED_DIVIDE_SQRT:
        return ["-cl-fp32-correctly-rounded-divide-sqrt"]
    return []


def driver_reason(message: str) -> str:
    """The first error line of a driver's build log (pyopencl puts the log in the exception's
    message), else the message's first line."""
    lines = [ln.strip() for ln in str(message).splitlines() if ln.strip()]
    for ln in lines:
        if "error" in ln.lower() and not ln.lower().startswith(("clbuildprogram failed",
                                                                 "pyopencl")):
            return ln
    return lines[0] if lines else "the build failed without a message"


def build_probe(device) -> None:
    """Build and run the trivial program on ``device``; raises whatever the driver raises."""
    import numpy as np
    import pyopencl as cl
    ctx = cl.Context([device])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # pyopencl's "non-empty compiler output"
        program = cl.Program(ctx, _PROBE_SOURCE).build(options=build_options(device))
    queue = cl.CommandQueue(ctx)
    out = np.zeros(2, np.int64)
    buf = cl.Buffer(ctx, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=out)
    program.probe(queue, (2,), None, buf, np.float32(4.0))
    cl.enqueue_copy(queue, out, buf)
    queue.finish()
    if not (out == 16).all():
        raise RuntimeError(f"error: the probe kernel returned {out.tolist()}, expected [16, 16]")


def check(device) -> DeviceCheck:
    """Check one device: required extensions, then a build and a run of the trivial program."""
    label = device_label(device)
    missing = [e for e in REQUIRED_EXTENSIONS if e not in device.extensions]
    if missing:
        return DeviceCheck(device, label, f"lacks {', '.join(missing)}, which the "
                           "deterministic fixed-point tallies need")
    try:
        build_probe(device)
    except Exception as exc:                       # the driver's errors have no common type
        return DeviceCheck(device, label, driver_reason(exc))
    return DeviceCheck(device, label, None)


@lru_cache(maxsize=1)
def checked_devices() -> tuple:
    """Every OpenCL device of every platform, each checked once per process (GPUs first).

    Returns an empty tuple where pyopencl is missing or no platform is installed."""
    try:
        import pyopencl as cl
        platforms = cl.get_platforms()
    except Exception:                              # no pyopencl, no ICD loader, no platform
        return ()
    devices = [d for p in platforms for d in p.get_devices()]
    devices.sort(key=lambda d: not (d.type & cl.device_type.GPU))
    return tuple(check(d) for d in devices)


def _chosen_by_environment():
    """The device ``$PYOPENCL_CTX`` names (pyopencl's own variable), checked."""
    import pyopencl as cl
    try:
        device = cl.create_some_context(interactive=False).devices[0]
    except Exception as exc:
        raise BackendUnavailableError(
            f"backend 'opencl': PYOPENCL_CTX={os.environ['PYOPENCL_CTX']!r} names no usable "
            f"device ({driver_reason(exc)}); unset it or pick another") from None
    result = check(device)
    if not result.ok:
        raise BackendUnavailableError(
            f"backend 'opencl': {result.label} (PYOPENCL_CTX) cannot run the walk: "
            f"{result.reason}; unset PYOPENCL_CTX, or {_INSTALL_HINT}")
    return device


def opencl_device():
    """The device the OpenCL walk runs on: the one ``$PYOPENCL_CTX`` names if set, else the
    first GPU that builds, else the first device that builds.

    Raises
    ------
    BackendUnavailableError
        pyopencl is missing, there is no device, or no device can build; one line naming each
        device and its driver's reason.
    """
    try:
        import pyopencl  # noqa: F401
    except ImportError:
        raise BackendUnavailableError(
            "backend 'opencl' needs pyopencl: pip install pyopencl, plus an OpenCL runtime "
            "(pip install pocl-binary-distribution gives a CPU device on most CPUs)") from None
    if os.environ.get("PYOPENCL_CTX"):
        return _chosen_by_environment()
    checks = checked_devices()
    for c in checks:
        if c.ok:
            return c.device
    if not checks:
        raise BackendUnavailableError(f"backend 'opencl': no OpenCL device found; {_INSTALL_HINT}")
    failed = "; ".join(f"{c.label}: {c.reason}" for c in checks)
    raise BackendUnavailableError(f"backend 'opencl': no OpenCL device can build the walk here "
                                  f"({failed}); {_INSTALL_HINT}")


def opencl_device_names() -> list[str]:
    """Names ``"opencl:K"`` of the devices that can build the walk here, K counting only those
    (GPUs first, as :func:`checked_devices` orders them): what several-device runs spread over."""
    return [f"opencl:{k}" for k in range(len([c for c in checked_devices() if c.ok]))]


def opencl_device_named(name: str):
    """The device an ``"opencl:K"`` name of :func:`opencl_device_names` stands for.

    Raises
    ------
    ValueError
        ``name`` is not ``"opencl:K"`` or K is not the index of a device that can build the walk.
    """
    usable = [c.device for c in checked_devices() if c.ok]
    head, _, index = str(name).partition(":")
    if head != "opencl" or not index.isdigit() or int(index) >= len(usable):
        have = ", ".join(opencl_device_names()) or "none"
        raise ValueError(f"device {name!r} is not an OpenCL device that can build the walk here "
                         f"(those: {have})")
    return usable[int(index)]
