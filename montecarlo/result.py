"""The result of :func:`layersim.montecarlo.simulate`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MCResult:
    """Monte Carlo estimates for one incident direction.

    Energy fractions follow ``docs/conventions.md``: ``reflectance`` is the fraction of the incident
    power leaving on the side the light came from (the top for ``wi.z > 0``, the bottom for
    ``wi.z < 0``), ``transmittance`` the fraction leaving on the other side, ``absorbed`` the rest
    (including energy lost by the single-scattering microfacet model and by truncated walks).
    Every estimate has a standard error ``*_stderr`` from per-particle second moments.

    For a monochromatic scene the fractions are floats and each bin array has shape
    ``(n_mu, n_phi)``; for an RGB scene (``scene.channels == 3``) every quantity gains a trailing
    channel axis of length 3 (fractions: shape (3,); bins: (n_mu, n_phi, 3)).

    Attributes
    ----------
    reflectance, transmittance, absorbed : float or ndarray
    reflectance_stderr, transmittance_stderr, absorbed_stderr : float or ndarray
    bins : dict
        ``bins["top"]``, ``bins["bottom"]``: fraction of the incident power leaving into each
        solid-angle bin ``[mu_edges[i], mu_edges[i+1]) x [phi_edges[j], phi_edges[j+1])`` of
        ``|cos theta_o|`` and ``phi_o`` (radians in [0, 2 pi), local frame) of the outgoing
        direction on that side. Energy outside the edges' range is in the totals only.
    bins_stderr : dict
        Standard errors of ``bins``, same keys and shapes.
    particles : int or ndarray of int
        Particles simulated (per channel); fewer than requested after an early stop.
    events : int or ndarray of int
        Scattering events (medium scatterings and interface interactions).
    truncated : int or ndarray of int
        Walks stopped at ``max_steps`` (their energy counts as absorbed).
    backend : str
        The backend that ran (``"warp-cpu"``, ``"warp-cuda"``, ``"opencl"``).
    device : str
        The device it ran on.
    seconds : float
        Wall-clock time of the walk (all channels, including a first compilation).
    seed : int
    wi : ndarray, shape (3,)
    mu_edges, phi_edges : ndarray
    left_out : tuple of str
        The walk's code paths that the kernel was built without, because the scene does not
        use them (:class:`layersim.kernels.walk.Features`).
    """

    reflectance: float | np.ndarray
    transmittance: float | np.ndarray
    absorbed: float | np.ndarray
    reflectance_stderr: float | np.ndarray
    transmittance_stderr: float | np.ndarray
    absorbed_stderr: float | np.ndarray
    bins: dict
    bins_stderr: dict
    particles: int | np.ndarray
    events: int | np.ndarray
    truncated: int | np.ndarray
    backend: str
    device: str
    seconds: float
    seed: int
    wi: np.ndarray
    mu_edges: np.ndarray
    phi_edges: np.ndarray
    left_out: tuple = ()

    def z_scores(self, side: str, values) -> np.ndarray:
        """Distances, in standard errors, of ``values`` (bin energies of the same bins from
        another method, e.g. a solver's :meth:`layersim.solved.bsdf.BSDF.bin_energies`; shape of
        ``bins[side]``) from these bins, over the populated bins (either nonzero), flattened.

        An empty or nearly empty bin has a tiny sample standard error; its real spread is
        Poisson, variance >= E / N for a bin that receives energy E per path, so ``max(values,
        0) / particles`` is added to the variance."""
        values = np.asarray(values, float)
        est = np.asarray(self.bins[side], float)
        sig = np.sqrt(np.asarray(self.bins_stderr[side], float) ** 2
                      + np.maximum(values, 0.0) / np.asarray(self.particles, float))
        populated = (est > 0) | (values > 1e-12)
        return (np.abs(values - est) / np.maximum(sig, 1e-15))[populated]

    def summary(self) -> str:
        """A few lines for reports and the command line."""
        def fmt(x, e):
            x, e = np.atleast_1d(x), np.atleast_1d(e)
            return ", ".join(f"{a:.6f} +- {b:.1e}" for a, b in zip(x, e))
        return (f"Monte Carlo ({self.backend}, {self.device}): {np.sum(self.particles):,} "
                f"particles in {self.seconds:.2f} s, seed {self.seed}\n"
                f"  R = {fmt(self.reflectance, self.reflectance_stderr)}\n"
                f"  T = {fmt(self.transmittance, self.transmittance_stderr)}\n"
                f"  A = {fmt(self.absorbed, self.absorbed_stderr)}"
                + (f"\n  kernel built without: {', '.join(self.left_out)}" if self.left_out
                   else ""))
