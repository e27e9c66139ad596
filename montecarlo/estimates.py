"""Integer tallies -> energy fractions and their standard errors.

The kernel sums, per side and bin, ``W1 = sum round(w 2^32)`` and ``W2 = sum round(w^2 2^32)``
over the particles leaving there (each particle leaves at most once). With ``N`` particles the
estimate of a fraction is ``W1 / (N 2^32)`` and its standard error comes from the per-particle
second moment (particles are independent and identically distributed):

    stderr = sqrt((W2 / (N 2^32) - mean^2) / (N - 1)).

The absorbed fraction is ``1 - R - T`` per particle; it is computed from the integers, so a run in
which every particle leaves with weight 1 reports exactly 0, and its variance is
``E[(w_top + w_bottom)^2] - (R + T)^2``.
"""

from __future__ import annotations

import numpy as np

SCALE = 2 ** 32


class TallySum:
    """Exact (Python integer) running sums of the batch tallies of one run."""

    def __init__(self, n_bins: int):
        self.w = np.zeros((2, 2, n_bins), dtype=object)   # side, moment, bin
        self.w[...] = 0
        self.particles = 0
        self.events = 0
        self.truncated = 0

    def add(self, tally: np.ndarray, counters: np.ndarray, count: int) -> None:
        self.w = self.w + tally.astype(object)
        self.particles += int(count)
        self.events += int(counters[0])
        self.truncated += int(counters[1])

    # ---- estimates ------------------------------------------------------------------------

    def _mean_err(self, w1, w2):
        n = self.particles
        w1 = np.asarray(w1, dtype=object)
        mean = np.asarray(w1 / (n * SCALE), dtype=np.float64)
        m2 = np.asarray(np.asarray(w2, dtype=object) / (n * SCALE), dtype=np.float64)
        if n < 2:
            return mean, np.full_like(mean, np.nan)
        return mean, np.sqrt(np.maximum(m2 - mean * mean, 0.0) / (n - 1))

    def side(self, s: int):
        """(fraction, stderr) leaving at side ``s`` (0 top, 1 bottom)."""
        m, e = self._mean_err(self.w[s, 0, -1], self.w[s, 1, -1])
        return float(m), float(e)

    def absorbed(self):
        n = self.particles
        left = n * SCALE - self.w[0, 0, -1] - self.w[1, 0, -1]
        mean = float(left / (n * SCALE))
        out = self.w[0, 0, -1] + self.w[1, 0, -1]
        m2 = float((self.w[0, 1, -1] + self.w[1, 1, -1]) / (n * SCALE))
        m1 = float(out / (n * SCALE))
        err = np.sqrt(max(m2 - m1 * m1, 0.0) / (n - 1)) if n > 1 else float("nan")
        return mean, float(err)

    def bins(self, s: int, shape: tuple):
        """(energies, stderr), each of ``shape`` (n_mu, n_phi), for side ``s``."""
        m, e = self._mean_err(self.w[s, 0, :-1], self.w[s, 1, :-1])
        return m.reshape(shape), e.reshape(shape)
