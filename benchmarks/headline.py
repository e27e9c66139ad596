"""Regenerate the outputs behind the README's headline results, each stamped with where, when and
from what tree it was made (not a test).

Each study runs as its own process (``python benchmarks/...``, or ``layersim bench``), its standard
output and error go to its committed output file, and the file starts with a header of comment
lines: the command, the machine (CPU model, cores, memory; the GPU where one is used), the date,
the commit of this tree (with ``+ uncommitted changes`` when the tree differs from it), the load
average before and after, and the wall time. A study that fails keeps its previous output and is
reported at the end.

Usage::

    python benchmarks/headline.py --list
    python benchmarks/headline.py cpu [NAME ...]      # the studies that run on this machine's CPU
    python benchmarks/headline.py gpu [NAME ...]      # the studies that need a CUDA GPU
"""

from __future__ import annotations

import argparse
import os
import platform
import shlex
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: name -> (where it runs, command after ``python``, output file relative to the root).
STUDIES = {
    "table2": ("cpu", "benchmarks/speed/table2.py", "benchmarks/speed/table2.txt"),
    "smooth_vs_mc": ("cpu", "benchmarks/features/smooth_vs_mc.py 1e7 warp-cpu",
                     "benchmarks/features/smooth_vs_mc.txt"),
    "forward_media": ("cpu", "benchmarks/features/forward_media.py",
                      "benchmarks/features/forward_media.txt"),
    "near_specular": ("cpu", "benchmarks/features/near_specular.py 1e7 warp-cpu coats",
                      "benchmarks/features/near_specular.txt"),
    "near_specular_conductors": ("cpu", "benchmarks/features/near_specular.py 1e7 warp-cpu "
                                        "conductors",
                                 "benchmarks/features/near_specular_conductors.txt"),
    "brushed_coats": ("cpu", "benchmarks/features/brushed_coats.py 1e7 warp-cpu",
                      "benchmarks/features/brushed_coats.txt"),
    "brushed_coats_control": ("cpu", "benchmarks/features/brushed_coats.py 1e7 warp-cpu control",
                              "benchmarks/features/brushed_coats_control.txt"),
    "energy_compensation": ("cpu", "benchmarks/features/energy_compensation.py 1e7 warp-cpu",
                            "benchmarks/features/energy_compensation.txt"),
    "tabulated_ndf": ("cpu", "benchmarks/features/tabulated_ndf.py",
                      "benchmarks/features/tabulated_ndf.txt"),
    "accuracy": ("cpu", "benchmarks/accuracy/accuracy.py vandehulst_slab dusty_gold coated_gold "
                        "coated_hg_diffuse ggx_coated_gold",
                 "benchmarks/accuracy/accuracy.txt"),
    "plan_estimates": ("cpu", "benchmarks/speed/plan_estimates.py",
                       "benchmarks/speed/plan_estimates.txt"),
    "mitsuba_plugin": ("cpu", "benchmarks/features/mitsuba_plugin.py",
                       "benchmarks/features/mitsuba_plugin.txt"),
    "eval_positivity": ("cpu", "benchmarks/features/eval_positivity.py",
                        "benchmarks/features/eval_positivity.txt"),
    "gpu_tabulated_vs_analytic": ("gpu", "benchmarks/features/gpu_tabulated_vs_analytic.py 1e8 "
                                         "warp-cuda",
                                  "benchmarks/features/gpu_tabulated_vs_analytic.txt"),
    "plans_vs_gpu_mc": ("gpu", "benchmarks/accuracy/plans_vs_gpu_mc.py 1e9 warp-cuda "
                               "coated_hg_diffuse ggx_coated_gold vandehulst_slab dusty_gold "
                               "coated_gold", "benchmarks/accuracy/plans_vs_gpu_mc.txt"),
    "plans_vs_gpu_mc_coupled": ("gpu", "benchmarks/accuracy/plans_vs_gpu_mc.py 1e9 warp-cuda "
                                       "gold_under_hg additive_validation",
                                "benchmarks/accuracy/plans_vs_gpu_mc_coupled.txt"),
    "projection_paths_gpu": ("gpu", "benchmarks/speed/projection_paths.py --devices cpu cuda "
                                    "--samples 1024 4096 16384 --repeat 3",
                             "benchmarks/reports/gpu/projection_paths_gpu.txt"),
}


