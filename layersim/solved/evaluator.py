"""The interface of a BSDF channel's evaluator, whatever the operator's representation.

:class:`layersim.solved.bsdf.BSDF` picks one evaluator per channel by the operator's representation
(:data:`layersim.solved.bsdf.EVALUATORS`: :class:`layersim.solved.isobsdf.IsoEvaluator` for cosine
series, :class:`layersim.aniso.bsdf.AnisoEvaluator` for coupled modes) and wraps it in
:class:`layersim.solved.boundary.BoundaryEvaluator` outside a smooth dielectric boundary. Every
evaluator takes validated, flattened directions ``(Q, 3)`` in the public convention
(docs/conventions.md) and answers:

* ``eval(wi, wo)``: f (1/sr) of the smooth part, shape ``(Q,)``;
* ``node_energy(name, weight=None, wi=None)``: energy fraction through block ``name`` per
  incident node;
* ``albedo(wi)``: ``(R, T)``, each ``(Q,)``;
* ``bins(wi, mu_edges, phi_edges, exits=None, deltas=True, taps=None)``: bin energies;
* ``specular(wi)``: the delta parts (:func:`layersim.operators.deltas.specular`).
"""

from __future__ import annotations

import numpy as np

from ..operators.deltas import specular


class Evaluator:
    """What the evaluators of both representations share: the operator, its table of series
    (built on first use, by the subclass's ``table_class``) and the delta parts.

    Parameters
    ----------
    op : Operator
        One channel's operator.
    """

    #: Class of the operator's table of series, built from the operator on first use.
    table_class: type

    def __init__(self, op):
        self.op = op
        self._table = None

    @property
    def table(self):
        """The operator's per-pair series (an instance of :attr:`table_class`)."""
        if self._table is None:
            self._table = self.table_class(self.op)
        return self._table

    def specular(self, wi: np.ndarray) -> dict:
        """The delta parts for beams from ``wi`` (Q, 3) (:func:`layersim.operators.deltas.specular`)."""
        return specular(self.op, wi)
