"""Belcour's statistical model of layered reflectance (Belcour 2018) and its inversion for
design (Bati, Barla & Pacanowski 2021, "An inverse method for the exploration of layered
material appearance").

* :func:`lobes` (``layersim.statistical.lobes(scene, theta_i)``): the model's lobes, energy and
  roughness per channel, of a stack of GGX interfaces and absorbing media;
* :class:`StatisticalBSDF`: the same as a BSDF (``eval``, ``albedo``, ``bin_energies``);
* :func:`design` (also ``layersim.design``): target lobes -> candidate scenes (a conductor
  base inferred where no dielectric reaches the bottom lobe, :mod:`.design.inference`);
* :func:`.refine.refine` (``layersim design --exact``): a design refined by exact fits to its
  target lobes.

Modules: :mod:`.fgd` (FGD tables), :mod:`.variance`, :mod:`.atomic`, :mod:`.forward`,
:mod:`.stack`, :mod:`.lobes`, :mod:`.targets`, :mod:`.design`, :mod:`.verify`, :mod:`.refine`.
"""

from .lobes import Lobe, StatisticalBSDF, lobes
from .targets import TargetError, parse_targets
from .design import design, designs

__all__ = ["lobes", "Lobe", "StatisticalBSDF", "design", "designs", "parse_targets",
           "TargetError"]
