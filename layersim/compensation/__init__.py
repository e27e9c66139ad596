"""Energy-loss compensation of rough interfaces (``energy_compensation`` in the scene).

Single-scattering microfacet interfaces lose the light that scatters more than once on the
microgeometry; a compensation term returns it. Two are offered, each applied by the solver
(:mod:`layersim.ingredients.compensation`, order 0 of the interface operator) and by the Monte
Carlo walk (:mod:`layersim.kernels.compensation`) from the same tables:

* ``"multiple-scattering"``: reciprocal, energy-conserving separable lobes after Kulla & Conty
  2017 (:func:`.model.multiple_scattering`);
* ``"layerlab"``: the additive near-diffuse correction of Jakob's layerlab
  (``Layer::setMicrofacet(..., conserveEnergy)``; :func:`.model.layerlab`).

:mod:`.tables` computes the albedo tables from :mod:`layersim.kernels.physics` and caches them.
"""

from .model import MODES, Lobes, layer_lobes, lobes_for

__all__ = ["MODES", "Lobes", "layer_lobes", "lobes_for"]
