"""Energy matching of raised operators (layersim.ingredients.energy_match)."""

import numpy as np
import scipy.sparse as sps

from layersim.ingredients.energy_match import diag_scaled


def test_diag_scaled_equals_the_sparse_products_bit_for_bit():
    rng = np.random.default_rng(1)
    B = sps.random(200, 150, density=0.1, format="csr", random_state=2)
    left, right = rng.random(200), rng.random(150)
    expect = sps.diags(left) @ B @ sps.diags(right)
    np.testing.assert_array_equal(diag_scaled(B, left, right).toarray(), expect.toarray())
    np.testing.assert_array_equal(diag_scaled(B, left, None).toarray(),
                                  (sps.diags(left) @ B).toarray())
    np.testing.assert_array_equal(diag_scaled(B, None, right).toarray(),
                                  (B @ sps.diags(right)).toarray())
    before = B.toarray()
    diag_scaled(B, left, right)
    np.testing.assert_array_equal(B.toarray(), before)      # the input is left as it was
