"""Linear solves with the banded block matrices of coupled Fourier modes.

The adding and subtracting equations need ``Y = A^-1 B`` for ``A = I - K`` (or
``T^T T + eps^2 I``) where ``K`` couples Fourier mode ``k`` only to modes ``k +- 2s``,
``|s| <= ms`` (seed 000 eq. (10)): ordered by mode, ``A`` is block banded. Seed 000 factors it
once with UMFPACK and runs custom sparse-sparse substitutions (sec. 3.3). Here
(:func:`layersim.aniso.adding.banded_solve` drives it):

1. **Components.** Mode parity is conserved, and for mirror-symmetric stacks (aligned layers)
   the cosine and sine slots decouple too; unknowns are ordered by (component, Fourier order),
   which keeps the matrix block banded with the bandwidth of its widest component.
2. **Active unknowns.** Rows of ``K`` that are empty (no scattering into that mode and
   ordinate, e.g. high orders at steep angles) give ``y = b`` directly and are eliminated.
3. **Block LU.** :class:`BlockBandedLU` factors the remaining matrix with dense blocks (one per
   Fourier order and component, its active ordinates), stored as dense block rows over the
   band, LAPACK partial pivoting inside the diagonal blocks and no pivoting across them.
   ``A = I - K`` with ``K`` a contraction of energy is block diagonally dominant in practice;
   the caller verifies the residual and falls back to sparse LU if it is not small.
4. **Pruned block substitution.** Right-hand sides are processed in groups (the columns of one
   source order); forward and backward substitution visit blocks outward from the source and
   stop after ``b`` consecutive blocks whose entries are below ``PRUNE`` times the group's
   largest right-hand side entry. Light entering in order ``k`` stays near order ``k``
   (coupling decays with ``|s|``), so each group touches a few dozen blocks: the sparse-RHS
   substitution of the paper, at BLAS-3 speed. Dropped entries are bounded by ``PRUNE``.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.linalg as sla

#: Relative magnitude below which blocks of the solution are treated as zero (and the
#: substitution stops after ``b`` such blocks in a row).
PRUNE = 1e-10


class BlockBandedLU:
    """LU factorisation of a block-banded matrix given by its dense block rows.

    Parameters
    ----------
    rows : list of ndarray
        ``rows[i]`` has shape ``(r_i, c_i)``: block row ``i`` over the column blocks
        ``lo(i) .. hi(i) - 1`` with ``lo(i) = max(0, i - b)``, ``hi(i) = min(J, i + b + 1)``
        (overwritten by the factors: the multipliers left of the diagonal, the inverse of
        the diagonal block, ``U`` right of it).
    starts : int ndarray (J + 1,)
        Block boundaries of the unknowns.
    bandwidth : int
    """

    def __init__(self, rows: list, starts, bandwidth: int):
        self.starts = np.asarray(starts, np.int64)
        self.J = J = self.starts.size - 1
        self.b = b = int(bandwidth)
        self.R = rows
        for j in range(J):
            Rj = self.R[j]
            cj = self._cols(j, j, j + 1)
            with warnings.catch_warnings():     # an exactly singular block: the caller
                warnings.simplefilter("error", sla.LinAlgWarning)  # falls back to sparse LU
                try:
                    D = sla.lu_factor(Rj[:, cj], check_finite=False)
                except sla.LinAlgWarning as exc:
                    raise np.linalg.LinAlgError(f"block LU: {exc}") from None
            inverse = sla.lu_solve(D, np.eye(D[0].shape[0]), check_finite=False)
            if not np.all(np.isfinite(inverse)):
                raise np.linalg.LinAlgError("singular diagonal block in the block LU")
            hi = min(J, j + b + 1)
            if hi > j + 1:
                U = Rj[:, self._cols(j, j + 1, hi)]
                for i in range(j + 1, hi):
                    Ri = self.R[i]
                    ci = self._cols(i, j, j + 1)
                    Lij = sla.lu_solve(D, Ri[:, ci].T, trans=1, check_finite=False).T
                    Ri[:, ci] = Lij
                    Ri[:, self._cols(i, j + 1, hi)] -= Lij @ U
            # The explicit inverse of the diagonal block replaces it in its block row (no
            # later step reads it): the substitutions run in worker threads, and
            # scipy.linalg's LAPACK wrappers gave corrupted results when called concurrently
            # on the CI machine (numpy's matmul does not). Kept beside the rows, the factors
            # and the inverses took 2 x 8 sum(r_j^2) bytes more.
            Rj[:, cj] = inverse
            del D, inverse

    def _inverse(self, j: int) -> np.ndarray:
        """Inverse of the diagonal block ``j`` (a view into its block row)."""
        return self.R[j][:, self._cols(j, j, j + 1)]

    def _lo(self, i: int) -> int:
        return max(0, i - self.b)

    def _cols(self, i: int, a: int, z: int) -> slice:
        """Columns of block row ``i`` holding column blocks ``a .. z-1``."""
        base = self.starts[self._lo(i)]
        return slice(int(self.starts[a] - base), int(self.starts[z] - base))

    @staticmethod
    def band_shape(starts, bandwidth: int, i: int) -> tuple:
        J = len(starts) - 1
        lo, hi = max(0, i - bandwidth), min(J, i + bandwidth + 1)
        return int(starts[i + 1] - starts[i]), int(starts[hi] - starts[lo])

    @staticmethod
    def memory_estimate(starts, bandwidth: int) -> int:
        """Bytes of the dense block rows."""
        J = len(starts) - 1
        return 8 * sum(int(np.prod(BlockBandedLU.band_shape(starts, bandwidth, i)))
                       for i in range(J))

    def solve(self, rhs: dict, lo: int, hi: int, tol: float = PRUNE) -> dict:
        """Solve for one group of right-hand sides.

        Parameters
        ----------
        rhs : dict
            ``{block j: dense (r_j, ncols)}`` for ``lo <= j < hi`` (missing blocks are zero);
            emptied, each block released as the forward substitution uses it (and each block
            of the forward solution as the backward one does: the three sets of blocks held
            at once took 270 MiB on Table 2 row 6 of seed 000).
        tol : float
            Blocks of the solution below ``tol`` times the largest right-hand side entry are
            dropped; the substitution stops after ``b`` such blocks beyond the support.

        Returns
        -------
        dict
            ``{block j: dense (r_j, ncols)}`` of the (pruned) solution.
        """
        J, b = self.J, self.b
        scale = max((float(np.abs(v).max()) for v in rhs.values() if v.size), default=0.0)
        if scale == 0.0:
            return {}
        ncols = next(iter(rhs.values())).shape[1]
        cut = tol * scale
        size = lambda j: int(self.starts[j + 1] - self.starts[j])

        def stacked(store, a, z):
            """Vertical stack of store[a..z-1] (zeros where missing), or None."""
            if not any(k in store for k in range(a, z)):
                return None
            return np.vstack([store[k] if k in store else np.zeros((size(k), ncols))
                              for k in range(a, z)])

        Z: dict = {}
        quiet = 0
        for j in range(lo, J):
            t = rhs.pop(j, None)
            a = max(lo, j - b)
            prev = stacked(Z, a, j) if j > a else None
            if prev is not None:
                u = self.R[j][:, self._cols(j, a, j)] @ prev
                t = -u if t is None else t - u
            if t is not None and np.abs(t).max() > cut:
                Z[j] = t
                quiet = 0
            else:
                quiet += 1
                if j >= hi and quiet >= b:
                    break
        if not Z:
            return {}
        Y: dict = {}
        quiet = 0
        for j in range(max(Z), -1, -1):
            t = Z.pop(j, None)
            z = min(J, j + b + 1)
            nxt = stacked(Y, j + 1, z) if z > j + 1 else None
            if nxt is not None:
                u = self.R[j][:, self._cols(j, j + 1, z)] @ nxt
                t = -u if t is None else t - u
            if t is not None:
                y = self._inverse(j) @ t
                if np.abs(y).max() > cut:
                    Y[j] = y
                    quiet = 0
                    continue
            quiet += 1
            if j < lo and quiet >= b:
                break
        return Y
