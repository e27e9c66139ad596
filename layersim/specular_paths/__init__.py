"""Stacks of flat interfaces (smooth or near-specular) and clear media, solved as sums over
their specular paths (issue 33, first class): :mod:`.stack` (the chain of faces and slabs),
:mod:`.energies` (event energies), :mod:`.paths` (enumeration), :mod:`.shape` (radial densities
of sums of slopes), :mod:`.lobes` (a path's lobe), :mod:`.model` (the BSDF as a sum over
paths), :mod:`.channels` (one model per group of channels sharing their indices: dispersion),
:mod:`.sampler` and :mod:`.bsdf` (the public BSDF object). docs/method.md, "Specular
paths", derives it.
"""

from .bsdf import SpecularPathsBSDF
from .stack import why_not

__all__ = ["SpecularPathsBSDF", "why_not"]
