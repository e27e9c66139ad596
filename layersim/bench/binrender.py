"""Render an isotropic material on a sphere from its bin energies (``layersim bench --render``).

A unit sphere is seen by an orthographic camera from the unit direction ``view`` (world space,
``y`` up) under an environment. The material enters only through a table of bin energies
``E_b(theta_i)`` (the fraction of the power of a beam from ``wi`` leaving into the bin
``b = (mu_o in [mu_lo, mu_hi), phi_o in [phi_lo, phi_hi))`` of the top side, ``wi`` at azimuth 0),
tabulated at a few incidence angles: the solver's :meth:`layersim.solved.bsdf.BSDF.bin_energies`
and the Monte Carlo walk's bins go through the same code, so that the difference of two
images shows the difference of their tables only.

The piecewise-constant BSDF of a table is the bin average of ``f cos theta_o``::

    fbar(wi, wo) = E_b(wi) / Omega_b        (wo in bin b; 1/sr)
    Omega_b = int_b cos theta dw = (mu_hi^2 - mu_lo^2) (phi_hi - phi_lo) / 2     (sr)

since ``E_b(wi) = int_b f(wi, wo) cos theta_o dw_o`` (the reflected exitance into the bin over
the irradiance of a collimated beam). The radiance reflected toward the camera, direction ``v``
in the local frame, is (reflection is reciprocal, ``f(l, v) = f(v, l)``, so the table lit from
``v`` serves for light arriving from every ``l``)::

    L(v) = int_H f(l, v) L_env(l) cos theta_l dw_l  ~=  sum_b E_b(v) Lbar_b(v)
    Lbar_b = (1 / Omega_b) int_b L_env(l) cos theta_l dw_l      (radiance, W / (m^2 sr))

``Lbar_b`` is the projected-solid-angle average of the environment over bin ``b``, the bin
turned about the normal so that its azimuth 0 is the azimuth of ``v`` (isotropic materials
only: their bins depend on ``phi_o - phi_i`` alone). A uniform environment of radiance 1
gives ``L(v) = sum_b E_b(v) = R(v)``, the albedo, whatever the bins; a Lambertian table
(``E_b = rho Omega_b / pi``) gives ``rho / pi`` times the irradiance, whatever the bins
(tests/test_binrender.py checks both). The integral over a bin is taken on a stratified grid
uniform in ``mu^2`` and ``phi`` (equal projected solid angle per point) for the smooth part
of the environment, and exactly for point sources (a small sun sampled as points): each adds
``E_j cos theta_j / Omega_b`` to the bin holding its direction. ``E_b(v)`` is interpolated
linearly in ``cos theta_v`` between the table's angles, constant beyond its extremes.
References: the bin energies of ``docs/conventions.md``; the reciprocity of reflection that
lets a table lit from ``v`` shade the light arriving at ``v`` (Veach 1997, PhD thesis,
Stanford, chapter 6).
"""

from __future__ import annotations

import numpy as np

#: Pixels shaded per block (bounds the (pixels, bins, subsamples) work arrays to ~3e6 values).
BLOCK_VALUES = 3_000_000


