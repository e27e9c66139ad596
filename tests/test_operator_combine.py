"""Linear combinations of operators (layersim.operators.combine): block by block, order by order
and delta by delta the weighted sum of the operands, in both representations, and refused for
operators of different discretisations."""

import numpy as np
import pytest
import scipy.sparse as sps

from layersim.aniso.operator import AnisoOperator
from layersim.errors import OperatorError
from layersim.operators.combine import linear_combination
from layersim.operators.operator import Grid, IsoOperator

GRID = Grid.make("gauss-lobatto", 8)


def _iso(seed, m=3, eta_bottom=1.5):
    """A random two-sided isotropic operator with a delta in its transmissions."""
    rng = np.random.default_rng(seed)
    h = GRID.h
    blocks = {k: rng.random((m, h, h)) * (rng.random((m, h, h)) < 0.5)
              for k in ("Rt", "Rb", "Ttb", "Tbt")}
    delta = {"Ttb": rng.random(h), "Tbt": rng.random(h)}
    return IsoOperator.from_dense(GRID, blocks, 1.0, eta_bottom, delta)


def _dense(op, name):
    return np.array([op.block(name, l).toarray() for l in range(op.m)])


def test_isotropic_combination_is_the_weighted_sum_of_every_order_and_delta():
    a, b = _iso(1), _iso(2)
    c = linear_combination([a, b], [-2.068, 3.068])
    assert isinstance(c, IsoOperator) and c.m == a.m and c.eta_bottom == 1.5
    for name in ("Rt", "Rb", "Ttb", "Tbt"):
        np.testing.assert_allclose(_dense(c, name), -2.068 * _dense(a, name)
                                   + 3.068 * _dense(b, name), rtol=0, atol=1e-15)
    for k in ("Ttb", "Tbt"):
        np.testing.assert_allclose(c.delta[k], -2.068 * a.delta[k] + 3.068 * b.delta[k],
                                   rtol=0, atol=1e-15)


def test_coupled_combination_is_the_weighted_sum_and_keeps_the_widest_coupling():
    a, b = AnisoOperator.from_iso(_iso(3), 3), AnisoOperator.from_iso(_iso(4), 3)
    b = AnisoOperator(b.grid, b.md, b.blocks, b.eta_top, b.eta_bottom, b.delta, ms=2)
    w = [0.25, 0.5]
    c = linear_combination([a, b], w)
    assert isinstance(c, AnisoOperator) and c.ms == 2
    for name in ("Rt", "Rb", "Ttb", "Tbt"):
        want = w[0] * a.blocks[name].toarray() + w[1] * b.blocks[name].toarray()
        np.testing.assert_allclose(c.blocks[name].toarray(), want, rtol=0, atol=1e-15)
        assert sps.isspmatrix_csr(c.blocks[name]) or sps.issparse(c.blocks[name])


def test_weights_one_and_zero_return_the_first_operator():
    a, b = _iso(5), _iso(6)
    c = linear_combination([a, b], [1.0, 0.0])
    for name in ("Rt", "Tbt"):
        np.testing.assert_array_equal(_dense(c, name), _dense(a, name))


@pytest.mark.parametrize("other, why", [
    (lambda: _iso(7, m=4), "orders"),
    (lambda: _iso(7, eta_bottom=1.3), "indices"),
    (lambda: AnisoOperator.from_iso(_iso(7), 3), "representation")])
def test_operators_of_other_discretisations_are_refused(other, why):
    with pytest.raises(OperatorError, match="one discretisation"):
        linear_combination([_iso(8), other()], [0.5, 0.5])


def test_a_weight_per_operator():
    with pytest.raises(OperatorError, match="one weight per operator"):
        linear_combination([_iso(9), _iso(10)], [1.0])
