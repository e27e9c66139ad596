"""Executors of path ranges (montecarlo/executors): serial, one thread per device, a Dask cluster.

Every executor must give the same integers as the serial run for any split and any number of
workers (the random numbers of a path depend on (seed, path) alone and tallies are integer
sums); a worker that dies mid-run must cost only its range; leaving early must cancel."""

import functools
import math
import os
import sys
import threading
import time

import numpy as np
import pytest

from layersim import Scene
from layersim.errors import ClusterError
from layersim.montecarlo.executors import Dask, Devices, InProcess, devices as devices_mod
from layersim.montecarlo.executors import tls_security
from layersim.montecarlo.work import Walk, run_range, split

SCENES = {
    "slab": {"layer": [{"kind": "medium", "albedo": 0.95, "g": 0.5, "tau": 2.0}]},
    "coated_conductor": {"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": [0.1, 0.2]},
        {"kind": "conductor", "ior": [0.143552, 3.98397], "roughness": [0.2, 0.1]}]},
    "coated_medium": {"layer": [
        {"kind": "dielectric", "ior": 1.5, "roughness": 0.3},
        {"kind": "medium", "tau": 1.0, "albedo": 0.8, "g": 0.5}]},
}
THETAS = (0.0, 35.0, 70.0)
PATHS = 1200


def _walks():
    out = []
    for data in SCENES.values():
        scene = Scene.from_dict(data)
        for theta in THETAS:
            t = math.radians(theta)
            out.append(Walk(scene, (math.sin(t), 0.0, math.cos(t)), (0.0, 0.5, 1.0),
                            (0.0, math.pi, 2 * math.pi), 11, 10_000, "warp-cpu"))
    return out


WALKS = _walks()


def _ranges(batch):
    # interleave the walks' ranges, as a sweep hands them out
    per_walk = [split(w, 0, PATHS, batch) for w in WALKS]
    return [r for group in zip(*per_walk) for r in group] + [
        r for rs in per_walk for r in rs[min(map(len, per_walk)):]]


def _totals(pairs):
    """{walk key: summed tally} from (range, tally) pairs."""
    out = {}
    for r, t in pairs:
        k = r.walk.key()
        out[k] = t if k not in out else out[k] + t
    return out


def _same(a, b):
    assert a.keys() == b.keys()
    for k in a:
        assert a[k].particles == b[k].particles == PATHS
        assert (a[k].events, a[k].truncated) == (b[k].events, b[k].truncated)
        assert np.array_equal(a[k].w, b[k].w)


@pytest.fixture(scope="module")
def serial():
    with InProcess() as ex:
        return _totals(ex.map(_ranges(PATHS)))     # one range per walk


def test_serial_split_equals_whole_walks(serial):
    with InProcess() as ex:
        assert ex.describe() == "in process"
        _same(_totals(ex.map(_ranges(250))), serial)
        assert ex.describe().startswith("cpu (") and ex.device == ex.describe()
    # the walks differ from one another, so equal totals are not a coincidence
    assert len({tuple(t.w.ravel()) for t in serial.values()}) == len(WALKS)


def test_two_threads_on_the_cpu_device_equal_serial(serial):
    with Devices("warp-cpu", ["cpu", "cpu"]) as ex:
        assert ex.describe() == "warp-cpu on cpu, cpu"
        _same(_totals(ex.map(_ranges(300))), serial)


def test_every_listed_device_by_default_gets_work(serial, monkeypatch):
    # a host whose backend lists three devices (the CPU device three times stands in for GPUs)
    monkeypatch.setattr(devices_mod, "device_names", lambda backend: ["cpu"] * 3)
    used = []
    real = devices_mod.run_range

    def slow_run_range(r, device):
        used.append((threading.current_thread().name, device))
        return real(r, device)

    monkeypatch.setattr(devices_mod, "run_range", slow_run_range)
    with Devices("warp-cpu") as ex:
        assert ex.devices == ["cpu"] * 3
        _same(_totals(ex.map(_ranges(100))), serial)
    assert {d for _, d in used} == {"cpu"}
    assert len({name for name, _ in used}) == 3


