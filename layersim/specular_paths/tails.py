"""The far tail of a path of several near-specular events: one large deviation at a time.

The linearised lobe of a path (:mod:`.lobes`) maps each event's slope to a deviation of the
wave vector with a scale ``c_e`` taken at the midpoint ``p_bar`` and the path's energy at
``p_bar``. In its core that is exact as ``alpha -> 0``; far out (a deviation of several tenths
of ``|p|``, where a bin holds few of the traced nodes) the scales, the Fresnel factors and the
Jacobian of the event that deviates vary across the deviation, and the linearised tail of a
GGX pane at normal incidence is 4-6 times the walk's (``benchmarks/accuracy/
near_specular_anywhere.txt``). A sum of heavy-tailed deviations is far out because *one* of
them is (the single big jump of subexponential sums, Foss, Korshunov & Zachary 2013, ch. 3): there the
path's BSDF is the sum over its events of that event's exact microfacet BSDF with every other
event undeviated (:meth:`.model.PathModel.single_event`). :func:`tail_f` adds to the
linearised lobe, per event, that exact single-event term minus its linearised counterpart (the
same event's lobe alone, ``x.singles``, scaled as the path's): in the far tail the
linearised terms cancel and the exact ones remain; in the core both terms of each pair agree to
first order. Gaussian (Beckmann) tails fall fast enough that the correction only matters for
GGX, where it is exact asymptotically.

:func:`.binning.path_bins` uses it for the bins where the traced nodes are sparse; ``eval``
keeps the linearised lobe (whose core is what rendering sees).
"""

from __future__ import annotations

import numpy as np

from .paths import Events

__all__ = ["tail_f"]


def tail_f(model, x, pi: np.ndarray, po: np.ndarray) -> np.ndarray:
    """``f`` (Q, C) in 1/sr of the path ``x`` (an entry of ``model``, a
    :class:`.model.PathModel`) from wave vectors ``pi`` to ``po`` (Q, 2): the linearised lobe
    with each event's far tail exact (module docstring); exact for one event. Negative sums
    (where the corrections overshoot in a lobe's flank) are 0."""
    if x.exact:
        return model.eval_path(x, pi, po)
    f, *linear = model.linearised(x, [x.lobe, *x.singles], pi, po)
    ev_in, ev_out = Events(model.chain, model.faces, pi), Events(model.chain, model.faces, po)
    for s, lin in zip(x.steps, linear):
        f = f + model.single_event(x.path, s, ev_in, ev_out, pi, po) - lin
    return np.maximum(f, 0.0)
