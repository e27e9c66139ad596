"""Stacking layers: the adding equations that combine layer operators into a stack, and the
subtracting equations that take one back out (Zeltner & Jakob 2018, sec. 3.4).

* :mod:`.adding` -- the adding equations and adding-doubling of isotropic operators;
* :mod:`.subtract` -- the subtracting equations, eq. (13)-(16);
* :mod:`.determined` -- what a stack determines of a recovered layer, and the rule for the rest.

The delta parts they carry are in :mod:`layersim.operators.deltas`, the anisotropic adding
equations in :mod:`layersim.aniso.adding`.
"""
