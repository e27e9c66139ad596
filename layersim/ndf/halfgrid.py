"""The (theta, phi) grid of microfacet normals on which fitted NDFs live.

It is the table layout of ``distribution = "tabulated"`` files (``docs/conventions.md``): ``theta``
increasing from 0 to pi/2 (both ends included), ``phi`` increasing from 0 in steps of
2 pi / n_phi (covering [0, 2 pi)), values interpolated bilinearly, periodic in phi. Wang et al.
2008 use a hemicube (sec. 3); a polar grid is what the tabulated-NDF layer reads, and azimuthal
rotation (their eq. 13) is a shift along phi on it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# symmetries of an NDF a user may state for completion (Wang et al. 2008 need none: they merge
# other surface points); the maps they induce on the grid are in complete.symmetry_images
SYMMETRIES = ("point", "mirror-x", "mirror-y", "isotropic")


@dataclass(frozen=True)
class HalfGrid:
    """Polar grid over the hemisphere of microfacet normals.

    Parameters
    ----------
    n_theta : int >= 3, nodes in theta over [0, pi/2]
    n_phi : int >= 4, nodes in phi over [0, 2 pi)
    """

    n_theta: int = 91
    n_phi: int = 180

    def __post_init__(self):
        if int(self.n_theta) < 3 or int(self.n_phi) < 4:
            raise ValueError(f"NDF grid {self.n_theta} x {self.n_phi}: need at least 3 theta "
                             "and 4 phi nodes")

    @property
    def theta(self) -> np.ndarray:
        """Polar angles in radians, shape (n_theta,)."""
        return np.linspace(0.0, 0.5 * np.pi, self.n_theta)

    @property
    def phi(self) -> np.ndarray:
        """Azimuths in radians, shape (n_phi,)."""
        return 2.0 * np.pi * np.arange(self.n_phi) / self.n_phi

    @property
    def weights(self) -> np.ndarray:
        """Solid angle per node in sr (trapezoid rule in theta with sin theta), (n_theta, n_phi).

        Sums to 2 pi up to O(h^2)."""
        t = self.theta
        wt = np.full(self.n_theta, t[1] - t[0])
        wt[[0, -1]] *= 0.5
        return np.outer(wt * np.sin(t), np.full(self.n_phi, 2.0 * np.pi / self.n_phi))

    def directions(self) -> np.ndarray:
        """Unit normals of the nodes, shape (n_theta, n_phi, 3)."""
        t, p = np.meshgrid(self.theta, self.phi, indexing="ij")
        return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)

    def angles(self, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(theta, phi) in radians of unit vectors h (..., 3); phi in [0, 2 pi)."""
        h = np.asarray(h, float)
        theta = np.arccos(np.clip(h[..., 2], -1.0, 1.0))
        return theta, np.mod(np.arctan2(h[..., 1], h[..., 0]), 2.0 * np.pi)

    def lookup(self, d: np.ndarray, h: np.ndarray) -> np.ndarray:
        """Bilinear interpolation of the table d (n_theta, n_phi) at unit vectors h (..., 3).

        Nodes holding NaN (undetermined) make the result NaN; h below the horizon gives 0."""
        theta, phi = self.angles(h)
        x = np.clip(theta / (self.theta[1]), 0.0, self.n_theta - 1.0)
        i0 = np.minimum(x.astype(int), self.n_theta - 2)
        fx = x - i0
        y = phi / (2.0 * np.pi / self.n_phi)
        j0 = np.floor(y).astype(int) % self.n_phi
        fy = y - np.floor(y)
        j1 = (j0 + 1) % self.n_phi
        v = ((1 - fx) * ((1 - fy) * d[i0, j0] + fy * d[i0, j1])
             + fx * ((1 - fy) * d[i0 + 1, j0] + fy * d[i0 + 1, j1]))
        return np.where(np.asarray(h)[..., 2] > 0, v, 0.0)

    def rotate(self, d: np.ndarray, angle: float) -> np.ndarray:
        """The table of h -> d(R(angle) h), R an azimuthal rotation by angle (radians):
        Wang et al. 2008 eq. (13). Linear interpolation along phi (exact for multiples of the
        phi step); NaN nodes spread to their phi neighbours."""
        y = np.arange(self.n_phi) + angle / (2.0 * np.pi / self.n_phi)
        j0 = np.floor(y).astype(int)
        f = y - j0
        return (1 - f) * d[:, j0 % self.n_phi] + f * d[:, (j0 + 1) % self.n_phi]

    def projected_area(self, d: np.ndarray) -> float:
        """int (h . n) D(h) dw_h over the grid (1 for a normalised NDF)."""
        return float(np.sum(self.weights * np.cos(self.theta)[:, None] * d))
