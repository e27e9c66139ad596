"""The OpenCL device check: a device whose compiler cannot build is reported in one line, never
chosen by ``backend="auto"`` and never used by ``backend="opencl"``; tests that need OpenCL skip
with that line only where no device can build.

A device whose build fails is simulated by a test double of the probe build (the driver's
message is the one PoCL 3.0-rc2 on LLVM 14 prints on CPUs newer than LLVM 14), so that these
tests run on every machine, with or without a working OpenCL runtime."""
import subprocess
import sys

import numpy as np
import pytest

import layersim
import layersim.montecarlo as mc
from layersim.montecarlo import backends, opencl_device as od

POCL_30_LOG = """clBuildProgram failed: BUILD_PROGRAM_FAILURE - clBuildProgram failed: \
BUILD_PROGRAM_FAILURE - clBuildProgram failed: BUILD_PROGRAM_FAILURE

Build on <pyopencl.Device 'pthread-AMD EPYC' on 'Portable Computing Language' at 0x55>:

error: unknown target CPU 'generic'
Device pthread-AMD EPYC failed to build the program

(options: -cl-fp32-correctly-rounded-divide-sqrt -I /x/pyopencl/cl)"""

SLAB = layersim.Scene.from_dict({"layer": [{"kind": "medium", "tau": 1.0, "albedo": 0.9}]})


class _FakePlatform:
    name = "Portable Computing Language"
    version = "OpenCL 3.0 PoCL 3.0-rc2  Linux, Release, RELOC, LLVM 14.0.6"


class _FakeDevice:
    """Stands for a CPU device whose driver lists it but cannot build any program."""
    name = "pthread-AMD EPYC"
    platform = _FakePlatform()
    extensions = "cl_khr_int64_base_atomics cl_khr_fp64"
    max_compute_units = 64


def _failing_build(device):
    raise RuntimeError(POCL_30_LOG)


@pytest.fixture
def broken_opencl(monkeypatch):
    """Every OpenCL device of this process is the failing test double."""
    real = od.checked_devices
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    monkeypatch.setattr(od, "build_probe", _failing_build)
    monkeypatch.setattr(od, "checked_devices", lambda: (od.check(_FakeDevice()),))
    yield
    real.cache_clear()


def test_the_driver_reason_is_its_first_error_line():
    assert od.driver_reason(POCL_30_LOG) == "error: unknown target CPU 'generic'"
    assert od.driver_reason("CL_OUT_OF_RESOURCES\nmore") == "CL_OUT_OF_RESOURCES"


def test_a_device_that_cannot_build_is_reported_in_one_line(broken_opencl):
    (c,) = od.checked_devices()
    assert not c.ok and c.reason == "error: unknown target CPU 'generic'"
    assert "pthread-AMD EPYC" in c.label and "3.0-rc2" in c.label
    with pytest.raises(mc.BackendUnavailableError) as err:
        od.opencl_device()
    msg = str(err.value)
    assert "\n" not in msg
    assert "unknown target CPU 'generic'" in msg and "pthread-AMD EPYC" in msg
    assert "pocl-opencl-icd" in msg and "warp-cpu" in msg


def test_auto_never_picks_a_device_that_cannot_build(broken_opencl):
    names = mc.available_backends()
    assert "opencl" not in names and "warp-cpu" in names
    res = mc.simulate(SLAB, [0, 0, 1], 1000, backend="auto")
    assert res.backend in ("warp-cpu", "warp-cuda")


def test_simulate_on_opencl_refuses_in_one_line(broken_opencl):
    with pytest.raises(mc.BackendUnavailableError, match="unknown target CPU 'generic'") as err:
        mc.simulate(SLAB, [0, 0, 1], 1000, backend="opencl")
    assert "\n" not in str(err.value)


def test_bench_on_opencl_refuses_in_one_line(broken_opencl, capsys, tmp_path, monkeypatch):
    import layersim.bench
    from layersim.cli import main

    def no_bench(*a, **k):
        raise AssertionError("the bench ran")
    monkeypatch.setattr(layersim.bench, "run", no_bench)
    assert main(["bench", "--out", str(tmp_path / "b"), "--backend", "opencl"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("layersim: error:") and "\n" not in err
    assert "unknown target CPU 'generic'" in err


def test_a_device_without_64_bit_atomics_is_not_chosen(monkeypatch):
    class NoAtomics(_FakeDevice):
        extensions = "cl_khr_fp64"
    c = od.check(NoAtomics())
    assert not c.ok and "cl_khr_int64_base_atomics" in c.reason


def test_the_chosen_device_builds_and_runs_the_probe(cl_device):
    """Where a device is chosen, it really builds and runs a program (the check is not a
    formality): the probe's atomics give the expected sums."""
    od.build_probe(cl_device)
    assert od.check(cl_device).ok


@pytest.mark.slow
def test_the_opencl_line_in_a_fresh_process_names_each_device():
    """In a fresh process (no cached checks) every device's check is printed in one line each by
    ``layersim.montecarlo.opencl_device``'s table, the same that the bench report shows."""
    code = ("from layersim.montecarlo.opencl_device import checked_devices\n"
            "for c in checked_devices(): print(c.label, '->', c.reason or 'ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    lines = [ln for ln in out.stdout.splitlines() if ln.strip()]
    assert all("->" in ln for ln in lines)
    assert np.all([len(ln) < 400 for ln in lines])