def _longest_stall(call) -> float:
    """The longest time (s) this thread cannot run Python while another thread makes ``call``."""
    done = threading.Event()
    other = threading.Thread(target=lambda: (call(), done.set()))
    longest, last = 0.0, time.perf_counter()
    other.start()
    while not done.is_set():
        now = time.perf_counter()
        longest, last = max(longest, now - last), now
    other.join()
    return longest


@pytest.mark.slow
def test_a_warp_cpu_launch_releases_the_gil():
    # Devices keeps several devices busy from one process only if a launch lets other Python
    # threads run meanwhile: a launch that kept the GIL would stall this thread for its length
    import ctypes
    from layersim.montecarlo.backends import make_runner
    runner = make_runner("warp-cpu", WALKS[0].launch())
    runner.run(0, 1000)
    t0 = time.perf_counter()
    runner.run(0, 1 << 16)
    paths = int((1 << 16) * 0.15 / (time.perf_counter() - t0))      # a launch of ~0.15 s
    t0 = time.perf_counter()
    stall = _longest_stall(lambda: runner.run(0, paths))
    length = time.perf_counter() - t0
    print(f"longest stall {stall * 1e3:.1f} ms during a {length * 1e3:.0f} ms launch")
    assert stall < length / 3
    # the probe tells them apart: a 0.3 s C call that keeps the GIL (ctypes.PyDLL) stalls it
    held = _longest_stall(lambda: ctypes.PyDLL(None).usleep(300_000))
    print(f"longest stall {held * 1e3:.1f} ms during a 300 ms GIL-holding call")
    assert held > 0.2


@pytest.mark.slow
def test_two_threads_on_an_opencl_device_equal_serial(cl_device):
    # one OpenCL device twice: two runners (each its own queue and kernel object) at once
    walks = [Walk(w.scene, w.wi, w.mu_edges, w.phi_edges, w.seed, w.max_steps, "opencl")
             for w in WALKS[:2]]
    ranges = [r for w in walks for r in split(w, 0, 4000, 500)]
    with InProcess() as ex:
        serial = _totals(ex.map(ranges))
    with Devices("opencl", ["opencl:0", "opencl:0"]) as ex:
        threaded = _totals(ex.map(ranges))
    for k in serial:
        assert np.array_equal(serial[k].w, threaded[k].w)
        assert serial[k].events == threaded[k].events and serial[k].particles == 4000


def test_device_names_are_checked():
    with pytest.raises(ValueError, match="'cuda:0' is not a device of backend 'warp-cpu'"):
        Devices("warp-cpu", ["cuda:0"])
    with pytest.raises(ValueError, match="devices: expected 'all' or a comma-separated"):
        Devices("warp-cpu", "cpu,,cpu")
    with pytest.raises(ValueError, match="unknown backend"):
        Devices("gpu")


def test_devices_raise_a_worker_error_in_the_consumer():
    other = Walk(WALKS[0].scene, WALKS[0].wi, WALKS[0].mu_edges, WALKS[0].phi_edges, 1, 100,
                 "opencl")
    with Devices("warp-cpu", ["cpu", "cpu"]) as ex:
        with pytest.raises(ValueError, match="walk backend 'opencl' does not match"):
            list(ex.map(split(WALKS[0], 0, 400, 100) + split(other, 0, 100, 100)))


def _counting(ranges, taken):
    for r in ranges:
        taken.append(r)
        yield r


@pytest.mark.parametrize("interrupt", [KeyboardInterrupt, None])
def test_devices_stop_when_the_consumer_leaves(interrupt):
    taken = []
    ex = Devices("warp-cpu", ["cpu", "cpu"])
    if interrupt is None:
        for _ in ex.map(_counting(split(WALKS[0], 0, 4000, 50), taken)):
            break
    else:
        with pytest.raises(KeyboardInterrupt):
            with ex:
                for _ in ex.map(_counting(split(WALKS[0], 0, 4000, 50), taken)):
                    raise KeyboardInterrupt
    ex.close()
    # one range consumed; at most one more per device was under way or just pulled
    assert len(taken) <= 1 + 2 * 2
    assert not [t for t in threading.enumerate() if t.name.startswith("layersim-cpu")]


