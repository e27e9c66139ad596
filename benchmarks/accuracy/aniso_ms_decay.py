"""How fast the truncation error of the coupled modes falls near the planner's ``ms``, and what
that means for companions of the error estimate (``layersim.plan.accuracy.scaled_ms``).

For Beckmann conductors (gold) and dielectrics (eta 1.5) of roughness (0.1, 0.1 r), r = 2, 3,
4, 6, it computes the relative (cosine-weighted) L2 error ``err(m)`` of keeping ``|s| <= m``
from the coefficients of one projection at a generous ``ms`` (the method of
``benchmarks/accuracy/ms_study.py``, n = 64, md = 128), and prints ``err`` at the planner's ``ms``
(``layersim.aniso.plan.ms_for_layer``) and two modes either side, the decay
``K = ms ln(err(ms - 1) / err(ms))`` (``err(m) ~ exp(-K m / ms)``), and, where the truncation
is the whole error, the ratio estimate / error that the estimate of ``layersim.plan.accuracy``
(``SAFETY`` x the larger of the distance to the first companion and the weighted distance to the
second) gives with companions at ``ms sqrt(scale)`` (what ``scaled_ms`` does) and at
``ms scale``. The distance to a companion at ``m`` is taken as ``err(m) - err(ms)`` (errors
of the same sign, the smallest distance).

Usage: python benchmarks/accuracy/aniso_ms_decay.py
(output: benchmarks/accuracy/aniso_ms_decay.txt)
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))

import ms_study  # noqa: E402  (the truncation errors of benchmarks/accuracy/ms_study.py)

from layersim.plan import accuracy  # noqa: E402
from layersim.aniso.plan import ms_for_layer  # noqa: E402
from layersim.operators.operator import Grid  # noqa: E402

RATIOS = (2.0, 3.0, 4.0, 6.0)


def ratio(err, ms: int, companions: list) -> float:
    """Estimate / error when the truncation at ``ms`` is the error (module docstring)."""
    d = [(err[m] - err[ms]) * w for m, (_, w) in zip(companions, accuracy.COMPANIONS)]
    return accuracy.SAFETY * max(d) / err[ms]


def main() -> None:
    grid = Grid.make("gauss-lobatto", ms_study.N)
    print(f"# n = {ms_study.N}, md = {ms_study.MD}; err(m): cosine-weighted relative L2 error "
          "of keeping |s| <= m; K = ms ln(err(ms-1) / err(ms))")
    print(f"# {'layer':20s} {'r':>3s} {'ms':>3s} | {'err(ms-2 .. ms+2)':39s} |    K | "
          f"{'ms sqrt(scale): est/err':24s} | {'ms scale: est/err':17s} | seconds")
    for r in RATIOS:
        for label, layer in ms_study.layers(0.1, r)[::2]:        # Beckmann conductor, dielectric
            t0 = time.perf_counter()
            err, _ = ms_study.truncation_errors(grid, layer, int(4 * r + 8))
            err = err["cos"]
            ms = ms_for_layer(layer)
            K = ms * math.log(err[ms - 1] / err[ms])
            root = [accuracy.scaled_ms(ms, s) for s, _ in accuracy.COMPANIONS]
            prop = [max(1, round(ms * s)) for s, _ in accuracy.COMPANIONS]
            print(f"{label:22s} {r:3g} {ms:3d} | " + " ".join(f"{x:.1e}" for x in err[ms - 2:ms + 3])
                  + f" | {K:4.1f} | {str(root):9s} {ratio(err, ms, root):14.1f} "
                  f"| {str(prop):9s} {ratio(err, ms, prop):7.1f} | {time.perf_counter() - t0:7.1f}",
                  flush=True)


if __name__ == "__main__":
    main()
