"""Warp initialisation and device selection, shared by every host module that launches kernels."""

from __future__ import annotations

import os

import warp as wp

_initialised = False


def ensure_init() -> None:
    """Initialise Warp once, quietly (no banner on the command line)."""
    global _initialised
    if not _initialised:
        wp.config.quiet = os.environ.get("LAYERSIM_WARP_VERBOSE", "") == ""
        wp.init()
        _initialised = True


def device_for(device=None):
    """The Warp device to run on: the given one, else ``$LAYERSIM_DEVICE``, else the CPU.

    Projection kernels are cheap and run on the CPU by default; pass ``"cuda"`` (or set
    ``LAYERSIM_DEVICE=cuda``) to run them on a GPU.
    """
    ensure_init()
    name = device or os.environ.get("LAYERSIM_DEVICE") or "cpu"
    return wp.get_device(name)


def cuda_available() -> bool:
    ensure_init()
    return wp.get_cuda_device_count() > 0
