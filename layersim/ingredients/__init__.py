"""Ingredient layers: each module turns one validated scene layer into an :class:`IsoOperator`
(or, for anisotropic layers, the coupled operator) on a given grid.

* :mod:`.diffuse` -- opaque Lambertian base;
* :mod:`.medium` -- homogeneous slab (isotropic or Henyey-Greenstein), by adding-doubling;
* :mod:`.microfacet` -- rough dielectric and conductor interfaces, semi-analytic projection.
"""
from .diffuse import diffuse_operator
from .medium import medium_operator
from .microfacet import interface_operator

__all__ = ["diffuse_operator", "medium_operator", "interface_operator"]
