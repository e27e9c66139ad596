"""Helpers of tests/test_mitsuba_plugin.py: the Mitsuba variant under test and batched calls
that work in scalar variants (one ray per call) and JIT variants (one wavefront) alike."""

import numpy as np

from layersim.mitsuba.llvm import find_libllvm  # noqa: F401  (re-exported for the tests)


def set_variant(mi, preferred=("llvm_ad_rgb", "scalar_rgb")) -> str:
    """Set the first variant of ``preferred`` that starts here and return its name."""
    for v in preferred:
        try:
            mi.set_variant(v)
            mi.Float(0.0)                      # starts the backend: raises without LLVM
            return v
        except Exception:                      # LLVM missing: Dr.Jit raises on first use
            continue
    raise RuntimeError(f"none of {preferred} starts")


def grid(side: int, n_theta=24, n_phi=48, theta_max=85.0) -> np.ndarray:
    """Directions on a regular (theta, phi) grid of one hemisphere (``side`` +1 or -1)."""
    t = np.radians(np.linspace(1.0, theta_max, n_theta))
    p = np.linspace(0.0, 2 * np.pi, n_phi, endpoint=False)
    T, P = np.meshgrid(t, p, indexing="ij")
    v = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), side * np.cos(T)], -1)
    return v.reshape(-1, 3)


def interaction(mi, wi: np.ndarray):
    """A ``SurfaceInteraction3f`` wavefront (or scalar) with ``si.wi`` from rows (N, 3)."""
    import drjit as dr
    if mi.variant().startswith("scalar"):
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wi = mi.Vector3f(*map(float, wi[0]))
        if "spectral" in mi.variant():
            si.wavelengths = [450.0, 520.0, 600.0, 680.0]
        return si
    si = dr.zeros(mi.SurfaceInteraction3f, len(wi))
    si.wi = mi.Vector3f(np.ascontiguousarray(wi.T, np.float32))
    return si


def eval_pdf(mi, bsdf, wi: np.ndarray, wo: np.ndarray, ctx=None):
    """``bsdf.eval`` (N, channels) and ``bsdf.pdf`` (N,) at rows of ``wi``, ``wo``."""
    ctx = ctx or mi.BSDFContext()
    if mi.variant().startswith("scalar"):
        out = [(np.array(bsdf.eval(ctx, interaction(mi, a[None]), mi.Vector3f(*map(float, b)))),
                float(bsdf.pdf(ctx, interaction(mi, a[None]), mi.Vector3f(*map(float, b)))))
               for a, b in zip(wi, wo)]
        return np.array([o[0] for o in out]).reshape(len(wi), -1), np.array([o[1] for o in out])
    si = interaction(mi, wi)
    w = mi.Vector3f(np.ascontiguousarray(wo.T, np.float32))
    return np.array(bsdf.eval(ctx, si, w)).T, np.array(bsdf.pdf(ctx, si, w))


def sample(mi, bsdf, wi: np.ndarray, u1: np.ndarray, u2: np.ndarray, ctx=None) -> dict:
    """``bsdf.sample`` at rows of ``wi`` (N, 3), ``u1`` (N,), ``u2`` (N, 2) as numpy."""
    ctx = ctx or mi.BSDFContext()
    if mi.variant().startswith("scalar"):
        res = [bsdf.sample(ctx, interaction(mi, a[None]), float(x), mi.Point2f(*map(float, y)))
               for a, x, y in zip(wi, u1, u2)]
        return {"wo": np.array([np.array(bs.wo) for bs, _ in res]),
                "pdf": np.array([float(bs.pdf) for bs, _ in res]),
                "eta": np.array([float(bs.eta) for bs, _ in res]),
                "type": np.array([int(bs.sampled_type) for bs, _ in res]),
                "weight": np.array([np.array(w) for _, w in res]).reshape(len(wi), -1)}
    bs, w = bsdf.sample(ctx, interaction(mi, wi), mi.Float(u1.astype(np.float32)),
                        mi.Point2f(np.ascontiguousarray(u2.T, np.float32)))
    return {"wo": np.array(bs.wo).T, "pdf": np.array(bs.pdf), "eta": np.array(bs.eta),
            "type": np.array(bs.sampled_type), "weight": np.array(w).T}
