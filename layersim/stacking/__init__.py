"""Stacking layers: the adding equations that combine layer operators into a stack, and the
subtracting equations that take one back out (Zeltner & Jakob 2018, sec. 3.4).

* :mod:`.adding` -- the adding equations and adding-doubling of isotropic operators;
* :mod:`.deltas` -- the specular and straight-through (delta) parts under the adding equations;
* :mod:`.subtract` -- the subtracting equations, eq. (13)-(16);
* :mod:`.determined` -- what a stack determines of a recovered layer, and the rule for the rest.

The anisotropic adding equations are in :mod:`layersim.aniso.adding`.
"""
