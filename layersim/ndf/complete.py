"""NDF completion by merging rotated partial NDFs (Wang et al. 2008 sec. 5.2, eq. 13-17).

One view determines D only over the region Omega of eq. (10). Other samples of the same material
(other surface points, other specimens, other views) whose microstructure is rotated about the
normal reveal other parts of it. Each candidate is rotated by every azimuth (the exemplar set,
eq. 13), compared with the current NDF over the overlap of their domains by the
confidence-weighted, scale-normalised distance of eq. (15), and the best one (eq. 14) is merged
with confidence weights (eq. 16-17). The paper runs this over the exemplars of a whole surface; here
the candidates are the partial NDFs given, each merged at most once at its best rotation. As in the
paper, candidates overlapping the current domain by 50-85 % are preferred (the overlap fixes the
rotation; the rest extends the domain), but the rotation is searched over all shifts with enough
overlap: with a few candidates, forcing it into the band biases it.

What single-view data never reach stays marked: the normals tilted beyond about
(theta_view + theta_light_max) / 2 from the normal are outside every view's Omega. Such a region is
filled only on request (:func:`fill_uncovered`, the push-pull interpolation the paper mentions),
and the filled solid angle is reported. For a single sample, where no other partial NDF exists,
:func:`symmetry_images` gives the images of a symmetry the user states (e.g. point symmetry of a
brushed surface); nothing is assumed otherwise.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.optimize import minimize_scalar
from scipy.sparse.linalg import spsolve

from .fit import PartialNDF
from .halfgrid import SYMMETRIES


def _distance(grid, d1, w1, d2, w2):
    """Eq. (15): confidence-weighted L2 distance of the two NDFs normalised over their overlap,
    and the scales s1, s2 (inf, nan, nan when they do not overlap)."""
    ov = (w1 > 0) & (w2 > 0)
    wts = grid.weights * ov
    s1, s2 = np.sum(wts * np.nan_to_num(d1)), np.sum(wts * np.nan_to_num(d2))
    if not ov.any() or s1 <= 0 or s2 <= 0:
        return np.inf, np.nan, np.nan
    ww = wts * w1 * w2
    diff = np.nan_to_num(d1) / s1 - np.nan_to_num(d2) / s2
    return float(np.sum(ww * diff ** 2) / np.sum(ww)), s1, s2


def _overlap(grid, w_cur, w_cand):
    """Fraction of the candidate's solid angle that the current domain already covers, and the
    solid angle it adds."""
    wts = grid.weights
    cand = np.sum(wts * (w_cand > 0))
    both = np.sum(wts * ((w_cand > 0) & (w_cur > 0)))
    return (both / cand if cand > 0 else 0.0), cand - both


def _rotations(grid, d, w, cand, min_overlap):
    """Eq. (14) for one candidate: the local minima over the grid's azimuthal shifts of the
    eq.-(15) distance, among shifts overlapping the current domain by at least ``min_overlap``
    and extending it. Returns a list of (distance, shift, overlap fraction, solid angle added)."""
    n = grid.n_phi
    dist, frac, gain = np.full(n, np.inf), np.zeros(n), np.zeros(n)
    for s in range(n):
        wc = np.roll(cand.w, -s, axis=1)
        frac[s], gain[s] = _overlap(grid, w, wc)
        if frac[s] >= min_overlap and gain[s] > 0:
            dist[s] = _distance(grid, d, w, np.roll(cand.d, -s, axis=1), wc)[0]
    mins = (dist <= np.roll(dist, 1)) & (dist <= np.roll(dist, -1)) & np.isfinite(dist)
    return [(dist[s], s, frac[s], gain[s]) for s in np.flatnonzero(mins)]


def _refine(grid, d, w, cand, shift):
    """The rotation (radians) of least eq.-(15) distance within one grid step of ``shift``."""
    step = 2.0 * np.pi / grid.n_phi

    def cost(a):
        return _distance(grid, d, w, *_rotated(grid, cand, a))[0]

    r = minimize_scalar(cost, bounds=((shift - 1) * step, (shift + 1) * step), method="bounded",
                        options={"xatol": 1e-3 * step})
    return (r.fun, r.x) if r.fun <= cost(shift * step) else (cost(shift * step), shift * step)


def _rotated(grid, part, angle):
    """D and W rotated by ``angle`` (eq. 13); nodes next to the domain's edge, where the
    interpolated D is NaN, get W = 0 so that they carry no weight."""
    d = grid.rotate(part.d, angle)
    return d, np.where(np.isfinite(d), grid.rotate(part.w, angle), 0.0)


def merge(grid, d, w, d2, w2, s1=1.0, s2=1.0):
    """Eq. (16-17): confidence-weighted merge of D2 (scaled by s1/s2) into D; W takes the max.
    NaN (undetermined) nodes of either side carry no weight."""
    a = np.where((w > 0) & np.isfinite(d), w, 0.0)
    b = np.where((w2 > 0) & np.isfinite(d2), w2, 0.0)
    num = a * np.nan_to_num(d) + (s1 / s2) * b * np.nan_to_num(d2)
    tot = a + b
    return np.where(tot > 0, num / np.where(tot > 0, tot, 1.0), np.nan), np.maximum(a, b)


def complete_ndf(target: PartialNDF, others, overlap=(0.5, 0.85),
                 min_overlap: float = 0.3) -> PartialNDF:
    """Complete ``target`` from the partial NDFs ``others`` (Wang et al. 2008 eq. 13-17).

    Parameters
    ----------
    target : PartialNDF whose frame the result keeps
    others : sequence of PartialNDF on the same grid, of the same material, in any azimuthal
        rotation
    overlap : (min, max) fraction of a candidate's domain overlapping the current one that the
        paper requires of a merge; candidates whose best rotation lies in this band are merged
        first. With a handful of candidates (not a surface's worth of exemplars) the true
        rotation of a candidate may overlap more or less, so the rotation itself is searched
        over every shift overlapping by at least ``min_overlap``, and candidates outside the
        band are merged afterwards (noted).

    Returns
    -------
    PartialNDF with the merged D (in the target's scale) and W; ``notes`` lists each merge
    (candidate, rotation, distance, overlap) and the coverage reached.
    """
    grid = target.grid
    if any(o.grid != grid for o in others):
        raise ValueError("completion needs partial NDFs on the same (theta, phi) grid")
    d, w = target.d.copy(), target.w.copy()
    notes = list(target.notes)
    left = dict(enumerate(others))
    while left and not np.all(w > 0):
        found = _pick(grid, d, w, left, overlap, min_overlap)
        if found is None:
            notes.append(f"{len(left)} partial NDF(s) left unmerged: none overlaps the current "
                         f"domain by {100 * min_overlap:g} % or more and extends it")
            break
        dist, angle, frac, j = found
        cand = left.pop(j)
        dc, wc = _rotated(grid, cand, angle)
        _, s1, s2 = _distance(grid, d, w, dc, wc)
        d, w = merge(grid, d, w, dc, wc, s1, s2)
        band = "" if overlap[0] <= frac <= overlap[1] else ", outside the %g-%g %% band" % (
            100 * overlap[0], 100 * overlap[1])
        notes.append(f"merged partial NDF {j + 1} rotated by {np.degrees(angle):.2f} deg "
                     f"(distance {dist:.3g}, overlap {100 * frac:.0f} %{band})")
    out = PartialNDF(grid, d, w, target.residual, target.channel_scale, target.channels, notes)
    notes.append(f"coverage after completion {100 * out.coverage:.1f} % of the hemisphere")
    return out


def _pick(grid, d, w, left, overlap, min_overlap, tolerance=4.0):
    """The candidate and rotation to merge next. Among the local distance minima of all
    candidates, those within ``tolerance`` times the least distance count as equally good
    matches: the distance of the true rotation is a floor set by noise and by the fit's bias,
    which differs between views, and a rotation within a few times that floor changes D by no
    more than the data can tell (for an NDF with a symmetry, e.g. GGX's point symmetry, the
    true rotation and its image are both exact). Of these, one overlapping within the band is
    preferred, then the one adding the most solid angle, as the paper's band intends.
    Returns (distance, angle, overlap, index) or None."""
    found = [(dist, s, frac, gain, j) for j, c in left.items()
             for dist, s, frac, gain in _rotations(grid, d, w, c, min_overlap)]
    if not found:
        return None
    best = min(f[0] for f in found)
    good = [f for f in found if f[0] <= tolerance * best]
    _, s, frac, _, j = min(good, key=lambda f: (not overlap[0] <= f[2] <= overlap[1], -f[3]))
    dist, angle = _refine(grid, d, w, left[j], s)
    return dist, angle, frac, j


def symmetry_images(part: PartialNDF, symmetry: str) -> list:
    """Images of a partial NDF under a symmetry the user states, ready to merge (eq. 16-17).

    Parameters
    ----------
    symmetry : "point" (D(h_x, h_y) = D(-h_x, -h_y)), "mirror-x" (D(h_x, h_y) = D(h_x, -h_y)),
        "mirror-y" (D(h_x, h_y) = D(-h_x, h_y)) or "isotropic" (D independent of phi_h)
    """
    g, n = part.grid, part.grid.n_phi
    idx = np.arange(n)
    if symmetry == "point":
        maps = [(idx + n // 2) % n] if n % 2 == 0 else []
    elif symmetry == "mirror-x":
        maps = [(-idx) % n]
    elif symmetry == "mirror-y":
        maps = [(n // 2 - idx) % n] if n % 2 == 0 else []
    elif symmetry == "isotropic":
        maps = [(idx + s) % n for s in range(1, n)]
    else:
        raise ValueError(f"symmetry {symmetry!r}: choose one of {', '.join(SYMMETRIES)}")
    if not maps:
        raise ValueError(f"symmetry {symmetry!r} needs an even number of phi nodes, not {n}")
    return [PartialNDF(g, part.d[:, m], part.w[:, m]) for m in maps]


def apply_symmetry(part: PartialNDF, symmetry: str) -> PartialNDF:
    """Merge the images of a stated symmetry into the partial NDF (no rotation search: the
    symmetry fixes the alignment)."""
    d, w = part.d, part.w
    if symmetry == "isotropic":
        # all rotations at once: the confidence-weighted mean of each theta ring (eq. 16)
        ww = np.where(w > 0, w, 0.0)
        tot = ww.sum(axis=1, keepdims=True)
        ring = (ww * np.nan_to_num(d)).sum(axis=1, keepdims=True) / np.where(tot > 0, tot, 1)
        d = np.broadcast_to(np.where(tot > 0, ring, np.nan), d.shape).copy()
        w = np.broadcast_to(ww.max(axis=1, keepdims=True), w.shape).copy()
    else:
        for img in symmetry_images(part, symmetry):
            d, w = merge(part.grid, d, w, img.d, img.w)
    out = PartialNDF(part.grid, d, w, part.residual, part.channel_scale, part.channels,
                     list(part.notes))
    out.notes.append(f"{symmetry} symmetry stated by the user: coverage "
                     f"{100 * out.coverage:.1f} % of the hemisphere")
    return out


def fill_uncovered(part: PartialNDF, horizon: str = "flat"):
    """Fill the nodes with W = 0 by harmonic (push-pull) interpolation on the (theta, phi) grid
    from the determined ones, as Wang et al. 2008 sec. 5.2 do for small holes. Periodic in phi,
    the pole row shared.

    Parameters
    ----------
    horizon : "flat": zero normal derivative at theta = pi/2 (the values at the edge of the
        data continue to the horizon: close for GGX's slowly falling tail); "zero": undetermined
        nodes at theta = pi/2 are 0 (closer for fast-falling tails such as Beckmann's, where a
        plateau inflates the projected area that normalises D)

    Returns
    -------
    d : array (n_theta, n_phi), complete table (same scale as part.d)
    filled : float, solid-angle fraction of the hemisphere that was filled
    """
    if horizon not in ("zero", "flat"):
        raise ValueError(f"horizon {horizon!r}: choose 'zero' or 'flat'")
    g = part.grid
    unknown = ~(part.w > 0)
    if not (~unknown).any():
        raise ValueError("nothing is determined: cannot fill an empty partial NDF")
    nt, nph = g.n_theta, g.n_phi
    num = -np.ones((nt, nph), int)
    num[unknown] = np.arange(unknown.sum())
    rows, cols, vals = [], [], []
    rhs = np.zeros(unknown.sum())
    known = np.nan_to_num(part.d)
    for (i, j), r in zip(np.argwhere(unknown), num[unknown]):
        if i == nt - 1 and horizon == "zero":
            rows.append(r), cols.append(r), vals.append(1.0)
            continue
        nbrs = [(i, (j + 1) % nph), (i, (j - 1) % nph),
                (i + 1 if i + 1 < nt else nt - 2, j),
                (i - 1, j) if i > 0 else (1, (j + nph // 2) % nph)]
        rows.append(r), cols.append(r), vals.append(float(len(nbrs)))
        for a, b in nbrs:
            if num[a, b] >= 0:
                rows.append(r), cols.append(num[a, b]), vals.append(-1.0)
            else:
                rhs[r] += known[a, b]
    mat = sp.csr_matrix((vals, (rows, cols)), shape=(len(rhs), len(rhs)))
    d = known.copy()
    d[unknown] = spsolve(mat, rhs)
    wts = g.weights
    return d, float(np.sum(wts * unknown) / np.sum(wts))
