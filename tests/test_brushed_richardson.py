"""The brushed route's extrapolation weights (``layersim.layers.brushed.extrapolation_weights``,
which ``benchmarks/features/brushed_richardson.py`` uses) against closed forms: Lagrange weights
reproduce any polynomial of degree m - 1 at the target, and the two-floor ones are the
first-order Richardson formula ``X2 + (v0 - v2) (X1 - X2) / (v1 - v2)``."""
import importlib.util
import pathlib

import numpy as np

from layersim.layers.brushed import extrapolation_weights

PATH = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "features" / "brushed_richardson.py"
_spec = importlib.util.spec_from_file_location("brushed_richardson", PATH)
rich = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(rich)


def test_two_floor_weights_are_the_richardson_formula():
    v0, v1, v2 = 0.03**2, 0.15**2, 0.1**2
    x1, x2 = 0.923, 0.925
    w = extrapolation_weights(v0, [v1, v2])
    assert np.isclose(w @ [x1, x2], x2 + (v0 - v2) * (x1 - x2) / (v1 - v2), rtol=0, atol=1e-15)
    assert np.isclose(w[1], (v0 - v1) / (v2 - v1))


def test_weights_reproduce_polynomials_of_their_degree_and_not_beyond():
    v0, vs = 0.02**2, [0.15**2, 0.12**2, 0.1**2]
    w = extrapolation_weights(v0, vs)
    assert np.isclose(w.sum(), 1.0, atol=1e-13)
    quad = lambda v: 0.9 - 0.3 * v + 40.0 * v * v
    assert np.isclose(w @ [quad(v) for v in vs], quad(v0), rtol=0, atol=1e-13)
    cubic = lambda v: v**3
    assert abs(w @ [cubic(v) for v in vs] - cubic(v0)) > 1e-8


def test_the_benchmark_uses_the_routes_weights():
    assert rich.weights is extrapolation_weights


def test_combine_is_the_weighted_sum_per_incidence():
    a = [(np.array([1.0]), np.full((2, 3), 2.0))]
    b = [(np.array([3.0]), np.full((2, 3), 5.0))]
    (R, bins), = rich.combine([a, b], [-0.5, 1.5])
    assert np.allclose(R, [4.0]) and np.allclose(bins, 6.5)
