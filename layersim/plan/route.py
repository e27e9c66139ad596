"""Which representation solves a stack: the Fourier basis, or its specular paths.

A stack of flat interfaces and clear media with a near-specular interface
(:func:`layersim.specular_paths.why_not` is None) is solved by its specular paths
(:mod:`layersim.specular_paths`) unless the exact Fourier representation is affordable: its plan
fits the limits and needs at most :data:`FOURIER_MAX_BYTES`. A scene whose
``[discretization]`` sets ``n`` or ``md`` asks for the Fourier basis and keeps it.

A near-specular dielectric interface inside a stack, under a rough one, is solved as a mirror
over its raised transmission (:mod:`layersim.layers.near_specular_inner`) on the same terms:
where the exact Fourier plan is refused or over :data:`FOURIER_MAX_BYTES`, and not where the
``[discretization]`` sets ``n``, ``md`` or ``tol``.
"""

from __future__ import annotations

from ..errors import InfeasibleError
from ..layers.near_specular_inner import route_layers
from ..specular_paths import why_not
from ..specular_paths.accuracy import measured_error_line
from ..specular_paths.channels import ChannelModels
from ..specular_paths.continuation import WALKERS
from ..specular_paths.frontier import WALK_BELOW
from ..specular_paths.paths import PRUNE
from .model import LayerPlan, Plan

__all__ = ["FOURIER_MAX_BYTES", "EXACT_REFLECTION_MAX_BYTES", "wants_paths",
           "wants_inner_mirrors", "exact_unaffordable", "paths_plan"]

#: The Fourier basis is kept for a stack that specular paths could solve while its plan needs at
#: most this much memory (1 GiB: a second or two of projection on the 2-core VM). Above it,
#: the plan of a near-specular interface grows like ``1 / alpha`` (``layersim plan``: a rough
#: glass interface of alpha 0.02 needs 2.5 GiB, a smooth coat over gold of alpha 0.01 4.2 GiB).
FOURIER_MAX_BYTES = 1 << 30

#: A split inner interface's reflection from above is projected at its own roughness while
#: that plan needs at most this much memory (2.5 GiB: the issue's 4 GiB of peak resident
#: memory less the process's own 0.25 GiB, over the estimate's measured margin of up to
#: 1.3x on the 2-core VM), else it is a mirror (:mod:`layersim.layers.near_specular_inner`):
#: a GGX inner interface of 0.007 under a coat of 0.2 into 1.4 plans 2.4 GiB, one of 0.005
#: 4.65 GiB.
EXACT_REFLECTION_MAX_BYTES = 5 << 29


def wants_paths(scene) -> bool:
    """True if ``scene`` may be solved by specular paths: of that class, and without ``n`` or
    ``md`` set in its ``[discretization]``."""
    disc = scene.discretization
    return disc.n is None and disc.md is None and disc.tol is None and why_not(scene) is None


def wants_inner_mirrors(scene) -> bool:
    """True if ``scene`` has a near-specular inner interface that may be solved as a mirror
    over its raised transmission (:func:`layersim.layers.near_specular_inner.route_layers`)
    and its ``[discretization]`` leaves ``n``, ``md`` and ``tol`` free; the route is taken
    where the exact Fourier plan is unaffordable (:func:`fourier_unaffordable`)."""
    disc = scene.discretization
    return (disc.n is None and disc.md is None and disc.tol is None
            and bool(route_layers(scene, True)[0]))


def fourier_unaffordable(fourier: Plan | None, limit: int = FOURIER_MAX_BYTES,
                         what: str = "the Fourier plan") -> str | None:
    """Why the Fourier plan ``fourier`` is not used (None: it is): none (the basis cannot
    represent the stack), refused, or over ``limit`` bytes (default
    :data:`FOURIER_MAX_BYTES`); ``what`` names it in the reason."""
    if fourier is None:
        return "the Fourier basis cannot represent it"
    if fourier.refused:
        return f"{what} (n = {fourier.n}, md = {fourier.md}) is refused"
    if fourier.memory_bytes > limit:
        return (f"{what} (n = {fourier.n}, md = {fourier.md}) needs "
                f"{fourier.memory_bytes / 2**30:.2f} GiB, over {limit / 2**30:g} GiB")
    return None


def exact_unaffordable(plan: Plan) -> str | None:
    """Why the plan that projects a split inner interface's reflection from above at its own
    roughness is not used (None: it is): refused, or over :data:`EXACT_REFLECTION_MAX_BYTES`."""
    return fourier_unaffordable(plan, EXACT_REFLECTION_MAX_BYTES,
                                "the plan of its own reflection")


def paths_plan(scene, why: str) -> Plan:
    """The plan of a stack solved by specular paths: one line per layer, the paths' count,
    the pruned energy and the measured error; ``why`` says why the Fourier basis is not
    used."""
    models = ChannelModels(scene, PRUNE)
    layers = []
    for i, layer in enumerate(scene.channel(0).layers):
        what = "near-specular face" if layer.is_interface and not layer.smooth else \
            "smooth face" if layer.is_interface else "clear slab (attenuation only)"
        layers.append(LayerPlan(i, layer.kind, f"specular paths: {what}"))
    notes = [f"specular paths ({why}): every path keeps the horizontal wave vector; lobes of "
             "several near-specular events add in slope space (docs/method.md, \"Specular "
             "paths\")"]
    if len(models.groups) > 1:
        notes.append(f"per-channel indices: {len(models.groups)} groups of channels "
                     f"{models.groups}, each with its own paths (a path's horizontal wave "
                     "vector differs per channel)")
    counts, pruned = models.path_counts(), models.pruned()
    for side, count in counts.items():
        top = side == "top"
        lobes = sum(1 for m in models.models for x in m.entries[top] if x.rough)
        cut = sum(len(m.sets[top].frontier) for m in models.models)
        notes.append(f"lit from the {side}: {count} paths ({lobes} with lobes), pruned energy "
                     f"at most {pruned[side]:.1e} of the incident power at the probes' wave "
                     f"vectors (cut below {PRUNE:g}); {cut} cut branches, and at each incidence "
                     f"the branches below {WALK_BELOW:g} there, carried on by a walk over the "
                     f"faces ({WALKERS:.0e} walkers)")
    notes.append(measured_error_line())
    return Plan(rule="none", n=0, md=0, representation="specular-paths", layers=layers,
                notes=notes, memory_bytes=sum(_memory(m) for m in models.models),
                seconds=None)


def _memory(model) -> int:
    """Bytes the paths of one :class:`~layersim.specular_paths.model.PathModel` hold: the
    shape tables and the energy tables (a bound)."""
    shapes = sum(x.lobe.h.nbytes for xs in model.entries.values() for x in xs if x.lobe)
    return int(shapes + 129 * 16 * 8 * 4 * max(1, len(model.faces)) * model.chain.channels)


def try_fourier(make, scene) -> Plan | None:
    """The Fourier plan ``make(scene, refuse=False)``, or None where it raises."""
    try:
        return make(scene, refuse=False)
    except InfeasibleError:
        return None
