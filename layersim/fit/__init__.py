"""Fit a stack to a target by exact transport: templates with free values, the least-squares
fit on solves of the adding equations, standard errors and correlations of the result."""

from .optimize import fit
from .modelsub import ModelSubtraction, subtract_model
from .result import FitResult
from .synthetic import noisy_points
from .target import Target, as_target, direction_pairs
from .template import Parameter, Template

__all__ = ["fit", "FitResult", "ModelSubtraction", "subtract_model", "Template", "Parameter",
           "Target", "as_target", "direction_pairs", "noisy_points"]