# ---- Dask -------------------------------------------------------------------------------------

def test_dask_arguments_are_checked_before_any_cluster():
    for kwargs, field in [({}, "workers/address"), ({"workers": 2, "address": "tcp://x:1"},
                                                      "workers/address"),
                          ({"workers": 0}, "workers"), ({"workers": True}, "workers"),
                          ({"workers": 1, "in_flight": 0}, "in_flight"),
                          ({"workers": 1, "retries": -1}, "retries"),
                          ({"address": ""}, "address"),
                          ({"workers": 1, "security": object()}, "security")]:
        with pytest.raises(ValueError, match=f"^{field}"):
            Dask(**kwargs)


def test_tls_files_are_checked(tmp_path):
    assert tls_security() is None                   # Dask's own configuration applies
    ca = tmp_path / "ca.pem"
    ca.write_text("x")
    with pytest.raises(ValueError, match="^tls_cert: cannot read"):
        tls_security(str(ca), str(tmp_path / "missing.pem"))
    with pytest.raises(ValueError, match="^tls_cert: TLS needs both"):
        tls_security(str(ca))


@pytest.mark.slow
def test_no_scheduler_is_one_clear_error():          # importing distributed takes ~0.7 s
    with pytest.raises(ClusterError, match="cannot reach the Dask scheduler at 'tcp://127.0.0.1:9'"):
        Dask(address="tcp://127.0.0.1:9", timeout=0.3)


@pytest.fixture(scope="module")
def two_workers():
    """One local cluster of two workers for the tests below (clusters are slow to start)."""
    with Dask(workers=2, in_flight=3) as ex:
        yield ex


@pytest.mark.slow
@pytest.mark.parametrize("workers,batch", [(1, 400), (2, 170), (3, 1200)])
def test_dask_local_cluster_equals_serial(serial, two_workers, workers, batch):
    if workers == 2:
        ex = two_workers
        _same(_totals(ex.map(_ranges(batch))), serial)
    else:
        with Dask(workers=workers, in_flight=None if workers == 1 else 2) as ex:
            assert ex.describe().startswith(f"dask: {workers} workers at tcp://")
            _same(_totals(ex.map(_ranges(batch))), serial)


@pytest.mark.slow
def test_the_workers_resolve_and_check_the_backend(two_workers):
    from layersim.montecarlo.backends import resolve_backend, why_unavailable
    assert two_workers.resolve_backend("auto") == resolve_backend("auto")
    if why_unavailable("warp-cuda"):                   # no GPU on the workers (this machine)
        with pytest.raises(ClusterError, match=r"^Dask worker tcp://\S+ \(and 1 more\) cannot "
                                               r"run the walk: backend 'warp-cuda'"):
            two_workers.resolve_backend("warp-cuda")


@pytest.mark.slow
def test_dask_interrupted_consumer_cancels_the_rest(two_workers):
    taken = []
    with pytest.raises(KeyboardInterrupt):
        for _ in two_workers.map(_counting(split(WALKS[0], 0, 100_000, 100), taken)):
            raise KeyboardInterrupt
    assert len(taken) <= 1 + 3                          # bounded: in_flight + the next one
    assert not two_workers._running


@pytest.mark.slow
def test_workers_with_another_layersim_are_refused(two_workers, monkeypatch):
    import layersim
    theirs = layersim.__version__
    monkeypatch.setattr(layersim, "__version__", "0.0.0-client")
    with pytest.raises(ClusterError, match=rf"^2 Dask worker\(s\) run layersim {theirs} \(e.g. "
                                           r"tcp://.*\), this client 0.0.0-client; install"):
        Dask(address=two_workers.client.scheduler.address)


