"""The real Fourier basis of the coupled-mode (anisotropic) operators, and its relation to the
complex exponential basis of the Layer Laboratory paper.

Complex basis (Zeltner & Jakob 2018 eq. (2), (7)-(10))
------------------------------------------
Radiance ``Phi(mu, phi) = sum_l Phi_l(mu) exp(i l phi)`` and a BSDF between propagation directions

    f(mu_i, phi_i, mu_o, phi_o) = sum_{d,s} f_{d,s}(mu_i, mu_o) exp(i d phi_d) exp(i s phi_s),
    phi_d = phi_o - phi_i,  phi_s = phi_o + phi_i

give the scattered mode ``l`` as ``Phi_l^o = sum_s B_{l, l-2s} Phi_{l-2s}^i`` with

    B_{l,k}[o, i] = 2 pi f_{d,s}(mu_i, mu_o) w_i |mu_i|,   d = (l + k) / 2,  s = (l - k) / 2

(eq. (9)-(10)): mode ``k`` couples to ``l = k + 2s`` only. ``f`` is real, so
``f_{-d,-s} = conj(f_{d,s})`` and ``B_{-l,-k} = conj(B_{l,k})``.

Isotropic layers (``f = sum_l f_l cos(l phi_d)``, the
:class:`~layersim.operators.operator.IsoOperator` convention) have ``f_{0,0} = f_0``,
``f_{d,0} = f_|d| / 2`` for ``d != 0`` and ``f_{d,s} = 0`` for ``s != 0``; hence
``B_{l,l} = c_l f_l w |mu|`` with ``c_0 = 2 pi``, ``c_l = pi``: exactly the isotropic order-``|l|``
block.

Real basis (what the solver stores)
-----------------------------------
We exploit ``f_{-d,-s} = conj(f_{d,s})`` by working with real radiance coefficients::

    Phi(phi) = a_0 + sum_{l >= 1} (a_l cos(l phi) + b_l sin(l phi)),
    Phi_0 = a_0,  Phi_{+-l} = (a_l -+ i b_l) / 2,

so that every operator is a *real* matrix of the same size as the complex one restricted to
``l >= 0`` (half the storage, real arithmetic). Coefficient ``(l, cos)`` sits in *slot*
``2 l - 1`` and ``(l, sin)`` in slot ``2 l`` (``(0, cos)`` in slot 0); with ``md`` orders
(modes ``-(md-1) .. md-1``) there are ``S = 2 md - 1`` slots, and unknown ``slot * h + node``.
With ``b = B_{l,k}`` the real blocks are (row slot <- column slot)::

    l > 0, k > 0:   cos<-cos  Re b     cos<-sin  Im b    sin<-cos  -Im b    sin<-sin  Re b
    l > 0, k < 0:   cos<-cos  Re b     cos<-sin -Im b    sin<-cos  -Im b    sin<-sin -Re b
                    (column slots of mode |k|)
    l > 0, k = 0:   cos<-0   2 Re b    sin<-0  -2 Im b
    l = 0, k > 0:   0<-cos    Re b     0<-sin    Im b
    l = 0, k = 0:   0<-0      Re b

summed over the complex entries with ``l > 0`` or ``l = 0, k >= 0`` (the others are their
conjugates). An isotropic block ``B_l`` becomes ``cos<-cos = sin<-sin = B_l``: block diagonal.

For a layer that is mirror symmetric about its tangent axes (aligned microfacet interfaces, all
isotropic ingredients), ``f_{d,s}`` is real and the cos and sin slots decouple; rotating such a
layer by ``rot`` (``alpha_u`` along ``(cos rot, sin rot)``) multiplies ``f_{d,s}`` by
``exp(-2 i s rot)`` and couples them. Mode parity is always conserved (``l - k`` is even).

Evaluation (derived from the expansions above): with ``G = B / (2 pi w_i |mu_i|)``,
``f = sum_{a,b} G[a, b] u_a(phi_o) v_b(phi_i)``, ``u = (1, cos l phi, sin l phi)``,
``v = (1, 2 cos k phi, 2 sin k phi)``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sps


def n_slots(md: int) -> int:
    """Number of real slots for ``md`` Fourier orders (modes ``-(md-1) .. md-1``)."""
    return 2 * int(md) - 1


def slot_mode(md: int) -> np.ndarray:
    """Fourier order ``l >= 0`` of every slot, shape (S,)."""
    s = np.arange(n_slots(md))
    return (s + 1) // 2


def slot_is_sin(md: int) -> np.ndarray:
    """True for the sine slots, shape (S,)."""
    s = np.arange(n_slots(md))
    return (s > 0) & (s % 2 == 0)


def cos_slot(l):
    """Slot of ``(l, cos)`` (slot 0 for l = 0)."""
    l = np.asarray(l)
    return np.where(l == 0, 0, 2 * l - 1)


def sin_slot(l):
    """Slot of ``(l, sin)`` (l >= 1)."""
    return 2 * np.asarray(l)


def slot_scale(md: int) -> np.ndarray:
    """Diagonal of ``D`` in ``T^-1 = D T^H`` (1 for slot 0, 2 otherwise): reciprocity of a real
    operator reads ``G^T = D^-1 G D`` (see :func:`layersim.aniso.operator.reciprocity_error`)."""
    d = np.full(n_slots(md), 2.0)
    d[0] = 1.0
    return d


def real_entries(l, k, b):
    """Real-basis entries of complex operator entries ``b = B_{l,k}``.

    Parameters
    ----------
    l, k : int ndarray, shape (E,)
        Output and input complex modes; only entries with ``l > 0`` or ``l = 0, k >= 0``
        are accepted (the others are implied by conjugate symmetry).
    b : complex ndarray, shape (E,) or (E, ...)
        Entry values (trailing axes, e.g. node pairs, are carried along).

    Returns
    -------
    row_slot, col_slot : int ndarray (E4,)
    value : float ndarray (E4, ...)
        To be summed into the real operator (duplicates allowed).
    src : int ndarray (E4,)
        Index of the complex entry each real entry comes from.
    """
    l = np.asarray(l, np.int64)
    k = np.asarray(k, np.int64)
    b = np.asarray(b)
    if np.any(l < 0) or np.any((l == 0) & (k < 0)):
        raise ValueError("real_entries takes the upper half (l > 0, or l = 0 and k >= 0)")
    re, im = b.real, b.imag
    ka = np.abs(k)
    index = np.arange(l.size)
    rows, cols, vals, srcs = [], [], [], []

    def put(mask, rs, cs, v):
        if np.any(mask):
            rows.append(rs[mask])
            cols.append(cs[mask])
            vals.append(v[mask])
            srcs.append(index[mask])

    pos_l = l > 0
    m = pos_l & (k > 0)
    put(m, cos_slot(l), cos_slot(ka), re)
    put(m, cos_slot(l), sin_slot(ka), im)
    put(m, sin_slot(l), cos_slot(ka), -im)
    put(m, sin_slot(l), sin_slot(ka), re)
    m = pos_l & (k < 0)
    put(m, cos_slot(l), cos_slot(ka), re)
    put(m, cos_slot(l), sin_slot(ka), -im)
    put(m, sin_slot(l), cos_slot(ka), -im)
    put(m, sin_slot(l), sin_slot(ka), -re)
    m = pos_l & (k == 0)
    put(m, cos_slot(l), np.zeros_like(k), 2.0 * re)
    put(m, sin_slot(l), np.zeros_like(k), -2.0 * im)
    m = (l == 0) & (k > 0)
    put(m, np.zeros_like(l), cos_slot(ka), re)
    put(m, np.zeros_like(l), sin_slot(ka), im)
    m = (l == 0) & (k == 0)
    put(m, np.zeros_like(l), np.zeros_like(k), re)
    if not rows:
        return (np.zeros(0, np.int64), np.zeros(0, np.int64),
                np.zeros((0,) + b.shape[1:]), np.zeros(0, np.int64))
    return (np.concatenate(rows), np.concatenate(cols), np.concatenate(vals),
            np.concatenate(srcs))


def real_entries_real(l, k, b):
    """:func:`real_entries` for real ``b`` (mirror-symmetric layers): the ``cos<-sin`` and
    ``sin<-cos`` entries vanish, so each complex entry gives at most two real ones."""
    l = np.asarray(l, np.int64)
    k = np.asarray(k, np.int64)
    b = np.asarray(b, float)
    if np.any(l < 0) or np.any((l == 0) & (k < 0)):
        raise ValueError("real_entries_real takes the upper half (l > 0, or l = 0 and k >= 0)")
    ka = np.abs(k)
    idx = np.arange(l.size)
    both = (l > 0) & (k != 0)
    sign = np.where(k > 0, 1.0, -1.0)
    rows = [cos_slot(l[both]), sin_slot(l[both])]
    cols = [cos_slot(ka[both]), sin_slot(ka[both])]
    vals = [b[both], sign[both] * b[both]]
    srcs = [idx[both], idx[both]]
    m = (l > 0) & (k == 0)
    rows.append(cos_slot(l[m]))
    cols.append(np.zeros(int(m.sum()), np.int64))
    vals.append(2.0 * b[m])
    srcs.append(idx[m])
    m = l == 0
    rows.append(np.zeros(int(m.sum()), np.int64))
    cols.append(cos_slot(ka[m]))
    vals.append(b[m])
    srcs.append(idx[m])
    return (np.concatenate(rows), np.concatenate(cols), np.concatenate(vals),
            np.concatenate(srcs))


def complex_entries(row_slot, col_slot, value):
    """Inverse of :func:`real_entries` for a *complete* set of real entries of one node pair.

    Parameters
    ----------
    row_slot, col_slot : int ndarray (E,)
    value : float ndarray (E,)

    Returns
    -------
    dict
        ``{(l, k): complex}`` over the upper half (``l > 0`` or ``l = 0, k >= 0``).
    """
    acc: dict = {}

    def add(key, v):
        acc[key] = acc.get(key, 0.0) + v

    # gather the four real blocks per (l, k>=0) combination
    quad: dict = {}
    for a, c, v in zip(np.asarray(row_slot), np.asarray(col_slot), np.asarray(value)):
        la, sa = (int(a) + 1) // 2, (a > 0 and a % 2 == 0)
        lc, sc = (int(c) + 1) // 2, (c > 0 and c % 2 == 0)
        blk = quad.setdefault((la, lc), {})
        blk[(bool(sa), bool(sc))] = blk.get((bool(sa), bool(sc)), 0.0) + float(v)
    for (l, k), q in quad.items():
        cc, cs = q.get((False, False), 0.0), q.get((False, True), 0.0)
        sc, ss = q.get((True, False), 0.0), q.get((True, True), 0.0)
        if l > 0 and k > 0:
            add((l, k), complex(0.5 * (cc + ss), 0.5 * (cs - sc)))
            add((l, -k), complex(0.5 * (cc - ss), -0.5 * (cs + sc)))
        elif l > 0:  # k == 0
            add((l, 0), complex(0.5 * cc, -0.5 * sc))
        elif k > 0:  # l == 0
            add((0, k), complex(cc, cs))
        else:
            add((0, 0), complex(cc, 0.0))
    return acc


def rotation_matrix(md: int, h: int, angle: float) -> sps.csr_matrix:
    """Real-basis matrix of the rotation ``Phi(phi) -> Phi(phi - angle)`` of a radiance field
    about the normal, shape (S h, S h): ``(a_l, b_l) -> (a_l cos l t - b_l sin l t,
    a_l sin l t + b_l cos l t)``.

    A layer rotated by ``angle`` has the operator ``Rot(angle) B Rot(-angle)``, i.e.
    ``f_{d,s} -> f_{d,s} exp(-2 i s angle)`` (module docstring).
    """
    S = n_slots(md)
    l = np.arange(1, md)
    c, s = np.cos(l * angle), np.sin(l * angle)
    rows = [np.array([0])]
    cols = [np.array([0])]
    vals = [np.array([1.0])]
    cs, ss = cos_slot(l), sin_slot(l)
    rows += [cs, cs, ss, ss]
    cols += [cs, ss, cs, ss]
    vals += [c, -s, s, c]
    small = sps.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                           shape=(S, S))
    return sps.kron(small, sps.identity(h, format="csr"), format="csr")
