"""Subtracting equations (Zeltner & Jakob 2018 eq. (13)-(16)): recovery errors without and with
noise.

For a few two-layer stacks, the known layer is removed from ``add(a, b)`` and the recovered
layer compared with the true one (relative Frobenius error of all blocks in the energy basis
``sqrt(w mu)``). With noise, every operator entry of the stack is multiplied by
``1 + 0.01 N(0, 1)`` and eps is chosen automatically (noise level estimated from reciprocity).
"negative" is the depth of negative lobes of the result (Fejer means of the low orders,
relative to the peak; 0 for the true layers).

Usage::

    python benchmarks/subtract_study.py
"""

from __future__ import annotations

import sys
import time

import layersim
from layersim import adding
from layersim.aniso import adding as aniso_adding
from layersim.ingredients import interface_operator, medium_operator
from layersim.ingredients.aniso_microfacet import aniso_interface_operator
from layersim.operator import Grid
from layersim.scene import Conductor, Dielectric
from layersim.subtract import negativity as _negativity, relative_error as error, with_noise


def main() -> int:
    g48, g32 = Grid.make("gauss-lobatto", 48), Grid.make("gauss-lobatto", 32)
    dust = medium_operator(g48, 24, 0.9, 0.6, 0.2, 1.0)
    dust15 = medium_operator(g48, 24, 0.9, 0.6, 0.2, 1.5)
    glass = interface_operator(g48, 24, Dielectric(ior=1.5, alpha_u=0.3, alpha_v=0.3), 1.0)
    metal = interface_operator(g48, 24, Conductor(ior=complex(0.2, 3.0), alpha_u=0.2,
                                                  alpha_v=0.2), 1.0)
    adust = medium_operator(g32, 16, 0.9, 0.6, 0.2, 1.0)
    brushed = aniso_interface_operator(g32, 16, 3, Conductor(ior=complex(0.2, 3.0),
                                                             alpha_u=0.2, alpha_v=0.4,
                                                             rotation=0.5), 1.0)
    cases = [
        ("dust (tau 0.2) over glass 0.3, remove top", adding.add, dust, glass, "top"),
        ("dust over metal 0.2, remove top", adding.add, dust, metal, "top"),
        ("glass 0.3 over dust, remove bottom", adding.add, glass, dust15, "bottom"),
        ("dust over brushed metal (0.2, 0.4) rotated, remove top", aniso_adding.add, adust,
         brushed, "top"),
    ]
    print(f"{'case':>58} | {'noise':>5} | {'eps':>8} {'method':>27} | {'error':>8} | "
          f"{'negative':>8} | time")
    for label, add, a, b, side in cases:
        stack = add(a, b)
        known, truth = (a, b) if side == "top" else (b, a)
        for level in (0.0, 0.01):
            t0 = time.perf_counter()
            data = stack if level == 0 else with_noise(stack, level, 3)
            got = layersim.subtract(data, known, side=side)
            info = got.info["subtract"]
            print(f"{label:>58} | {level:5.2f} | {info['eps']:8.2g} {info['method']:>27} | "
                  f"{error(got, truth):8.1e} | {_negativity(got):8.1e} | "
                  f"{time.perf_counter() - t0:.1f} s", flush=True)
    thick = medium_operator(g48, 24, 0.9, 0.3, 10.0, 1.0)
    try:
        layersim.subtract(adding.add(thick, metal), thick, side="top")
    except layersim.InfeasibleError as exc:
        print(f"\nthick slab (tau 10) over metal, remove top: refused: {exc}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
