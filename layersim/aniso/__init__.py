"""Coupled-mode (anisotropic) layer calculus (Zeltner & Jakob 2018, sec. 3-4).

* :mod:`.basis` -- the real slot basis and its relation to the complex exponential basis of
  Zeltner & Jakob 2018 eq. (7)-(10) (and to the isotropic cosine basis);
* :mod:`.operator` -- :class:`AnisoOperator`, the four banded-block scattering matrices;
* :mod:`.pairs` -- slot pairs holding entries, and pruning per ordinate pair;
* :mod:`.reciprocity` -- the reciprocal image of a block;
* :mod:`.banded` -- block-banded LU with pruned block substitution (the solver of the adding
  and subtracting equations);
* :mod:`.adding` -- the adding equations (Zeltner & Jakob 2018 eq. (11)-(12)) on coupled
  operators, their blocks held by a :class:`~layersim.outofcore.workspace.Workspace`.

Isotropic layers and stacks keep the cheaper :class:`~layersim.operators.operator.IsoOperator`; they
are converted (block diagonal, no coupling) only when combined with an anisotropic one.
"""
from .operator import AnisoOperator, as_aniso, reciprocity_error

__all__ = ["AnisoOperator", "as_aniso", "reciprocity_error"]
