"""Where the peak resident memory of a coupled-mode (anisotropic) solve goes, phase by phase.

A sampling thread reads the resident set size (``/proc/self/statm``, Linux) every
``INTERVAL`` seconds; the solver's phases are wrapped (projection of each layer and its
assembly, each adding step: the products, the banded solve and within it the dense block rows,
the block LU and the substitutions, the output products, the pruning), and the peak RSS seen
while each phase runs is printed, absolute and above the baseline of a process that has
imported numpy, scipy, Warp and layersim and warmed up Warp's kernels.

Usage::

    python benchmarks/speed/memory_phases.py 7            # Table 2 row 7 (table2.py)
    python benchmarks/speed/memory_phases.py 6 --default  # row 6 at the planner's discretisation
    python benchmarks/speed/memory_phases.py path/to/scene.toml
"""

from __future__ import annotations

import os
import sys
import threading
import time

INTERVAL = 0.005
_PAGE = os.sysconf("SC_PAGE_SIZE")


def rss_bytes() -> int:
    """Current resident set size of this process (bytes)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * _PAGE


class Sampler:
    """Background RSS sampler with a stack of named phases: every phase records the largest
    RSS sampled while it (or a phase inside it) was running."""

    def __init__(self):
        self.stack: list = []
        self.peaks: dict = {}
        self.order: list = []
        self.peak = 0
        self.t0 = time.perf_counter()
        self._stop = False
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _note(self, value: int) -> None:
        self.peak = max(self.peak, value)
        for name in self.stack:
            self.peaks[name] = max(self.peaks.get(name, 0), value)

    def _run(self) -> None:
        while not self._stop:
            self._note(rss_bytes())
            time.sleep(INTERVAL)

    def enter(self, name: str) -> str:
        k, base = 1, name
        while name in self.peaks:
            k += 1
            name = f"{base} #{k}"
        self.peaks[name] = rss_bytes()
        self.order.append((name, len(self.stack), rss_bytes()))
        # progress on stderr, for runs that may be stopped before the summary
        print(f"[{time.perf_counter() - self.t0:7.1f} s] {name.strip()}: RSS "
              f"{rss_bytes() / 2**20:.0f} MiB", file=sys.stderr, flush=True)
        self.stack.append(name)
        return name

    def leave(self, name: str) -> None:
        self._note(rss_bytes())
        self.stack.remove(name)
        self.order.append((name + " (end)", len(self.stack), rss_bytes()))

    def wrap(self, module, attr: str, label: str | None = None) -> None:
        fn = getattr(module, attr)
        sampler = self

        def wrapped(*args, **kwargs):
            name = sampler.enter(label or attr)
            try:
                return fn(*args, **kwargs)
            finally:
                sampler.leave(name)

        setattr(module, attr, wrapped)

    def stop(self) -> None:
        self._stop = True
        self._thread.join()


def main(argv) -> int:
    import layersim
    from layersim import solver
    from layersim.aniso import adding, banded, operator, reciprocity
    from layersim.config import settings
    from layersim.ingredients import aniso_microfacet as am
    from layersim.outofcore import memory
    memory.cap_arenas(settings().malloc_arenas)     # this script owns its process
    sys.path.insert(0, os.path.dirname(__file__))
    import table2

    layersim.solve(layersim.Scene.from_dict({"layer": [
        {"kind": "conductor", "ior": [0.2, 3.0], "roughness": [0.3, 0.2]}],
        "discretization": {"n": 16, "md": 4}}))
    base = rss_bytes()
    if argv[0].endswith(".toml"):
        scene = layersim.Scene.from_toml(argv[0])
    else:
        k = int(argv[0])
        top, bottom = table2.ROWS[k - 1][:2]
        d = {"layer": [{"kind": "dielectric", "ior": 1.5, "roughness": list(top)},
                       {"kind": "conductor", "ior": table2.GOLD, "roughness": list(bottom)}]}
        if k in table2.OVERRIDES and "--default" not in argv:
            d["discretization"] = dict(table2.OVERRIDES[k])
        scene = layersim.Scene.from_dict(d)
    s = Sampler()
    s.wrap(solver, "_layer_operator", "layer operator")
    s.wrap(am, "_project_block", "  project block")
    s.wrap(am, "from_parts", "  assemble block")
    s.wrap(am, "reciprocal_image", "  reciprocal image")
    s.wrap(adding, "add", "adding step")
    s.wrap(adding, "banded_solve", "  banded solve")
    s.wrap(banded, "_block_rows", "    dense block rows")
    s.wrap(banded.BlockBandedLU, "__init__", "    block LU")
    s.wrap(banded, "_solve_groups", "    substitutions")
    s.wrap(banded, "_residual", "    residual check")
    s.wrap(banded, "from_parts", "    assemble solution")
    s.wrap(adding, "_sum", "  sum")
    s.wrap(operator, "reciprocal_image", "    reciprocal image")
    s.wrap(reciprocity, "sum_pieces", "    sum in pieces")
    s.wrap(adding.AnisoOperator, "pruned", "  pruned (result)")
    s.wrap(adding, "pruned_product", "  product (pruned)")
    s.wrap(adding, "prune", "  prune (sums)")
    s.wrap(adding, "reciprocal_prune", "  reciprocal prune (result)")
    from layersim import plan as lplan
    s.wrap(solver, "make_plan", "plan")
    t0 = time.perf_counter()
    bsdf = layersim.solve(scene)
    t = time.perf_counter() - t0
    s.stop()
    mib = 2.0 ** -20
    print(f"baseline RSS after imports and warm-up: {base * mib:.0f} MiB")
    print(f"solve {t:.1f} s, n={bsdf.info['n']} md={bsdf.info['md']} ms={bsdf.info['ms']}, "
          f"plan estimate {bsdf.plan.memory_bytes * mib:.0f} MiB, result "
          f"{bsdf.info['memory_bytes'] * mib:.1f} MiB")
    print(f"peak RSS {s.peak * mib:.0f} MiB ({(s.peak - base) * mib:.0f} above baseline)")
    print(f"{'phase':<28} {'RSS at start':>12} {'peak':>8} {'peak-base':>10}  (MiB)")
    for name, depth, at in s.order:
        if name.endswith("(end)"):
            continue
        p = s.peaks[name]
        print(f"{name:<28} {at * mib:12.0f} {p * mib:8.0f} {(p - base) * mib:10.0f}")
    del lplan
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
