"""How the error estimate of :mod:`layersim.plan.accuracy` compares with measured errors, on the
ladders written by ``benchmarks/accuracy/convergence_tables.py`` (the data its factor is chosen on).

A case is a scene solved at a rung ``s`` of the ladder that has the two coarser rungs ``s / sqrt 2``
and ``s / 2`` and a reference at least twice as fine (the finest rung). For each case it
measures the error of the rung against the reference (relative L2 of bin energies, worst of 0, 30,
60 and 80 degrees: what the estimate estimates) and the distances ``d1``, ``d2`` to the two
coarser rungs, and prints

* each case: measured error, the adopted estimate
  (:func:`layersim.plan.accuracy.estimate_from_distances`), their ratio and ``d2 / d1``
  (``1 + 2^(p/2)`` where the error fell like ``s^-p``);
* for candidate estimates (the adopted one, ``d1`` alone, with ``d2`` as a guard against an
  accidental agreement, a Richardson-type weighting, ...): how often each lies above the error
  (conservative) and within 3 times it, worst-angle and per angle;
* a simulated solve to tolerance on each ladder with the adopted estimate: the rung accepted,
  its measured error against ``tol``, and the time of the rungs climbed relative to the
  planner's default solve.

Usage: python benchmarks/accuracy/estimator_study.py
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from layersim.plan import accuracy

DATA = Path(__file__).parent / "convergence"

#: Candidate estimates from the distances d1 (to s / sqrt 2) and d2 (to s / 2).
CANDIDATES = {
    "adopted": lambda d1, d2: accuracy.estimate_from_distances([d1, d2]),
    "1.5 d1": lambda d1, d2: 1.5 * d1,
    "d1": lambda d1, d2: d1,
    "2 d1": lambda d1, d2: 2 * d1,
    "1.5 max(d1, d2/3)": lambda d1, d2: 1.5 * np.maximum(d1, d2 / 3),
    "1.5 max(d1, d2/2)": lambda d1, d2: 1.5 * np.maximum(d1, d2 / 2),
    "1.5 max(d1, d2/8)": lambda d1, d2: 1.5 * np.maximum(d1, d2 / 8),
    "1.5 sqrt(d1 d2)": lambda d1, d2: 1.5 * np.sqrt(d1 * d2),
    # e = d1 / (2^(p/2) - 1) with 2^(p/2) = d2 / d1 - 1, the order p clamped to [1, 4]
    "1.5 Richardson": lambda d1, d2: 1.5 * d1 / (np.clip(d2 / np.maximum(d1, 1e-300) - 1,
                                                           math.sqrt(2), 4) - 1),
}


def ladders():
    """(scene, scales, n, md, seconds, tables (float64)) per file."""
    for path in sorted(DATA.glob("*.npz")):
        z = np.load(path)
        yield (path.stem, z["scales"], z["n"], z["md"], z["seconds"],
               z["tables"].astype(np.float64))


def cases():
    """(scene, n, md, measured, d1, d2) per case; each of the last three per angle."""
    for name, scales, ns, mds, _, tables in ladders():
        ref = len(scales) - 1
        for k in range(2, len(scales)):
            if not (np.isclose(scales[k - 1] * math.sqrt(2), scales[k])
                    and np.isclose(scales[k - 2] * 2, scales[k])
                    and scales[ref] >= 2 * scales[k] - 1e-9):
                continue
            yield (name, int(ns[k]), int(mds[k]),
                   accuracy.relative_errors(tables[k], tables[ref]),
                   accuracy.relative_errors(tables[k], tables[k - 1]),
                   accuracy.relative_errors(tables[k], tables[k - 2]))


def simulate(tol: float):
    """Solve to ``tol`` on each ladder: (scene, accepted scale or None, measured error or
    None, time of the rungs climbed / time of the default rung)."""
    for name, scales, _, _, seconds, tables in ladders():
        default = seconds[int(np.argmin(abs(scales - 1.0)))]
        spent = seconds[0]
        for k in range(1, len(scales)):
            spent += seconds[k]
            est = accuracy.estimate_from_distances(
                [accuracy.relative_errors(tables[k], tables[j]) for j in (k - 1, k - 2) if j >= 0]
            ).max()
            if est <= tol:
                measured = None
                if scales[-1] >= 2 * scales[k] - 1e-9:
                    measured = accuracy.relative_errors(tables[k], tables[-1]).max()
                yield name, scales[k], measured, spent / default
                break
        else:
            yield name, None, None, spent / default


def main() -> None:
    rows = list(cases())
    print("# python benchmarks/accuracy/estimator_study.py   (shared 2-core CI VM, beside other "
          "jobs: times are wall times under load; data: "
          "python benchmarks/accuracy/convergence_tables.py)")
    weights = ", ".join(f"{w:g} d{i + 1}" for i, (_, w) in enumerate(accuracy.COMPANIONS))
    print(f"# {len(rows)} cases on {len(list(DATA.glob('*.npz')))} ladders; adopted estimate "
          f"{accuracy.SAFETY} x max({weights}) (d1, d2: distances to the companions at n, md "
          f"over sqrt 2 and over 2), {accuracy.SINGLE} x {accuracy.SAFETY} x d1 with one")
    print(f"{'scene':22s} {'n':>5s} {'md':>5s} {'measured':>9s} {'estimate':>9s} {'ratio':>6s}"
          f" {'d2/d1':>6s}")
    for name, n, md, meas, d1, d2 in rows:
        est = accuracy.estimate_from_distances([d1, d2]).max()
        print(f"{name:22s} {n:5d} {md:5d} {meas.max():9.2e} {est:9.2e} "
              f"{est / meas.max():6.2f} {d2.max() / d1.max():6.2f}")
    print("\n# candidate estimates: % of cases conservative (estimate >= measured) and within "
          "3x above it; worst angle | each angle a case")
    for label, f in CANDIDATES.items():
        worst = np.array([f(d1.max(), d2.max()) / meas.max() for _, _, _, meas, d1, d2 in rows])
        each = np.concatenate([f(d1, d2) / meas for _, _, _, meas, d1, d2 in rows])
        print(f"{label:20s} worst: {100 * np.mean(worst >= 1):5.1f} % cons, "
              f"{100 * np.mean((worst >= 1) & (worst <= 3)):5.1f} % within 3x, median ratio "
              f"{np.median(worst):5.2f} | per angle: {100 * np.mean(each >= 1):5.1f} % cons, "
              f"{100 * np.mean((each >= 1) & (each <= 3)):5.1f} % within 3x")
    print("\n# simulated solves to tol with the adopted estimate: accepted scale of the plan's "
          "n and md (measured error; ! over tol), time of the rungs climbed / default solve")
    for tol in (1e-2, 3e-3, 1e-3):
        parts, over, measured, times = [], 0, 0, []
        for name, scale, meas, cost in simulate(tol):
            if scale is None:
                parts.append(f"{name} -")
                continue
            times.append(cost)
            text = f"{name} {scale:.2f}"
            if meas is not None:
                measured += 1
                over += meas > tol
                text += f" ({meas:.1e}{'!' if meas > tol else ''})"
            parts.append(text)
        print(f"tol {tol:g}: {over} of {measured} measured over tol; time median "
              f"{np.median(times):.2f} x default; " + "; ".join(parts))


if __name__ == "__main__":
    main()