def _die_once(flag, r):
    """Kill this worker process on the first range of the run (whichever worker gets it)."""
    try:
        os.close(os.open(flag, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        return run_range(r)
    os._exit(1)


@pytest.mark.slow
def test_a_worker_killed_mid_run_costs_only_its_range(serial, two_workers, tmp_path):
    import cloudpickle
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    flag = tmp_path / "died"
    address = two_workers.client.scheduler.address
    with Dask(address=address, task=functools.partial(_die_once, str(flag))) as ex:
        assert ex.describe() == f"dask: 2 workers at {address}"
        _same(_totals(ex.map(_ranges(400))), serial)
    assert flag.exists()


def _fail_once(flag, r):
    """Raise on the first range of the run (whichever worker gets it), then walk normally."""
    try:
        os.close(os.open(flag, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        return run_range(r)
    raise RuntimeError("a transient failure")


@pytest.mark.slow
@pytest.mark.parametrize("retries", [1, 0])
def test_a_failed_range_is_retried(serial, two_workers, tmp_path, retries):
    import cloudpickle
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    task = functools.partial(_fail_once, str(tmp_path / "failed"))
    with Dask(address=two_workers.client.scheduler.address, task=task, retries=retries) as ex:
        if retries:
            _same(_totals(ex.map(_ranges(PATHS))), serial)
        else:
            with pytest.raises(RuntimeError, match="a transient failure"):
                list(ex.map(_ranges(PATHS)))


@pytest.fixture
def tls_files(tmp_path):
    """A self-signed certificate (its own CA) and key for 127.0.0.1, made with openssl."""
    import shutil
    import subprocess
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed")
    cert, key = tmp_path / "cert.pem", tmp_path / "key.pem"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-keyout",
                    str(key), "-out", str(cert), "-days", "1", "-subj", "/CN=localhost"],
                   check=True, capture_output=True)
    return str(cert), str(key)


@pytest.mark.slow
def test_a_tls_scheduler_with_files_or_dask_config(serial, tls_files):
    import dask
    from distributed import LocalCluster
    from distributed.security import Security
    cert, key = tls_files
    sec = Security(tls_ca_file=cert, tls_scheduler_cert=cert, tls_scheduler_key=key,
                   tls_worker_cert=cert, tls_worker_key=key, tls_client_cert=cert,
                   tls_client_key=key, require_encryption=True)
    with LocalCluster(n_workers=1, threads_per_worker=1, protocol="tls://", security=sec,
                      dashboard_address=None, scheduler_kwargs={"dashboard_address": ":0"}
                      ) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tls://")
        with Dask(address=address, security=tls_security(cert, cert, key)) as ex:
            assert ex.describe() == f"dask: 1 workers at {address}"
            _same(_totals(ex.map(_ranges(PATHS))), serial)
        config = {"distributed.comm.tls.ca-file": cert, "distributed.comm.tls.client.cert": cert,
                  "distributed.comm.tls.client.key": key}
        with dask.config.set(config), Dask(address=address) as ex:
            _same(_totals(ex.map(_ranges(PATHS))), serial)
        with pytest.raises(ValueError, match="^security: the scheduler 'tls://.*' speaks TLS"):
            Dask(address=address)


@pytest.mark.slow
def test_a_range_that_keeps_killing_workers_is_one_line():   # imports distributed
    import distributed
    from layersim.montecarlo.executors import cluster

    class Killed:
        def result(self):
            last = type("WorkerState", (), {"address": "tcp://10.0.0.5:4000"})()
            raise distributed.KilledWorker("run_range-abc", last, 3)

    r = split(WALKS[0], 0, 3000, 1000)[1]
    with pytest.raises(ClusterError, match=r"^paths 1000 to 1999 of the walk of 'scene' killed 4 "
                                           r"Dask workers \(the last tcp://10.0.0.5:4000\); see"):
        cluster._result(Killed(), r, distributed)
