"""The plain subtraction's error report bounds its error: for a rough coating over a rough
conductor, isotropic and anisotropic (the cases of benchmarks/features/subtract_study.py at a
small n), the estimated error over every cut mu >= 0.8 ... 0.95 is at least the error that the
noise-free round trip ``subtract(stack, coat)`` against the hidden base measures."""

import numpy as np
import pytest

import layersim

COND = {"kind": "conductor", "ior": [0.2, 3.9]}
CUTS = (0.8, 0.85, 0.9, 0.95)


def _solve(layers, top_ior=1.0, like=None, disc=None):
    d = {"layer": layers, "stack": {"top_ior": top_ior}}
    if disc:
        d["discretization"] = disc
    return layersim.solve(layersim.Scene.from_dict(d), like=like)


def _error_over(got, truth, mu_min):
    """Relative L2 error (energy basis, all orders / slots and blocks) over the directions with
    mu >= mu_min on the top side (all directions on the bottom side)."""
    a, b = got.as_coupled(), truth.as_coupled()
    keep = np.tile(b.grid.mu >= mu_min, b.slots).astype(float)
    w = np.tile(np.sqrt(b.grid.flux_weight), b.slots)
    num = den = 0.0
    for name, blk in b.blocks.items():
        if blk is None:
            continue
        r = keep if name in ("Rt", "Tbt") else np.ones_like(keep)
        c = keep if name in ("Rt", "Ttb") else np.ones_like(keep)
        scale = np.outer(w * r, c / w)
        num += (a.blocks[name] - blk).multiply(scale).power(2).sum()
        den += blk.multiply(scale).power(2).sum()
    return float(np.sqrt(num / den))


def _report_and_truth(coat_roughness, base_roughness, disc):
    coat = {"kind": "dielectric", "ior": 1.5, "roughness": coat_roughness}
    base = dict(COND, roughness=base_roughness)
    stack = _solve([coat, base], disc=disc)
    known, truth = _solve([coat], like=stack), _solve([base], top_ior=1.5, like=stack)
    got = layersim.subtract(stack, known, side="top")
    d = got.info["subtract"]["determined"]
    est = dict(d["estimates"])
    out = []
    for cut in CUTS:
        reported = est[min(m for m in est if m >= cut)]
        out.append((cut, reported, _error_over(got.operators[0], truth.operators[0], cut)))
    return out


def test_the_isotropic_report_bounds_the_round_trip_error():
    """Coat (1.5, alpha 0.2) over a conductor (alpha 0.3), n 48: measured 3.8e-2 reported
    for 3.8e-3 at mu > 0.85 (conservative: the estimate is made before the correction)."""
    for cut, reported, measured in _report_and_truth(0.2, 0.3, {"n": 48, "md": 24}):
        assert reported >= measured, (cut, reported, measured)


@pytest.mark.slow
def test_the_anisotropic_report_bounds_the_round_trip_error():
    """Coat (0.3, 0.2) over a conductor (0.3, 0.2), n 48, md 24: the report on rotational
    averages said 1.7e-2 at mu > 0.85 where the round trip measures 2.6e-2; estimated in the
    coupled algebra, with the stack's truncation (STACK_RELERR) simulated, it says 8.1e-2."""
    for cut, reported, measured in _report_and_truth([0.3, 0.2], [0.3, 0.2],
                                                     {"n": 48, "md": 24}):
        assert measured > 1e-2                   # the case is one where the report matters
        assert reported >= measured, (cut, reported, measured)