def frame(view) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Image axes of an orthographic camera looking along ``-view`` with world ``y`` up:
    ``(right, up, view)``, unit vectors of shape (3,)."""
    c = np.asarray(view, dtype=float)
    c = c / np.linalg.norm(c)
    right = np.cross([0.0, 1.0, 0.0], c)
    right /= np.linalg.norm(right)
    return right, np.cross(c, right), c


def sphere_pixels(resolution: int, view) -> tuple[np.ndarray, np.ndarray]:
    """The unit sphere filling a ``resolution`` x ``resolution`` orthographic image.

    Returns
    -------
    mask : ndarray of bool, shape (resolution, resolution)
        Pixels whose centre sees the sphere (rows from the top of the image).
    normals : ndarray, shape (P, 3)
        World normals at those pixels, in ``mask``'s row-major order.
    """
    right, up, c = frame(view)
    x = (np.arange(resolution) + 0.5) / resolution * 2 - 1
    X, Y = np.meshgrid(x, -x)
    r2 = X ** 2 + Y ** 2
    mask = r2 < 1.0
    z = np.sqrt(1.0 - r2[mask])
    normals = X[mask][:, None] * right + Y[mask][:, None] * up + z[:, None] * c
    return mask, normals


def local_frames(normals, view) -> tuple[np.ndarray, np.ndarray]:
    """Tangents ``t`` and bitangents ``b = n x t`` (P, 3) such that the view direction has
    local azimuth 0 (``t`` along its projection on the tangent plane; any tangent where the
    view is the normal)."""
    right, _, c = frame(view)
    t = c - (normals @ c)[:, None] * normals
    norm = np.linalg.norm(t, axis=1)
    flat = norm < 1e-9
    t[flat] = right - (normals[flat] @ right)[:, None] * normals[flat]
    t /= np.linalg.norm(t, axis=1)[:, None]
    return t, np.cross(normals, t)


def projected_solid_angles(mu_edges, phi_edges) -> np.ndarray:
    """``Omega_b`` (sr) of the bins, shape (n_mu * n_phi,), mu-major (module docstring)."""
    mu, phi = np.asarray(mu_edges, float), np.asarray(phi_edges, float)
    return (0.5 * np.outer(np.diff(mu ** 2), np.diff(phi))).ravel()


def bin_subsamples(mu_edges, phi_edges, per_axis: int) -> np.ndarray:
    """Local directions (n_bins, per_axis ** 2, 3) stratified in each bin, uniform in ``mu^2``
    and ``phi``: each carries the same projected solid angle of its bin."""
    mu, phi = np.asarray(mu_edges, float), np.asarray(phi_edges, float)
    u = (np.arange(per_axis) + 0.5) / per_axis
    m2 = mu[:-1, None] ** 2 + np.diff(mu ** 2)[:, None] * u           # (n_mu, S)
    p = phi[:-1, None] + np.diff(phi)[:, None] * u                     # (n_phi, S)
    M = np.sqrt(m2)[:, None, :, None]
    P = p[None, :, None, :]
    s = np.sqrt(np.maximum(1.0 - M ** 2, 0.0))
    d = np.stack(np.broadcast_arrays(s * np.cos(P), s * np.sin(P), M), axis=-1)
    return d.reshape(len(mu) - 1, len(phi) - 1, per_axis * per_axis, 3).reshape(
        -1, per_axis * per_axis, 3)


def environment_bins(normals, view, mu_edges, phi_edges, env, sources=None,
                     per_axis: int = 4) -> np.ndarray:
    """``Lbar_b`` per pixel: the environment averaged over each bin turned to the pixel's
    frame (module docstring), shape (P, n_bins, channels of ``env``).

    Parameters
    ----------
    normals : ndarray (P, 3)
        World normals (:func:`sphere_pixels`).
    view : array_like (3,)
        Unit direction toward the camera, world space.
    mu_edges, phi_edges : array_like
        The table's bin edges (|cos theta_o| in [0, 1], phi_o in [0, 2 pi]).
    env : callable
        Radiance of the smooth part of the environment, world directions (..., 3) ->
        (..., C).
    sources : tuple (directions (J, 3), weights (J, C)), optional
        Point sources: unit world directions and their irradiance at normal incidence
        (radiance times solid angle, W / m^2).
    per_axis : int
        Subsamples per bin and axis for the smooth part (``per_axis ** 2`` per bin).
    """
    t, b = local_frames(normals, view)
    sub = bin_subsamples(mu_edges, phi_edges, per_axis)               # (B, S, 3)
    block = max(1, BLOCK_VALUES // (sub.shape[0] * sub.shape[1] * 3))
    out = []
    for i in range(0, len(normals), block):
        sl = slice(i, i + block)
        world = (sub[None, ..., 0:1] * t[sl, None, None] + sub[None, ..., 1:2] * b[sl, None, None]
                 + sub[None, ..., 2:3] * normals[sl, None, None])
        out.append(np.asarray(env(world)).mean(axis=2))
    lbar = np.concatenate(out, axis=0)
    if sources is not None:
        lbar = lbar + _source_bins(normals, t, b, mu_edges, phi_edges, *sources)
    return lbar


def _source_bins(normals, t, b, mu_edges, phi_edges, dirs, weights) -> np.ndarray:
    """Point sources' share of ``Lbar_b``: ``E_j cos theta_j / Omega_b`` added to the bin
    holding each source's direction (P, n_bins, C)."""
    mu_edges, phi_edges = np.asarray(mu_edges, float), np.asarray(phi_edges, float)
    n_mu, n_phi = len(mu_edges) - 1, len(phi_edges) - 1
    weights = np.atleast_2d(np.asarray(weights, float))
    mu = normals @ dirs.T                                              # (P, J)
    phi = np.mod(np.arctan2(b @ dirs.T, t @ dirs.T), 2 * np.pi)
    i = np.clip(np.searchsorted(mu_edges, mu, side="right") - 1, 0, n_mu - 1)
    k = np.clip(np.searchsorted(phi_edges, phi, side="right") - 1, 0, n_phi - 1)
    inside = (mu > mu_edges[0]) & (mu <= mu_edges[-1]) & (phi >= phi_edges[0]) & (
        phi < phi_edges[-1])
    omega = projected_solid_angles(mu_edges, phi_edges)
    bins = i * n_phi + k
    out = np.zeros((len(normals), n_mu * n_phi, weights.shape[-1]))
    rows = np.broadcast_to(np.arange(len(normals))[:, None], mu.shape)
    add = np.where(inside, mu, 0.0)[..., None] * weights[None] / omega[bins][..., None]
    np.add.at(out, (rows, bins), add)
    return out


