"""Subtracting equations (Zeltner & Jakob 2018 eq. (13)-(16)): what the stack determines of the
recovered layer, and recovery errors without and with noise.

For two-layer stacks solved from scenes (the known layer and the true unknown one solved with
``like=stack``), the known layer is removed from the stack and the result compared with the
true layer: relative L2 error in the energy basis ``sqrt(w mu)`` over all orders (coupled slots)
and blocks,

- ``err det``: over the directions the result declares determined
  (``info["subtract"]["determined"]``: ``mu >= mu_min`` on the side facing the known layer);
- ``err reach``: over the directions reached through the known layer (``mu >= mu_reached``).

With noise, every stored operator entry of the stack is multiplied by ``1 + level N(0, 1)``
(:func:`layersim.stacking.subtract.with_noise`, seed 3) and eps is chosen automatically; ``best`` is
the smallest ``err reach`` (same directions) over eps on a half-decade grid refined by quarter
decades around its best, and ``ratio`` the automatic error over it. ``neg det`` is the depth of
negative lobes over the determined directions (Fejer means of the low orders, relative to the
peak; 0 for the true layers, and 0 where no direction is declared).

The last part measures, for the rough coating over a rough conductor, why the stack does not
determine the base to 1e-3 anywhere: the share of the stack's signal ``Z = R2 (I - Rb1 R2)^-1``
(the part of eq. (13) the data give) that passes through directions below a ``mu`` inside the
coating, and the error over near-normal directions against a fixed eps.

The third part compares both ways on the noise-free coatings over a conductor or a diffuse
base and dust over gold, isotropic and anisotropic: the plain subtraction and the model-based
one (:func:`layersim.subtract_model`: the template is the stack with the known layer fixed and
the base's fields free, fitted by exact transport on the stack's plan, the base then solved
alone). Each base's ``eval`` is compared with the hidden base solved alone on the same plan,
relative L2 at 4000 random pairs of directions with both cosines above 0.2 in the medium above
the base, and split where both directions are inside the escape cone of the known layer's
medium (``mu > sqrt(1 - 1 / eta^2)``) or at least one is outside it.

Usage (machine: shared 2-core CI VM)::

    python benchmarks/features/subtract_study.py > benchmarks/features/subtract_study.txt
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sps

sys.path[:0] = [str(Path(__file__).resolve().parent.parent)]
from headline import commit, machine  # noqa: E402

import layersim  # noqa: E402
from layersim.stacking.determined import error_by_cut  # noqa: E402
from layersim.stacking.subtract import with_noise  # noqa: E402

COND = {"kind": "conductor", "ior": [0.2, 3.9]}
GOLD = {"kind": "conductor", "ior": [0.143552, 3.98397]}
DUST = {"kind": "medium", "albedo": 0.9, "g": 0.6, "tau": 0.3}
NOISE = (0.0, 1e-6, 1e-3, 1e-2)


def solve(layers, disc, top_ior=1.0, like=None):
    d = {"layer": layers, "stack": {"top_ior": top_ior}}
    return layersim.solve(layersim.Scene.from_dict(d), like=like).operators[0]


def error_over(got, truth, mu_min, side="top"):
    """Relative L2 error (energy basis, all orders or coupled slots and blocks) over the
    directions with mu >= mu_min on ``side`` (all directions on the other side)."""
    if got.representation == truth.representation == "isotropic":
        k = int(np.searchsorted(truth.grid.mu, mu_min))
        return float(error_by_cut(got, truth, side)[k])
    a, b = got.as_coupled(), truth.as_coupled()
    keep = np.tile(b.grid.mu >= mu_min, b.slots).astype(float)
    w = np.tile(np.sqrt(b.grid.flux_weight), b.slots)
    rows, cols = {"top": ("Rt", "Tbt"), "bottom": ("Rb", "Ttb")}[side], \
        {"top": ("Rt", "Ttb"), "bottom": ("Rb", "Tbt")}[side]
    num = den = 0.0
    for name, blk in b.blocks.items():
        if blk is None:
            continue
        left = sps.diags(w * (keep if name in rows else 1.0))
        right = sps.diags((keep if name in cols else 1.0) / w)
        num += (left @ (a.blocks[name] - blk) @ right).power(2).sum()
        den += (left @ blk @ right).power(2).sum()
    return float(np.sqrt(num / den)) if den > 0 else float("nan")


def cases():
    """(label, known layers, unknown layers, discretisation or None for the plan's, index
    between them, noise levels)."""
    out = []
    for alpha, levels in ((0.05, (0.0,)), (0.1, NOISE), (0.2, NOISE), (0.3, NOISE)):
        coat = {"kind": "dielectric", "ior": 1.5, "roughness": alpha}
        out.append((f"coat {alpha} / conductor 0.3", [coat], [dict(COND, roughness=0.3)],
                    None, 1.5, levels))
    for alpha in (0.1, 0.3):
        coat = {"kind": "dielectric", "ior": 1.5, "roughness": alpha}
        out.append((f"coat {alpha} / diffuse 0.8", [coat],
                    [{"kind": "diffuse", "albedo": 0.8}], None, 1.5, NOISE))
    out.append(("dust / gold 0.15", [DUST], [dict(GOLD, roughness=0.15)],
                {"n": 96, "md": 120}, 1.0, NOISE))
    aniso = {"n": 48, "md": 24}
    out.append(("aniso coat (.2,.3) / cond (.3,.2)",
                [{"kind": "dielectric", "ior": 1.5, "roughness": [0.2, 0.3]}],
                [dict(COND, roughness=[0.3, 0.2])], aniso, 1.5, (0.0, 1e-2)))
    out.append(("aniso dust / gold (.15,.3)", [DUST], [dict(GOLD, roughness=[0.15, 0.3])],
                aniso, 1.0, (0.0, 1e-2)))
    return out


def best_eps(data, known, truth, mu):
    """Smallest error over the reached directions ``mu`` on a refined log grid of eps."""
    seen = {}

    def err(le):
        if le not in seen:
            try:
                got = layersim.subtract(data, known, side="top", eps=10.0 ** le)
                seen[le] = error_over(got, truth, mu)
            except layersim.InfeasibleError:
                seen[le] = float("inf")
        return seen[le]

    best = min(np.arange(-4.0, 0.01, 0.5), key=err)
    best = min([best - 0.25, best, best + 0.25], key=err)
    return 10.0 ** best, seen[best]


def study() -> None:
    print(f"{'case':>39} | {'noise':>5} | {'eps':>7} {'method':>16} | {'theta det':>9} "
          f"{'est':>7} {'err det':>7} | {'theta reach':>11} {'err reach':>9} | "
          f"{'neg det':>7} | {'best eps':>8} {'best':>7} {'ratio':>5} | time")
    for label, top, bottom, disc, ior, levels in cases():
        like = layersim.solve(layersim.Scene.from_dict(
            {"layer": top + bottom} | ({"discretization": disc} if disc else {})))
        stack = like.operators[0]
        known = solve(top, disc, like=like)
        truth = solve(bottom, disc, top_ior=ior, like=like)
        label = f"{label} n{stack.grid.n}"
        for level in levels:
            data = stack if level == 0 else with_noise(stack, level, 3)
            t0 = time.perf_counter()
            try:
                got = layersim.subtract(data, known, side="top")
            except layersim.InfeasibleError as exc:
                print(f"{label:>39} | {level:5.0e} | refused: {exc}", flush=True)
                continue
            dt = time.perf_counter() - t0
            info = got.info["subtract"]
            d = info["determined"]
            det = "none" if d["mu_min"] is None else f"<{d['theta_max_deg']:.1f}"
            reach = "none" if d["mu_reached"] is None else f"<{d['theta_reached_deg']:.1f}"
            e_det = error_over(got, truth, d["mu_min"]) if d["mu_min"] is not None else None
            e_reach = error_over(got, truth, d["mu_reached"])
            best = ratio = "-"
            if level >= 1e-2:
                be, bv = best_eps(data, known, truth, d["mu_reached"])
                best, ratio = f"{be:8.2g} {bv:7.2g}", f"{e_reach / bv:5.2f}"
            else:
                best = f"{'-':>8} {'-':>7}"
            print(f"{label:>39} | {level:5.0e} | {info['eps']:7.2g} {info['method'][:16]:>16} | "
                  f"{det:>9} {d['error']:7.1e} {'-' if e_det is None else f'{e_det:7.1e}':>7} | "
                  f"{reach:>11} {e_reach:9.1e} | {info['negative_lobes_determined']:7.1e} | "
                  f"{best} {ratio:>5} | {dt:.1f} s", flush=True)


def coupling() -> None:
    """Why the rough coating over a rough conductor is not determined (module docstring)."""
    from layersim.stacking.determined import visibility
    disc = {"n": 96, "md": 96}
    coat = {"kind": "dielectric", "ior": 1.5, "roughness": 0.2}
    base = dict(COND, roughness=0.3)
    stack = layersim.solve(layersim.Scene.from_dict({"layer": [coat, base],
                                                     "discretization": disc}))
    known = solve([coat], disc, like=stack)
    truth = solve([base], disc, top_ior=1.5, like=stack)
    grid = known.grid
    mu, h = grid.mu, grid.h
    sw = np.sqrt(grid.flux_weight)
    I = np.eye(h)
    hat = [sw[:, None] * truth.block("Rt", l).toarray() / sw[None, :] for l in range(truth.m)]
    rb1 = [sw[:, None] * known.block("Rb", l).toarray() / sw[None, :] for l in range(truth.m)]
    cuts = (0.95, 0.9, 0.8)
    print("\nrough coating (1.5, alpha 0.2) over a rough conductor (alpha 0.3), n 96, md 96: "
          "share of the stack's signal Z = R2 (I - Rb1 R2)^-1 over the directions mu > "
          + ", ".join(f"{c}" for c in cuts) + " inside the coating that passes through "
          "directions mu < mu_h (relative L2, all orders)")
    vis = visibility(known, "top", 1e-6)
    for mu_h in (0.745, 0.5, 0.4, 0.3):
        num = np.zeros(len(cuts))
        den = np.zeros(len(cuts))
        hidden = mu < mu_h
        for R, B in zip(hat, rb1):
            Z = R @ np.linalg.inv(I - B @ R)
            Rv = R.copy()
            Rv[hidden, :] = 0
            Rv[:, hidden] = 0
            Zv = Rv @ np.linalg.inv(I - B @ Rv)
            for j, c in enumerate(cuts):
                s = mu > c
                num[j] += np.sum((Z - Zv)[np.ix_(s, s)] ** 2)
                den[j] += np.sum(Z[np.ix_(s, s)] ** 2)
        reach = float(vis[np.searchsorted(mu, mu_h)])
        print(f"  mu_h {mu_h:5.3f} (visibility at eps 1e-6 there {reach:.2f}): "
              + ", ".join(f"{np.sqrt(n / d):.1e}" for n, d in zip(num, den)))
    print("error of the recovered base over mu > " + ", ".join(f"{c}" for c in cuts)
          + " against eps (no noise):")
    for eps in (1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2):
        got = layersim.subtract(stack.operators[0], known, side="top", eps=eps)
        print(f"  eps {eps:7.0e}: " + ", ".join(f"{error_over(got, truth, c):.1e}"
                                              for c in cuts))


#: Free fields of each base kind in the model-based templates: bounds of a wide prior.
FREE = {"conductor": {"ior": [{"fit": [0.05, 2.0]}, {"fit": [1.0, 6.0]}]},
        "diffuse": {"albedo": {"fit": [0.05, 0.99]}}}
#: Both cosines above this in the base's medium for the eval comparison.
MU_EVAL = 0.2


def _free(layer: dict) -> dict:
    """The base ``layer`` with its fields free (roughness per axis where anisotropic)."""
    out = dict(layer, **FREE[layer["kind"]])
    if "roughness" in layer:
        r = layer["roughness"]
        out["roughness"] = ([{"fit": [0.05, 0.6]} for _ in r] if isinstance(r, list)
                            else {"fit": [0.05, 0.6]})
    return out


def eval_errors(got, truth, eta: float, count: int = 4000) -> tuple:
    """Relative L2 errors of ``got.eval`` against ``truth.eval``: over pairs with both cosines
    above MU_EVAL, those with both inside the escape cone of a medium of index ``eta`` and
    those with one or both outside it (nan where there is no such pair)."""
    rng = np.random.default_rng(0)
    mu = rng.uniform(MU_EVAL, 1.0, (2, count))
    phi = rng.uniform(0.0, 2 * np.pi, (2, count))
    w = np.stack([np.sqrt(1 - mu * mu) * np.cos(phi), np.sqrt(1 - mu * mu) * np.sin(phi), mu],
                 axis=-1)
    a = np.asarray(got.eval(w[0], w[1])).reshape(count, -1)
    b = np.asarray(truth.eval(w[0], w[1])).reshape(count, -1)
    inside = np.all(mu > np.sqrt(max(0.0, 1.0 - 1.0 / eta ** 2)), axis=0)

    def rel(sel):
        return (float(np.linalg.norm(a[sel] - b[sel]) / np.linalg.norm(b[sel]))
                if sel.any() else float("nan"))
    return rel(np.ones(count, bool)), rel(inside), rel(~inside)


def both_ways() -> None:
    """Plain against model-based subtraction, noise-free (module docstring)."""
    print(f"\nplain against model-based subtraction, noise-free: base eval error (relative L2) "
          f"with both cosines above {MU_EVAL}, both directions inside / one or both outside the "
          "escape cone; time of each; the fitted values")
    print(f"{'case':>39} | {'way':>5} | {'mu > 0.2':>8} {'inside':>8} {'outside':>8} | "
          f"{'time':>6} | values")
    for label, top, bottom, disc, ior, _ in cases():
        if label.startswith("coat 0.05"):
            continue        # n 390: the plain way alone takes 1.5 min; the coats below show it
        like = layersim.solve(layersim.Scene.from_dict(
            {"layer": top + bottom} | ({"discretization": disc} if disc else {})))
        known = layersim.solve(layersim.Scene.from_dict({"layer": top}), like=like)
        truth = layersim.solve(layersim.Scene.from_dict(
            {"layer": bottom, "stack": {"top_ior": ior}}), like=like)
        label = f"{label} n{like.operators[0].grid.n}"
        t0 = time.perf_counter()
        plain = layersim.subtract(like, known, side="top")
        t1 = time.perf_counter()
        model = layersim.subtract_model(like, {"layer": top + [_free(b) for b in bottom]},
                                        side="top", plain=False)
        t2 = time.perf_counter()
        values = ", ".join(f"{k.split('.', 1)[1]} {v:.4g}" for k, v in model.fit.params.items())
        for way, got, dt, extra in (("plain", plain, t1 - t0, ""),
                                    ("model", model.base, t2 - t1, values)):
            e = eval_errors(got, truth, ior)
            print(f"{label:>39} | {way:>5} | " + " ".join(f"{x:8.1e}" for x in e)
                  + f" | {dt:5.1f}s | {extra}", flush=True)


def main() -> int:
    t0 = time.perf_counter()
    print("# subtract_study.py: plain subtraction (what the stack determines, errors without and "
          "with noise), why coatings leave the base undetermined, and model-based subtraction")
    print("# command: python benchmarks/features/subtract_study.py")
    print(f"# machine: {machine(False)}")
    print(f"# date: {time.strftime('%Y-%m-%d %H:%M')}; commit: {commit()}")
    print(f"# load average (1 min) at the start: {os.getloadavg()[0]:.2f}")
    study()
    coupling()
    both_ways()
    print(f"# load average (1 min) at the end: {os.getloadavg()[0]:.2f}; "
          f"wall time {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
