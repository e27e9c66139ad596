"""Version 2 of the ``.bsdf`` layout (the Layer Laboratory's anisotropic files): per file pair
the box of complex coefficients ``c_sd = f_{d,s} |mu_o|`` (:mod:`layersim.bsdffile`)."""

from __future__ import annotations

import numpy as np

from ..solved.channels import LUMINANCE
from .layout import FLAG_COMPLEX, integrate_catmull_rom, n_marginal


def bsdf_spectrum(bsdf, c: int):
    """Every nonzero ``f_{d,s}`` (1/sr, complex) with ``d >= 0`` of channel ``c`` of a solved
    BSDF, the unscattered delta excluded: ``(pair, s, d, f)`` with our pair numbering
    (``b h^2 + o h + i``). The ``d = 0`` row holds ``f_{0,s}`` and ``f_{0,-s}``."""
    return _SPECTRA[bsdf.operators[c].representation](bsdf.series_table(c))


def _isotropic_spectrum(table):
    """:func:`bsdf_spectrum` of a cosine-series table (:class:`layersim.solved.isobsdf.SeriesTable`):
    ``f = sum_l f_l cos(l phi_d)``, so ``f_{0,0} = f_0`` and ``f_{+-l,0} = f_l / 2``."""
    size = np.diff(table.offsets)
    pair = np.repeat(np.arange(size.size), size)
    d = np.arange(table.coef.size) - table.offsets[pair]
    f = np.where(d > 0, 0.5, 1.0) * table.coef
    keep = f != 0
    return pair[keep], np.zeros(int(keep.sum()), np.int64), d[keep], f[keep] + 0j


def _coupled_spectrum(table):
    """:func:`bsdf_spectrum` of a :class:`layersim.aniso.bsdf.SeriesTable2D`: runs over the
    half ``l = d + s > 0`` (and ``l = 0, d >= 0``), ``f_{0,0}`` halved."""
    run = np.repeat(np.arange(table.run_s.size), table.run_len)
    pair = np.searchsorted(table.run_offsets, run, side="right") - 1
    s = table.run_s[run].astype(np.int64)
    d = table.run_d0[run] + (np.arange(run.size) - table.run_start[run])
    f = table.coef_re + 1j * table.coef_im
    f = np.where((d == 0) & (s == 0), 2.0 * f, f)
    keep = f != 0
    pair, s, d, f = pair[keep], s[keep], d[keep], f[keep]
    neg = d < 0                                             # use the conjugate (-d, -s)
    s, d, f = np.where(neg, -s, s), np.abs(d), np.where(neg, np.conj(f), f)
    mirror = (d == 0) & (s != 0)                            # f_{0,-s} = conj f_{0,s}
    return (np.concatenate([pair, pair[mirror]]), np.concatenate([s, -s[mirror]]),
            np.concatenate([d, d[mirror]]), np.concatenate([f, np.conj(f[mirror])]))


#: The spectrum of each operator representation's series table.
_SPECTRA = {"isotropic": _isotropic_spectrum, "anisotropic": _coupled_spectrum}


def layout_v2(bsdf, file_of, mu_out, nodes, relerr: float = 0.0):
    """Version 2: ``(offsets, (ms, md), coef, cdf, flags)`` of any solved BSDF (module
    docstring): per file pair the box of every nonzero ``c_sd = f_{d,s} |mu_o|`` over all
    channels (those below ``relerr`` times the pair's largest dropped first), channel-major
    Y, R, B, imaginary parts after the real parts where any is nonzero
    (:data:`FLAG_COMPLEX`)."""
    N = nodes.size
    P = N * N
    nch = bsdf.channels
    spectra = []
    for c in range(nch):
        pair, s, d, f = bsdf_spectrum(bsdf, c)
        sel = file_of[pair] >= 0
        spectra.append((file_of[pair[sel]], s[sel], d[sel], f[sel] * mu_out[pair[sel]]))
    if relerr > 0:
        peak = np.zeros(P)
        for p, _, _, f in spectra:
            np.maximum.at(peak, p, np.abs(f))
        spectra = [tuple(x[np.abs(f) >= relerr * peak[p]] for x in (p, s, d, f))
                   for p, s, d, f in spectra]
    allp = np.concatenate([sp[0] for sp in spectra])
    msh = np.zeros(P, np.int64)
    np.maximum.at(msh, allp, np.abs(np.concatenate([sp[1] for sp in spectra])))
    md = np.zeros(P, np.int64)
    np.maximum.at(md, allp, np.concatenate([sp[2] for sp in spectra]) + 1)
    ms = np.where(md > 0, 2 * msh + 1, 0)
    size = ms * md
    base = np.zeros(P, np.int64)                           # start of the pair, real parts only
    base[1:] = np.cumsum(size * nch)[:-1]
    re = np.zeros(int((size * nch).sum()))
    im = np.zeros(re.size)
    # (stored block, source channel, weight): Y = sum_c LUMINANCE[c] channel c, then R and B
    plan = [(0, c, LUMINANCE[c]) for c in range(3)] + [(1, 0, 1.0), (2, 2, 1.0)] \
        if nch == 3 else [(0, 0, 1.0)]
    for ch, c, w in plan:
        p, s, d, f = spectra[c]
        pos = base[p] + ch * size[p] + (s + msh[p]) * md[p] + d
        np.add.at(re, pos, w * f.real)
        np.add.at(im, pos, w * f.imag)
    re32, im32 = re.astype(np.float32), im.astype(np.float32)
    complex_ = bool(np.any(im32 != 0))
    parts = 2 if complex_ else 1
    pair_of = np.repeat(np.arange(P), size * nch)
    dest = np.arange(re.size) + (parts - 1) * base[pair_of]
    coef = np.zeros(parts * re.size, np.float32)
    coef[dest] = re32
    if complex_:
        coef[dest + nch * size[pair_of]] = im32
    # marginal coefficients of channel 0: (s, d) = (-j, j), from the stored float32 values
    flags = FLAG_COMPLEX if complex_ else 0
    J = int(ms.max()) // 2 if P else 0
    marg = np.zeros((n_marginal(2 * J + 1, flags), P))
    for j in range(J + 1):
        has = (msh >= j) & (md > j)
        pos = base[has] + (msh[has] - j) * md[has] + j
        marg[j, has] = (1.0 if j == 0 else 2.0) * re32[pos]
        if complex_ and j > 0:
            marg[J + j, has] = 2.0 * im32[pos]
    cdf = integrate_catmull_rom(nodes.astype(float), marg.reshape(-1, N, N))    # [j, i, o]
    cdf = cdf.transpose(2, 1, 0).astype(np.float32).ravel()                     # [o, i, j]
    shape = np.stack([ms, md], axis=1).astype(np.uint32)
    return parts * base, shape, coef, cdf, flags