def interpolation(mu_table, mu_view) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Linear interpolation in ``cos theta`` between the table's angles, constant beyond
    them: indices ``(lo, hi)`` into the table and the weight ``w`` of ``hi``, each (P,)."""
    mu_table = np.asarray(mu_table, float)
    order = np.argsort(mu_table)
    m = mu_table[order]
    x = np.clip(np.asarray(mu_view, float), m[0], m[-1])
    if len(m) == 1:
        first = np.full(x.shape, order[0])
        return first, first, np.zeros(x.shape)
    j = np.clip(np.searchsorted(m, x, side="right") - 1, 0, len(m) - 2)
    return order[j], order[j + 1], (x - m[j]) / (m[j + 1] - m[j])


def shade(table, lbar, lo, hi, w) -> np.ndarray:
    """``sum_b E_b(v) Lbar_b`` per pixel (P, C).

    Parameters
    ----------
    table : ndarray (K, n_bins) or (K, n_bins, C_material)
        Bin energies at the K table angles (a one-channel material lights every colour of
        the environment alike).
    lbar : ndarray (P, n_bins, C)
        :func:`environment_bins`.
    lo, hi, w : ndarray (P,)
        :func:`interpolation`.
    """
    table = np.asarray(table, float)
    if table.ndim == 2:
        table = table[..., None]
    e = (1 - w)[:, None, None] * table[lo] + w[:, None, None] * table[hi]
    return np.einsum("pbc,pbc->pc", np.broadcast_to(e, lbar.shape), lbar)


def shade_variance(stderr, lbar, lo, hi, w) -> np.ndarray:
    """The variance of :func:`shade` from independent per-bin standard errors ``stderr``
    (shape of ``table``), (P, C): ``sum_b (weight_k sigma_kb Lbar_b)^2`` over both angles."""
    s2 = np.asarray(stderr, float) ** 2
    if s2.ndim == 2:
        s2 = s2[..., None]
    v = ((1 - w) ** 2)[:, None, None] * s2[lo] + (w ** 2)[:, None, None] * s2[hi]
    return np.einsum("pbc,pbc->pc", np.broadcast_to(v, lbar.shape), lbar ** 2)


def luminance_stderr(stderr, lbar, lo, hi, w) -> np.ndarray:
    """Standard error (P,) of the luminance of :func:`shade` from per-bin standard errors
    ``stderr`` (shape of its ``table``): bins, and the channels of an RGB table, taken as
    independent (:func:`shade_variance` of each channel's luminance share)."""
    stderr = np.asarray(stderr, float)
    y = np.array([0.2126, 0.7152, 0.0722])
    if stderr.ndim == 2 or stderr.shape[-1] == 1:
        share = (lbar @ y)[..., None] if lbar.shape[-1] == 3 else lbar
    else:
        share = lbar * y
    return np.sqrt(shade_variance(stderr, share, lo, hi, w).sum(axis=-1))


def to_image(mask, values, background=np.nan) -> np.ndarray:
    """Pixel values (P, C) back to an image (H, W, C), ``background`` off the sphere."""
    img = np.full(mask.shape + (values.shape[-1],), background, dtype=float)
    img[mask] = values
    return img


def luminance(rgb) -> np.ndarray:
    """Rec. 709 luminance of linear RGB (..., 3) (one channel: itself)."""
    rgb = np.asarray(rgb, float)
    if rgb.shape[-1] == 1:
        return rgb[..., 0]
    return rgb @ np.array([0.2126, 0.7152, 0.0722])
