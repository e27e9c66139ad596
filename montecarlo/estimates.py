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

    def __add__(self, other: "TallySum") -> "TallySum":
        """The tally of two disjoint path ranges of the same walk (exact)."""
        if self.w.shape != other.w.shape:
            raise ValueError(f"tallies of different bins cannot be added: {self.w.shape[2] - 1} "
                             f"and {other.w.shape[2] - 1} bins per side")
        out = TallySum(self.w.shape[2])
        out.w = self.w + other.w
        out.particles = self.particles + other.particles
        out.events = self.events + other.events
        out.truncated = self.truncated + other.truncated
        return out

    # ---- exact storage --------------------------------------------------------------------

    #: 64-bit words per stored integer: sums reach particles * 2^32 < 2^96 for any 64-bit count.
    WORDS = 3

    def to_words(self) -> tuple[np.ndarray, np.ndarray]:
        """The sums as little-endian uint64 words (for files): ``w`` of shape (2, 2, n_bins, 3)
        and ``(particles, events, truncated)`` of shape (3, 3)."""
        def words(values):
            flat = np.asarray(values, dtype=object).ravel()     # Python ints, elementwise
            if np.any(flat < 0):
                raise ValueError("negative tally: not a sum of the walk's fixed-point weights")
            out = np.empty(flat.shape + (self.WORDS,), dtype=np.uint64)
            for k in range(self.WORDS):
                out[:, k] = ((flat >> (64 * k)) & 0xFFFFFFFFFFFFFFFF).astype(np.uint64)
            return out.reshape(np.shape(values) + (self.WORDS,))
        return words(self.w), words(np.array([self.particles, self.events, self.truncated],
                                             dtype=object))

    @classmethod
    def from_words(cls, w_words: np.ndarray, counts_words: np.ndarray) -> "TallySum":
        """Inverse of :meth:`to_words`."""
        def ints(words):
            words = np.asarray(words, dtype=np.uint64)
            out = np.zeros(words.shape[:-1], dtype=object)
            out[...] = 0
            for k in range(words.shape[-1]):
                out = out + (words[..., k].astype(object) << (64 * k))
            return out
        w = ints(w_words)
        total = cls(w.shape[2])
        total.w = w
        total.particles, total.events, total.truncated = (int(v) for v in ints(counts_words))
        return total

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
