"""The homogeneous medium: a slab of optical thickness ``tau`` (along the normal),
single-scattering ``albedo`` and Henyey-Greenstein asymmetry ``g``.

Solved by adding-doubling of its phase function's Fourier orders (whole series, or delta-M
scaled for strongly forward-peaked ``g``; :mod:`layersim.ingredients.medium`), walked as a slab
of exponential flights, an absorber (albedo 0) in Belcour's statistical model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import InfeasibleError
from ..ingredients.medium import G_EXACT_MAX, hg_scaling, medium_operator
from .base import N_PER_WIDTH, Layer, LayerKind, LayerPlan
from .fields import Field, real
from .registry import register

__all__ = ["Medium", "MediumKind"]

#: Legendre moments a delta-M scaled medium needs (the accuracy target that sets its share of
#: ``n``): for g = 0.99, tau 5, albedo 0.95 the albedo at normal incidence moves by 3e-5 from
#: N = 31 to N = 195 moments (by 2.3e-4 from 15 to 31);
#: ``benchmarks/features/forward_media.py``. A grid of ``n`` Gauss-Lobatto ordinates represents
#: ``n - 1`` moments, so the planner's smallest grid (64) already meets it.
DELTA_M_MOMENTS = 32


@dataclass(frozen=True)
class Medium(Layer):
    """Homogeneous slab: optical thickness ``tau``, single-scattering ``albedo``, Henyey-Greenstein
    asymmetry ``g`` (0 = isotropic)."""

    kind = "medium"
    albedo: float = 0.0
    g: float = 0.0
    tau: float = 0.0


class MediumKind(LayerKind):
    name = "medium"
    record = Medium
    walk_role = "slab"
    fields = (
        Field("albedo", "single-scattering albedo", parse=real(lo=0.0, hi=1.0), required=True,
              per_channel=True, fit=True),
        Field("g", "Henyey-Greenstein asymmetry (0: isotropic)",
              parse=real(lo=-1.0, hi=1.0, lo_open=True, hi_open=True), default=0.0,
              per_channel=True, fit=True),
        Field("tau", "optical thickness along the normal", parse=real(lo=0.0), required=True,
              per_channel=True, fit=True),
    )

    def build(self, ctx, values, raw, defaults) -> list:
        albedos, gs, taus = values["albedo"], values["g"], values["tau"]
        # a shared value pairs with every channel of the others
        channels = max(len(albedos), len(gs), len(taus))
        return [Medium(albedo=albedos[c % len(albedos)], g=gs[c % len(gs)],
                       tau=taus[c % len(taus)]) for c in range(channels)]

    def to_raw(self, per_channel) -> dict:
        cv = self.channel_value
        return {"kind": self.name, "tau": cv(per_channel, lambda x: x.tau),
                "albedo": cv(per_channel, lambda x: x.albedo), "g": cv(per_channel, lambda x: x.g)}

    def describe(self, per_channel) -> str:
        v = self.values
        return (f"medium tau={v(per_channel, lambda x: f'{x.tau:g}')}, "
                f"albedo={v(per_channel, lambda x: f'{x.albedo:g}')}, "
                f"g={v(per_channel, lambda x: f'{x.g:g}')}")

    def survey(self, scene, i, survey) -> None:
        channels = [scene.channel(c).layers[i] for c in range(scene.channels)]
        if all(x.tau == 0.0 for x in channels):
            survey.left_out.append(f"layer {i} (medium): tau = 0 is an exact no-op")
            survey.layers.append(LayerPlan(i, self.name, "left out", "tau = 0"))
            return
        # a per-channel g: every channel's representation is decided on the grid (on_grid);
        # the most forward-peaked channel that keeps the whole series sets the lobe width
        gs = [x.g for x in channels]
        g_text = "/".join(f"{g:g}" for g in dict.fromkeys(gs))
        tau_text = "/".join(f"{t:g}" for t in dict.fromkeys(x.tau for x in channels))
        lp = LayerPlan(i, self.name, "adding-doubling", f"tau={tau_text}, g={g_text}")
        survey.layers.append(lp)
        if max(x.albedo for x in channels) == 0:
            lp.detail += ": no scattering, unscattered beam in all orders"
            return
        if max(gs) > G_EXACT_MAX:
            # delta-M scaled: the scaled phase function needs DELTA_M_MOMENTS moments, i.e. a
            # grid of DELTA_M_MOMENTS + 1 Gauss-Lobatto ordinates
            survey.widths.append((N_PER_WIDTH / (DELTA_M_MOMENTS + 1), i, self.name,
                                  f"delta-M scaled phase function ({DELTA_M_MOMENTS} moments)"))
        whole = [g for g in gs if g <= G_EXACT_MAX and g != 0.0]
        if whole:
            g = max(whole, key=abs)
            survey.widths.append((math.sqrt(1.0 - abs(g)), i, self.name, "phase-function lobe"))
        survey.scaled.append(lp)

    def on_grid(self, scene, lp, grid) -> int:
        """The phase-function representation of every channel on ``grid``
        (:func:`~layersim.ingredients.medium.hg_scaling`, the function the solve uses): the
        whole series or delta-M scaled; sets the report line and returns the orders.

        Raises
        ------
        InfeasibleError
            Naming the layer and field ``g`` for a backward peak the grid cannot hold.
        """
        layers = [scene.channel(c).layers[lp.index] for c in range(scene.channels)]
        try:
            scs = [hg_scaling(grid, x.g, x.albedo, x.tau) for x in layers]
        except InfeasibleError as exc:
            raise InfeasibleError(f"layer {lp.index} (medium): field 'g': {exc}") from None
        lp.orders = max(c.moments for c in scs)
        if any(c.scaled for c in scs):
            per = lambda v: "/".join(dict.fromkeys(v))      # one value, or one per channel
            lp.detail += (f": delta-M scaled (Wiscombe 1977), N = "
                          f"{per(str(c.moments) for c in scs)} moments, f = "
                          f"{per(f'{c.f:.4g}' for c in scs)}, scaled tau = "
                          f"{per(f'{c.tau:.4g}' for c in scs)}, albedo = "
                          f"{'/'.join(f'{c.albedo:.4g}' for c in scs)}; scattering in "
                          f"{lp.orders} order(s), unscattered beam (with the truncated forward "
                          "peak) in all")
        else:
            lp.detail += f": scattering in {lp.orders} order(s), unscattered beam in all"
        return lp.orders

    def operator(self, job):
        layer = job.layer
        return medium_operator(job.grid, job.plan.md, layer.albedo, layer.g, layer.tau,
                               job.eta_above, name=f"layer {job.index} (medium)")

    def walk_slab(self, layer) -> tuple:
        return (layer.tau, layer.albedo, layer.g)

    def statistical_atom(self, layer, refuse):
        if layer.albedo > 0.0:
            raise refuse("albedo", f"a scattering medium (albedo {layer.albedo:g}) is not "
                                   "represented; use albedo = 0")
        return ("absorber", layer.tau)


register(MediumKind())
