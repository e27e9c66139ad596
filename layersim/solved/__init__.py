"""The solved BSDF: what a solve returns, evaluated, sampled and drawn.

* :mod:`.bsdf` -- :class:`~.bsdf.BSDF`: evaluation, energy fractions, bin energies;
* :mod:`.isobsdf`, :mod:`.evaluator` -- the isotropic evaluator and the interface every
  operator kind's evaluator follows;
* :mod:`.boundary`, :mod:`.lobe` -- smooth and near-specular dielectric boundaries, applied where
  the BSDF is evaluated;
* :mod:`.sampling` -- importance sampling from the Fourier representation;
* :mod:`.channels` -- colour channels (luminance, the ``(Y, R, B)`` storage of RGB files);
* :mod:`.directions` -- validation of public direction arguments;
* :mod:`.plot` -- pictures of the operator blocks and hemispherical slices.

Files for renderers are written and read by :mod:`layersim.bsdffile`.
"""
