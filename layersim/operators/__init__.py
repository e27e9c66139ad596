"""Discrete scattering operators: the representation every layer is projected into.

* :mod:`.operator` -- :class:`~.operator.IsoOperator` (cosine-series blocks on a quadrature grid)
  and the :class:`~.operator.Operator` interface shared with the anisotropic kind;
* :mod:`.quadrature` -- quadrature rules on ``mu = cos(theta)`` and their Snell-matched splits;
* :mod:`.fourier` -- cosine-series tools of the semi-analytic projection of microfacet BSDFs;
* :mod:`.deltas` -- the specular and straight-through (delta) parts of operators, as the adding
  equations carry them;
* :mod:`.energy` -- the discrete energy balance of interface operators;
* :mod:`.interpolation` -- operator coefficients between ordinates.

The projections of each layer kind into these operators are in :mod:`layersim.ingredients`, the
anisotropic operators in :mod:`layersim.aniso`.
"""
