"""Quadrature rules: exactness degree, symmetry, no node on the horizon."""

import numpy as np
import pytest

from layersim.operators import quadrature


def _error(rule, n, degree):
    x, w = rule(n)
    exact = 2.0 / (degree + 1) if degree % 2 == 0 else 0.0
    # odd powers vanish by symmetry; test x^d + x^(d-1) to probe both parities
    return abs(np.sum(w * (x ** degree + x ** (degree - 1)))
               - (exact + (2.0 / degree if (degree - 1) % 2 == 0 else 0.0)))


@pytest.mark.parametrize("n", [4, 6, 10, 16])
def test_gauss_legendre_exact_to_degree_2n_minus_1(n):
    assert _error(quadrature.gauss_legendre, n, 2 * n - 1) < 1e-13
    assert _error(quadrature.gauss_legendre, n, 2 * n) > 1e-10  # first inexact degree


@pytest.mark.parametrize("n", [4, 6, 10, 16])
def test_gauss_lobatto_exact_to_degree_2n_minus_3(n):
    x, _ = quadrature.gauss_lobatto(n)
    assert x[0] == -1.0 and x[-1] == 1.0
    assert _error(quadrature.gauss_lobatto, n, 2 * n - 3) < 1e-13
    assert _error(quadrature.gauss_lobatto, n, 2 * n - 2) > 1e-10  # first inexact degree


def test_gauss_lobatto_matches_tabulated_values():
    # layerlab tutorial sec. 3.3.1 (n = 6)
    x, w = quadrature.gauss_lobatto(6)
    np.testing.assert_allclose(x, [-1, -0.76505532, -0.28523152, 0.28523152, 0.76505532, 1],
                               atol=1e-8)
    np.testing.assert_allclose(w, [0.06666667, 0.37847496, 0.55485838, 0.55485838, 0.37847496,
                                   0.06666667], atol=1e-8)


def test_gauss_lobatto_large_n_is_accurate():
    x, w = quadrature.gauss_lobatto(1000)
    assert abs(w.sum() - 2.0) < 1e-12
    assert abs(np.sum(w * x ** 1996) - 2.0 / 1997) < 1e-14


@pytest.mark.parametrize("n", [10, 22, 64])
def test_simpson38_is_exact_for_cubics_and_fourth_order(n):
    assert _error(quadrature.simpson38, n, 3) < 1e-13
    # x^4 is not integrated exactly, and the error falls like h^4
    e1 = abs(np.sum(quadrature.simpson38(n)[1] * quadrature.simpson38(n)[0] ** 4) - 0.4)
    m = 3 * (n - 1) + 1  # three times finer, still n = 3k + 1 with k odd
    e2 = abs(np.sum(quadrature.simpson38(m)[1] * quadrature.simpson38(m)[0] ** 4) - 0.4)
    assert e1 > 1e-9
    assert 60 < e1 / e2 < 100  # 3^4 = 81


@pytest.mark.parametrize("name", ["gauss-legendre", "gauss-lobatto", "simpson38"])
def test_rules_are_symmetric_and_avoid_the_horizon(name):
    n = 22
    x, w = quadrature.rule(name, n)
    assert np.all(x != 0.0)
    np.testing.assert_allclose(x, -x[::-1], atol=1e-15)
    np.testing.assert_allclose(w, w[::-1], atol=1e-15)
    assert abs(w.sum() - 2.0) < 1e-13
    mu, wh = quadrature.hemisphere(name, n)
    assert mu.size == n // 2 and np.all(mu > 0) and np.all(np.diff(mu) > 0)


@pytest.mark.parametrize("bad", [3, 0, -2, 7])
def test_odd_or_tiny_node_counts_are_rejected(bad):
    with pytest.raises(ValueError, match="even number of nodes"):
        quadrature.gauss_legendre(bad)


def test_simpson38_rejects_incompatible_counts():
    with pytest.raises(ValueError, match="3k \\+ 1"):
        quadrature.simpson38(12)
    with pytest.raises(ValueError, match="unknown quadrature rule"):
        quadrature.rule("trapezoid", 10)
