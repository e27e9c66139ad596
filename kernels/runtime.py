"""Warp initialisation and device selection, shared by every host module that launches kernels."""

from __future__ import annotations

import os
import sys

import numpy as np
import warp as wp

from ..config import DEVICE_NAME, ConfigError, settings

_initialised = False


def ensure_init() -> None:
    """Initialise Warp once. Unless ``settings().warp_verbose`` (``LAYERSIM_WARP_VERBOSE``) is
    on, the banner and the native library's "no CUDA driver" notice (printed to the C-level
    stderr on CPU-only machines) are silenced, so that command-line output stays readable."""
    global _initialised
    if _initialised:
        return
    try:
        verbose = settings().warp_verbose
    except ConfigError:
        # initialised at import: a bad LAYERSIM_* variable is reported, as one line naming
        # it, where the settings are used rather than as an import traceback
        verbose = False
    if not verbose:
        # Warp >= 1.18 uses log_level; older versions the quiet flag.
        if hasattr(wp.config, "log_level") and hasattr(wp, "LOG_WARNING"):
            wp.config.log_level = wp.LOG_WARNING
        wp.config.quiet = True
    if verbose:
        wp.init()
    else:
        sys.stderr.flush()
        saved = os.dup(2)
        try:
            with open(os.devnull, "w") as null:
                os.dup2(null.fileno(), 2)
                wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
    _initialised = True


def device_for(device=None):
    """The Warp device to run on: the given one, else ``settings().device``
    (``LAYERSIM_DEVICE``, default the CPU).

    Projection and evaluation kernels are light and run on the CPU by default; pass ``"cuda"``
    (or set ``LAYERSIM_DEVICE=cuda``) to run them on a GPU.

    Raises
    ------
    ConfigError
        For a device that is not ``cpu``, ``cuda`` or ``cuda:N``, or a CUDA device that this
        machine does not have; the message names the argument or ``LAYERSIM_DEVICE``. CUDA is
        checked by counting devices first, so that Warp's native error lines are not printed.
    """
    ensure_init()
    name = device or settings().device
    where = f"device={name!r}" if device else f"LAYERSIM_DEVICE={name!r}"
    if not isinstance(name, str) or not DEVICE_NAME.fullmatch(name):
        raise ConfigError(f"{where}: not a Warp device; use 'cpu', 'cuda' or 'cuda:N'")
    if name.startswith("cuda"):
        count = wp.get_cuda_device_count()
        index = int(name[5:]) if ":" in name else 0
        if index >= count:
            have = (f"{count} CUDA device(s)" if count else
                    "no CUDA device (no GPU, or no driver)")
            raise ConfigError(f"{where}: this machine has {have}; use 'cpu'"
                              + (" or unset LAYERSIM_DEVICE" if not device else ""))
    return wp.get_device(name)


#: numpy dtype of each Warp scalar type the host wrappers pass.
_NUMPY_DTYPE = {wp.float64: np.float64, wp.float32: np.float32, wp.int64: np.int64,
                wp.int32: np.int32}


def host_array(a, dtype, device) -> wp.array:
    """A Warp array of ``dtype`` on ``device`` from host data (converted to the matching numpy
    type and made contiguous first, as ``wp.array`` needs)."""
    return wp.array(np.ascontiguousarray(a, _NUMPY_DTYPE[dtype]), dtype=dtype, device=device)


def cuda_available() -> bool:
    ensure_init()
    return wp.get_cuda_device_count() > 0
