"""layersim: reflectance of layered materials.

Public entry points (see docs/conventions.md)::

    scene = layersim.Scene.from_toml(path)
    bsdf = layersim.solve(scene)
    bsdf.eval(wi, wo); bsdf.albedo(wi); bsdf.bin_energies(wi, mu_edges, phi_edges)
    layersim.export(bsdf, path)                   # .bsdf file for renderers
    layersim.export(bsdf, path, format="rgl")     # RGL file (Mitsuba 3 / pbrt-v4), reflection
    stack = layersim.add(top, bottom); layer = layersim.subtract(stack, known, side="top")
    result = layersim.fit(template, target)      # free values { fit = [lo, hi] }
    base = layersim.subtract_model(stack, template, side="top").base   # subtraction by a fit
    layersim.statistical.lobes(scene, theta_i); layersim.design(targets)   # Bati et al. 2021
"""
from .errors import LayersimError, SceneError, InfeasibleError, OperatorError, FileFormatError
from .scene import Scene, Dielectric, Conductor, Medium, Diffuse, Measured, Discretization
from .plan import Plan, make_plan
from .operators.operator import IsoOperator, Operator
from .aniso import AnisoOperator
from .solved.bsdf import BSDF
from . import bsdffile
from .bsdffile import FourierTable, export
from .solver import solve, add
from .stacking.subtract import subtract
from .fit import fit, FitResult, subtract_model

__version__ = "0.1.0"


def design(targets, eta_max=None):
    """Inverse design of layered appearance (Bati et al. 2021): target lobes -> candidate
    scenes, preferred first; see :func:`layersim.statistical.design.design`."""
    from .statistical.design import design as _design
    return _design(targets, eta_max)


def __getattr__(name):
    # the statistical model loads its FGD table on first use, not at `import layersim`
    if name == "statistical":
        import importlib
        return importlib.import_module(".statistical", __name__)
    raise AttributeError(f"module 'layersim' has no attribute {name!r}")