def _run(cmd: list[str], **kw) -> str:
    try:
        return subprocess.run(cmd, capture_output=True, text=True, timeout=20, **kw).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def machine(gpu: bool) -> str:
    """CPU model, cores and memory (and the GPU) of this machine, one line."""
    cpu = next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                if ln.startswith("model name")), platform.processor() or "cpu") \
        if Path("/proc/cpuinfo").exists() else platform.processor()
    mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    line = f"{cpu}, {os.cpu_count()} cores, {mem:.0f} GiB, Python {platform.python_version()}"
    if gpu:
        # one line per GPU from nvidia-smi: a host of identical GPUs is named once with its count
        gpus = (_run(["nvidia-smi", "--query-gpu=name,driver_version",
                      "--format=csv,noheader"]) or "").splitlines()
        names = sorted(set(gpus), key=gpus.index)
        line += "; GPU " + ("none found" if not gpus else "; ".join(
            (f"{gpus.count(g)}x " if gpus.count(g) > 1 else "") + g for g in names))
    return line


#: What the measured code is: a change elsewhere (the outputs this script writes) is no change of it.
CODE = ["layersim", "kernels", "montecarlo", "pyproject.toml", ":(glob)benchmarks/**/*.py"]


def commit() -> str:
    """The commit of this tree, marked where its code differs from it."""
    head = _run(["git", "-C", str(ROOT), "log", "-1", "--format=%h %cs"])
    if not head:
        return "unknown (no git metadata)"
    dirty = _run(["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no",
                  "--", *CODE])
    return head + (" + uncommitted changes" if dirty else "")


def run_study(name: str, tree: str | None = None) -> bool:
    where, command, output = STUDIES[name]
    argv = [sys.executable] + shlex.split(command)
    out = ROOT / output
    tmp = out.with_name(out.name + ".partial")
    load0, t0 = os.getloadavg()[0], time.perf_counter()
    print(f"{name}: python {command} > {output}", flush=True)
    with open(tmp, "w") as f:
        proc = subprocess.run(argv, stdout=f, stderr=subprocess.STDOUT, cwd=ROOT,
                              env=dict(os.environ, PYTHONUNBUFFERED="1"))
    seconds, load1 = time.perf_counter() - t0, os.getloadavg()[0]
    if proc.returncode != 0:
        print(f"  failed (status {proc.returncode}); its log is {tmp}", flush=True)
        return False
    header = [f"# command: python {command}",
              f"# machine: {machine(where == 'gpu')}",
              f"# date: {time.strftime('%Y-%m-%d %H:%M')}; commit: {tree or commit()}",
              f"# load average (1 min): {load0:.1f} before, {load1:.1f} after; wall time "
              f"{seconds:.0f} s (benchmarks/headline.py)"]
    out.write_text("\n".join(header) + "\n" + tmp.read_text())
    tmp.unlink()
    print(f"  done in {seconds:.0f} s", flush=True)
    return True


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("where", nargs="?", choices=["cpu", "gpu"])
    ap.add_argument("names", nargs="*")
    ap.add_argument("--list", action="store_true")
    ap.add_argument("--commit", help="the commit of this tree, where its git metadata is not "
                                     "this tree's (a copy sent to another machine)")
    args = ap.parse_args()
    if args.list or args.where is None:
        for name, (where, command, output) in STUDIES.items():
            print(f"{name:28} {where}  python {command}  > {output}")
        return 0
    names = args.names or [n for n, s in STUDIES.items() if s[0] == args.where]
    unknown = [n for n in names if n not in STUDIES]
    if unknown:
        ap.error(f"unknown study {unknown[0]!r}; --list shows them")
    failed = [n for n in names if not run_study(n, args.commit)]
    if failed:
        print("failed: " + ", ".join(failed))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
