"""Layer kinds: one module per kind, each holding its record, its declared fields, and what the
planner, the solver, the Monte Carlo walk and the statistical model need from it
(:class:`~layersim.layers.base.LayerKind`).

* :mod:`.dielectric`, :mod:`.conductor` -- rough or smooth interfaces (shared in
  :mod:`.interface`, with the variants :mod:`.smooth`, :mod:`.near_specular`,
  :mod:`.brushed`, :mod:`.tabulated`);
* :mod:`.medium` -- homogeneous scattering and absorbing slab;
* :mod:`.diffuse` -- Lambertian base;
* :mod:`.measured` -- measured (MERL) base, its files read by :mod:`.merl`.

A new kind subclasses :class:`LayerKind`, declares its record and fields, implements the hooks
of the stages it takes part in, and calls :func:`register`; nothing else in the package needs to
change (``tests/test_layer_kinds.py`` adds one from a test module).
"""

from .base import Layer, LayerKind, LayerPlan, OperatorJob, Survey, WalkBoundary
from .fields import Ctx, Field
from .registry import KINDS, kind_named, kind_of, names, register
from .interface import COMPENSATIONS, DISTRIBUTIONS, SHADOWINGS, Interface
from .dielectric import Dielectric
from .conductor import Conductor
from .medium import Medium
from .diffuse import Diffuse
from .measured import Measured

__all__ = ["Layer", "LayerKind", "LayerPlan", "OperatorJob", "Survey", "WalkBoundary", "Ctx",
           "Field", "KINDS", "kind_named", "kind_of", "names", "register", "Interface",
           "Dielectric", "Conductor", "Medium", "Diffuse", "Measured", "DISTRIBUTIONS",
           "COMPENSATIONS", "SHADOWINGS"]
