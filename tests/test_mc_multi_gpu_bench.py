"""benchmarks/montecarlo/multi_gpu.py runs from a staged checkout, checks the tallies of N
devices against one, and says so plainly where there is no device to spread over."""

import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "montecarlo" / "multi_gpu.py"


def _run(*args):
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=300)


@pytest.mark.slow
def test_two_cpu_threads_give_the_one_device_tallies():
    p = _run("--backend", "warp-cpu", "--devices", "cpu,cpu", "--seconds", "0.2", "--scenes",
             "slab")
    assert p.returncode == 0, p.stderr
    rows = [ln.split() for ln in p.stdout.splitlines() if ln.startswith("slab ")]
    assert [r[1] for r in rows] == ["1", "2"] and all(r[7] == "same" for r in rows)
    assert f"from {ROOT}" not in p.stdout and "layersim-stage-" in p.stdout  # staged, not installed
    for key in ("# command:", "# machine:", "# date:", "commit:"):
        assert key in p.stdout


@pytest.mark.slow
def test_no_cuda_device_is_a_plain_message():
    import layersim.montecarlo.backends as b
    if b.device_names("warp-cuda"):
        pytest.skip("this machine has CUDA devices")
    p = _run("--scenes", "slab")
    assert p.returncode == 0 and "no warp-cuda device is visible here" in p.stdout
