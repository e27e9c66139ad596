"""The compensation tables of a stack's boundaries, packed for the random walk.

Each compensated boundary's record (:mod:`layersim.kernels.compensation`) is appended to the
walk's boundary floats ``bnd_f``, and its offset is stored in the boundary record's slot
:data:`OFFSET_SLOT` (:data:`layersim.kernels.walk.BND_F` floats per record): per side
of incidence (top, then bottom) the block albedos ``a_R = u_R V_R``, ``a_T = u_T V_T`` and the
outgoing shapes ``g_R = pi v_R / V_R``, ``g_T = pi v_T / V_T`` at the table nodes.
"""

from __future__ import annotations

import numpy as np

from . import tables
from .model import layer_lobes

#: Blocks lit from each side: (reflection, transmission).
_SIDES = (("Rt", "Ttb"), ("Rb", "Tbt"))
#: Index of the table offset in a boundary record (``walk.BND_F`` floats each).
OFFSET_SLOT = 7


def _record(lobes) -> np.ndarray:
    parts = []
    for blocks in _SIDES:
        albedo, shape = [], []
        for b in blocks:
            if b not in lobes.u:
                albedo.append(np.zeros(tables.NODES))
                shape.append(np.zeros(tables.NODES))
                continue
            v = lobes.integral(b)
            albedo.append(lobes.u[b] * v)
            shape.append(lobes.v[b] * (np.pi / v) if v > 0 else np.zeros(tables.NODES))
        parts += albedo + shape
    return np.concatenate(parts)


def append_tables(scene, owners: list, bnd_f: np.ndarray, record_floats: int) -> np.ndarray:
    """``bnd_f`` with the compensation records of the boundaries made by layers ``owners[b]``
    (None for null boundaries) appended and their offsets set.

    Parameters
    ----------
    scene : Scene
        Validated monochromatic scene.
    owners : list of int or None
        Layer index of every boundary, top to bottom.
    bnd_f : ndarray of float32
        Boundary records, ``record_floats`` each.
    """
    out = [np.asarray(bnd_f, np.float32)]
    size = out[0].size
    for b, i in enumerate(owners):
        # null boundaries, diffuse bases and smooth interfaces have alpha_u = 0 in their record
        if i is None or out[0][b * record_floats + 2] == 0.0:
            continue
        layer = scene.layers[i]
        lobes = layer_lobes(layer, scene.ior_above(i))
        if lobes is None:
            continue
        out[0][b * record_floats + OFFSET_SLOT] = float(size)
        rec = _record(lobes).astype(np.float32)
        out.append(rec)
        size += rec.size
    return np.concatenate(out)
