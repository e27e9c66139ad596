"""``simulate``: the Monte Carlo reference entry point (``docs/conventions.md``)."""

from __future__ import annotations

import math
import numbers
import time
import warnings

import numpy as np

from ..scene import Scene
from .backends import BACKENDS, resolve_backend
from .checks import check_edges, check_int, check_wi
from .estimates import TallySum
from .result import MCResult
from .stack import flatten
from .work import Walk, run_range, runner_device, split

__all__ = ["simulate", "MAX_BATCH", "DEFAULT_BATCH"]

#: Largest batch: keeps each batch's fixed-point sums (<= count * 2^32) inside int64.
MAX_BATCH = 1 << 30
DEFAULT_BATCH = {"warp-cpu": 1 << 17, "opencl": 1 << 19, "warp-cuda": 1 << 24}


def simulate(scene: Scene, wi, particles: int, mu_edges=(0.0, 1.0), phi_edges=(0.0, 2 * math.pi),
             backend: str = "auto", seed: int = 0, *, batch_size: int | None = None,
             target_stderr: float | None = None, progress: bool = False,
             max_steps: int = 100_000) -> MCResult:
    """Particle Monte Carlo estimate of the energy leaving a layer stack lit from ``wi``.

    Parameters
    ----------
    scene : layersim.Scene
        Validated scene; RGB scenes are simulated channel by channel with the same seed (common
        random numbers, so colour differences are less noisy than the channels themselves).
    wi : array_like, shape (3,)
        Unit direction toward the light, local frame; ``wi.z > 0`` lights the top, ``wi.z < 0``
        the bottom (only for a stack that is not opaque).
    particles : int
        Number of particles (per channel), > 0.
    mu_edges : array_like
        Increasing bin edges in ``|cos theta_o|`` within [0, 1].
    phi_edges : array_like
        Increasing bin edges in ``phi_o`` (radians) within [0, 2 pi].
    backend : {"auto", "warp-cpu", "warp-cuda", "opencl"}
        Where to run; ``"auto"`` picks the fastest present: CUDA, else OpenCL on a GPU or on a
        CPU device with enough compute units, else Warp's CPU device (see
        :mod:`layersim.montecarlo.backends`).
    seed : int
        0 <= seed < 2^64. The same seed gives bit-identical tallies on the same backend, for any
        ``batch_size`` (the random numbers of particle ``p`` depend only on ``(seed, p)`` and the
        tallies are integer sums).
    batch_size : int, optional
        Particles per kernel launch (default depends on the backend; at most 2^30).
    target_stderr : float, optional
        Stop after the first batch at which the standard errors of the reflectance,
        transmittance and absorbed fraction are all at most this value (per channel).
        ``particles`` is then the upper limit.
    progress : bool
        Show a tqdm progress bar (only on a terminal).
    max_steps : int
        Cap on the interactions of one walk; walks that reach it are reported in
        ``result.truncated`` (with a warning) and their energy counts as absorbed.

    Returns
    -------
    MCResult
        Fractions, bin energies and standard errors (see :class:`MCResult`).

    Raises
    ------
    ValueError
        Bad ``wi``, ``particles``, edges, ``backend`` name, seed or options.
    BackendUnavailableError
        The requested backend is not installed or has no device.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be a layersim.Scene (Scene.from_toml / Scene.from_dict), "
                        f"got {type(scene).__name__}")
    wi = check_wi(wi, scene)
    particles = check_int("particles", particles, 1, None)
    mu_edges = check_edges("mu_edges", mu_edges, 1.0, "|cos theta_o|")
    phi_edges = check_edges("phi_edges", phi_edges, 2 * math.pi, "phi_o (radians)")
    if not isinstance(backend, str) or backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; expected one of {', '.join(BACKENDS)}")
    seed = check_int("seed", seed, 0, (1 << 64) - 1)
    max_steps = check_int("max_steps", max_steps, 1, (1 << 31) - 1)
    if batch_size is not None:
        batch_size = check_int("batch_size", batch_size, 1, MAX_BATCH)
    if target_stderr is not None:
        if not (isinstance(target_stderr, numbers.Real) and math.isfinite(target_stderr)
                and target_stderr > 0):
            raise ValueError(f"target_stderr must be a positive number, got {target_stderr!r}")

    name = resolve_backend(backend)
    batch = batch_size or DEFAULT_BATCH[name]
    n_mu, n_phi = len(mu_edges) - 1, len(phi_edges) - 1
    incident = 0 if wi[2] > 0 else 1

    t0 = time.perf_counter()
    per_channel = []
    device = ""
    used = None                     # the walk's code paths any channel needs
    for c in range(scene.channels):
        walk = Walk(scene.channel(c), tuple(wi), tuple(mu_edges), tuple(phi_edges), seed,
                    max_steps, name)
        features = flatten(walk.scene).features
        used = features if used is None else used | features
        device = runner_device(walk)
        per_channel.append(_run(walk, particles, batch, target_stderr, progress,
                                f"{scene.name}" + (f"[{'RGB'[c]}]" if scene.channels > 1 else "")))
    seconds = time.perf_counter() - t0

    fields = {}
    for key, get in (("reflectance", lambda s: s.side(incident)),
                     ("transmittance", lambda s: s.side(1 - incident)),
                     ("absorbed", lambda s: s.absorbed())):
        vals = [get(s) for s in per_channel]
        fields[key] = _stack([v[0] for v in vals])
        fields[key + "_stderr"] = _stack([v[1] for v in vals])
    bins, bins_err = {}, {}
    for side, s in (("top", 0), ("bottom", 1)):
        vals = [t.bins(s, (n_mu, n_phi)) for t in per_channel]
        bins[side] = _stack([v[0] for v in vals])
        bins_err[side] = _stack([v[1] for v in vals])
    truncated = [t.truncated for t in per_channel]
    if any(truncated):
        frac = max(t.truncated / t.particles for t in per_channel)
        warnings.warn(f"{sum(truncated)} walk(s) reached max_steps={max_steps} and were stopped "
                      f"(up to {frac:.2e} of the particles; their energy counts as absorbed). "
                      "Raise max_steps if this matters.", RuntimeWarning, stacklevel=2)
    return MCResult(
        **fields, bins=bins, bins_stderr=bins_err,
        particles=_stack([t.particles for t in per_channel]),
        events=_stack([t.events for t in per_channel]),
        truncated=_stack(truncated), backend=name, device=device, seconds=seconds, seed=seed,
        wi=wi, mu_edges=mu_edges, phi_edges=phi_edges, left_out=tuple(used.left_out()))


def _run(walk: Walk, particles: int, batch: int, target, progress: bool, label) -> TallySum:
    from tqdm.auto import tqdm
    total = TallySum(walk.n_bins)
    bar = tqdm(total=particles, unit="paths", unit_scale=True, desc=label,
               disable=None if progress else True, leave=False)
    try:
        for r in split(walk, 0, particles, batch):
            total = total + run_range(r)
            bar.update(r.count)
            if target is not None and total.particles >= 2:
                errs = (total.side(0)[1], total.side(1)[1], total.absorbed()[1])
                if max(errs) <= target:
                    break
    finally:
        bar.close()
    return total


def _stack(values):
    """A scalar for one channel, else an array with a trailing channel axis."""
    if len(values) == 1:
        v = values[0]
        return v if np.ndim(v) else (int(v) if isinstance(v, (int, np.integer)) else float(v))
    return np.stack([np.asarray(v) for v in values], axis=-1)
