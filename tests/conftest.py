"""Shared fixtures: the OpenCL device (tests that need one skip where there is none)."""

import pytest


def _opencl_device():
    try:
        import pyopencl as cl
        devices = [d for p in cl.get_platforms() for d in p.get_devices()]
    except Exception:                                       # no ICD loader, no platform
        return None
    return devices[0] if devices else None


@pytest.fixture(scope="session")
def cl_device():
    dev = _opencl_device()
    if dev is None:
        pytest.skip("no OpenCL device (pip install pocl-binary-distribution)")
    return dev
