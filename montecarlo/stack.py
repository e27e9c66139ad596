"""Scene -> flat kernel parameters of the random walk (see :mod:`layersim.kernels.walk`).

The walk sees the stack as slabs between boundaries. Reading the validated layers top to bottom,
each layer's kind gives its record (:meth:`layersim.layers.LayerKind.walk_boundary`,
``walk_slab``):

* an interface layer (dielectric, conductor, diffuse, measured) is a boundary; two adjacent
  interfaces get a zero-thickness clear slab (of the index in between) between them;
* a medium layer is a slab; a medium without an interface above (or below) it gets an
  index-matched *null* boundary there, which particles cross unchanged;
* the stack ends with a boundary: the last interface, or a null boundary below a final medium,
  under which lies the bottom medium (index ``scene.bottom_ior``) unless the stack is opaque.

Relative indices come from :meth:`Scene.relative_ior`. A dielectric interface whose relative index
is exactly 1 is a null boundary: nothing changes index there, so light passes straight through
(the microfacet model is degenerate at ``eta = 1``: its refraction half vector vanishes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..compensation.walk import append_tables
from ..kernels import walk
from ..layers import WalkBoundary, kind_of
from ..scene import Scene

__all__ = ["StackArrays", "flatten"]


@dataclass(frozen=True)
class StackArrays:
    """Kernel parameters of one monochromatic stack.

    Attributes
    ----------
    bnd_i : ndarray of int32, shape (3 * (n_slabs + 1),)
        Per boundary: kind code (``walk.NULL`` ...), distribution code.
    bnd_f : ndarray of float32, shape (10 * (n_slabs + 1) + tables,)
        Per boundary (:data:`layersim.kernels.walk.BND_F` floats): eta, k (relative to the
        medium above), alpha_u, alpha_v, cos and sin of the tangent-frame rotation, Lambertian
        albedo, offset of its energy-compensation tables (0: none), the index of its thin film
        relative to the medium above and the film's phase scale ``4 pi n d / lambda`` (0: no
        film); a tabulated-NDF boundary (distribution code
        :data:`layersim.kernels.tabulated.TABULATED`) holds in place of ``alpha_u`` the offset of
        its packed table (:meth:`layersim.ndf.NDFTable.packed`), and so does a measured base
        (:data:`layersim.kernels.walk.MEASURED`: one channel of its MERL table,
        :meth:`layersim.layers.merl.MERLTable.packed`). The NDF and MERL tables follow the records,
        then the compensation tables (:mod:`layersim.compensation.walk`).
    slab_f : ndarray of float32, shape (3 * max(n_slabs, 1),)
        Per slab: tau (along the normal), single-scattering albedo, HG g (padded when empty).
    n_slabs : int
    opaque : bool
        True when the bottom boundary is a conductor or a diffuse base.
    """

    bnd_i: np.ndarray
    bnd_f: np.ndarray
    slab_f: np.ndarray
    n_slabs: int
    opaque: bool

    @property
    def features(self) -> walk.Features:
        """The walk's code paths these records use; the kernel leaves the others out."""
        return walk.features_of(self.bnd_i, self.bnd_f, self.slab_f, self.n_slabs)


#: The record of a null boundary: an index-matched pass-through.
NULL_BOUNDARY = WalkBoundary((walk.NULL, 0, 0), (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0))


def _boundary(scene: Scene, i: int | None) -> WalkBoundary:
    """The boundary made by layer ``i`` (its kind's record; None, or a kind's None: a null
    boundary)."""
    if i is None:
        return NULL_BOUNDARY
    return kind_of(scene.layers[i]).walk_boundary(scene, i) or NULL_BOUNDARY


def _append_tables(boundaries: list, bnd_f: np.ndarray) -> np.ndarray:
    """``bnd_f`` followed by the packed tables of the tabulated-NDF boundaries, each record
    pointing at its table (float32 holds the offsets exactly below 2^24)."""
    parts = [bnd_f]
    size = bnd_f.size
    for b, record in enumerate(boundaries):
        if record.table is not None:
            packed = record.table.packed(np.float32)
            bnd_f[walk.BND_F * b + 2] = size
            parts.append(packed)
            size += packed.size
    if size >= 1 << 24:
        raise ValueError(f"the NDF tables take {size} floats; the walk addresses at most 2^24")
    return np.concatenate(parts)


def flatten(scene: Scene) -> StackArrays:
    """Boundary and slab records of a monochromatic, validated scene (no re-validation)."""
    boundaries, slabs, owners = [], [], []
    last = None                      # what was appended last: "boundary" or "slab"
    for i, layer in enumerate(scene.layers):
        kind = kind_of(layer)
        if kind.walk_role == "slab":
            if last != "boundary":       # top of the stack, or a medium right below a medium
                boundaries.append(_boundary(scene, None))
                owners.append(None)
            slabs.append(list(kind.walk_slab(layer)))
            last = "slab"
        else:
            if last == "boundary":       # two interfaces in a row: zero-thickness clear gap
                slabs.append([0.0, 1.0, 0.0])
            boundaries.append(_boundary(scene, i))
            owners.append(i)
            last = "boundary"
    if last == "slab":
        boundaries.append(_boundary(scene, None))
        owners.append(None)
    for i, b in zip(owners, boundaries):
        if len(b.floats) != walk.BND_F or len(b.ints) != walk.BND_I:
            raise ValueError(f"the walk record of layer {i} has {len(b.ints)} ints and "
                             f"{len(b.floats)} floats; a boundary record has {walk.BND_I} and "
                             f"{walk.BND_F}")
    bnd_i = np.array([x for b in boundaries for x in b.ints], dtype=np.int32)
    bnd_f = np.array([x for b in boundaries for x in b.floats], dtype=np.float32)
    bnd_f = append_tables(scene, owners, _append_tables(boundaries, bnd_f), walk.BND_F)
    slab_f = np.array([x for s in slabs for x in s] or [0.0, 1.0, 0.0], dtype=np.float32)
    assert len(boundaries) == len(slabs) + 1
    return StackArrays(bnd_i, bnd_f, slab_f, len(slabs), scene.opaque)
