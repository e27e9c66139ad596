"""The tabulated Fourier BSDF file format (``.bsdf``, header ``SCATFUN``) of layerlab, Mitsuba 0.6
and pbrt-v3 (version 1, isotropic), and the Layer Laboratory's anisotropic version 2.

(The RGL tensor format of Mitsuba 3's and pbrt-v4's ``measured`` material, reflection only, is
:mod:`layersim.bsdffile.rgl`; ``export(..., format="rgl")`` writes it.)

Byte layout (little-endian; offsets in bytes; ``N`` nodes, ``P = N * N`` ordinate pairs)
---------------------------------------------------------------------------------------
======  ==========================  ==============================================================
size    field                       meaning
======  ==========================  ==============================================================
7       identifier                  ``b"SCATFUN"``
1       version                     1 (isotropic) or 2 (anisotropic)
4       flags (uint32)              0x01: the file holds a BSDF; 0x02 (v1): harmonic
                                    extrapolation; 0x04 (v2, layersim's extension): complex
                                    coefficients (see below)
4       nNodes (uint32)             ``N``
4       nCoeffs (uint32)            floats in the coefficient array
4       nMaxOrder (uint32)          v1: longest series; v2: two fields, ``ms_max`` (odd) then
(8)                                 ``md_max``, the largest ``ms`` and ``md`` of the table
4       nChannels (uint32)          1 or 3 (stored as Y, R, B)
4       nBases (uint32)             1 (textured files: more)
4       nMetadataBytes (uint32)     length of the trailing JSON/text metadata
4       nParameters (uint32)        0 (textured files: more)
4       nParameterValues (uint32)   0
4       eta (float32)               relative index eta(bottom) / eta(top)
8       alpha (2 x float32)         Beckmann-equivalent roughness, top and bottom (informative)
8 / 4   unused                      pads the header to 64 bytes (v2: one float, since it has
                                    ``ms_max`` and ``md_max``)
4 N     nodes (float32)             ``[-mu_h .. -mu_1, 0, 0, mu_1 .. mu_h]`` (layerlab inserts
                                    two zero nodes so that the spline has a node on the horizon)
4 nP    parameter sample counts     absent when ``nParameters = 0``
4 nPV   parameter sample positions  absent when ``nParameterValues = 0``
4 P M   CDF (float32)               v1 (``M = 1``): ``cdf[i N + o]``, integral over mu_o of the
                                    zeroth order of channel 0 from node 0 to node o
                                    (Catmull-Rom spline); v2: ``M`` marginal coefficients per
                                    pair at ``[(o N + i) M + j]`` (below)
8 P     offset table (uint32)       v1: ``(offset, length)`` of pair ``i N + o``;
(12 P)                              v2: ``(offset, ms, md)``
4 nC    coefficients (float32)      v1: per pair, channel-major blocks (Y, R, B) of ``length``
                                    floats; v2: per pair, channel-major blocks of ``ms x md``
                                    floats (``s = -(ms-1)/2 .. (ms-1)/2`` slowest, ``d = 0 ..
                                    md-1`` fastest); with flag 0x04 the ``ms x md`` imaginary
                                    parts of every channel follow the real parts of every channel
nMB     metadata                    UTF-8 text (layersim writes JSON)
======  ==========================  ==============================================================

The file size must equal the sum exactly (layerlab and Mitsuba refuse anything else).

Meaning of the coefficients
---------------------------
Directions use layerlab's discrete-ordinates convention (``mu > 0`` propagates down, into the
stack). The series of pair ``(o, i)`` is ``a_l = f_l(mu_o, mu_i) |mu_o|``, the BSDF's cosine series
(radiance convention, light arriving along ``mu_i``) times the outgoing cosine, so that a
renderer's ``eval`` (which includes the cosine factor) is ``sum_l a_l cos(l phi)``; ``phi`` is
the azimuth difference of the propagation directions (0: specular / straight through).
In layersim's terms (``docs/conventions.md``): ``mu_i = wi.z``, ``mu_o = -wo.z``, and pair
``(o, i)`` of block ``Rt`` (our ordinate indices ``o``, ``i``) is file pair ``(h - 1 - o, h + 2 + i)``, ``Ttb``
is ``(h + 2 + o, h + 2 + i)``, ``Rb`` is ``(h + 2 + o, h - 1 - i)`` and ``Tbt`` is
``(h - 1 - o, h - 1 - i)``.

Version 2 stores per pair and channel a series in ``phi_s = phi_o + phi_i`` and
``phi_d = phi_o - phi_i``::

    f |mu_o| = 2 sum_{s, d >= 0} Re(c_sd exp(i (s phi_s + d phi_d))) - sum_s Re(c_s0 exp(i s phi_s)),
    c_sd = f_{d,s}(mu_o, mu_i) |mu_o|,

where ``f = sum_{d,s} f_{d,s} exp(i d phi_d) exp(i s phi_s)`` over all ``d, s`` is the complex
expansion of Zeltner & Jakob 2018 eq. (7) (:mod:`layersim.aniso.basis`;
``f_{-d,-s} = conj(f_{d,s})``, so ``d >= 0`` suffices; the ``d = 0`` row holds both ``f_{0,s}`` and ``f_{0,-s}``). The Layer
Laboratory stores real ``c_sd`` (its layers are mirror symmetric about their tangent axes), and
then this is its ``eval_fourier_series_2d``: ``2 sum c_sd cos(s phi_s + d phi_d) - sum_s c_s0
cos(s phi_s)``. A layer rotated by ``rot`` has ``f_{d,s} exp(-2 i s rot)``: rotated layers, and
stacks that hold one, have complex coefficients, which layersim writes with flag 0x04 (files
without it are the Layer Laboratory's layout, bit for bit). An isotropic BSDF is ``ms = 1`` with
``c_00 = a_0`` and ``c_0d = a_d / 2``.

The marginal table of version 2 serves the sampling of ``mu_o``: averaged over the outgoing
azimuth, ``f |mu_o|`` keeps the terms with ``s = -d``, a series in ``2 phi_i``::

    m(phi_i) = sum_{j=0}^{J} m_j cos(2 j phi_i) + sum_{j=1}^{J} m'_j sin(2 j phi_i),
    m_0 = Re c_00,  m_j = 2 Re c_{-j,j},  m'_j = 2 Im c_{-j,j},   J = ms_max // 2,

of channel 0. The table holds, for every pair, its Catmull-Rom integral over ``mu_o`` from node 0
to node ``o``, coefficient by coefficient: ``M = J + 1`` cosine coefficients ``m_j``, followed with
flag 0x04 by the ``J`` sine coefficients ``m'_j`` (``M = 2 J + 1``). (``c_{-j,j}`` is zero where a
pair's ``ms`` or ``md`` does not reach it.)

Azimuths: the version-2 plugin evaluates at ``phi_i`` = the azimuth of the camera direction and
``phi_o`` = that of the reversed light direction; both differ from the propagation azimuths of
:mod:`layersim.aniso.bsdf` (``phi_i = atan2(-wi.y, -wi.x)``, ``phi_o = atan2(wo.y, wo.x)`` with the
roles swapped, below) by ``pi``, which leaves ``phi_d`` and ``phi_s`` (mod ``2 pi``) unchanged.

Renderers evaluate the table *adjointly* (pbrt-v3 ``FourierBSDF::f``, Mitsuba 0.6 ``fourier``,
the Layer Laboratory's Mitsuba 2 ``fourier``): the camera direction takes the role of ``mu_i``
and the light that of ``mu_o``, and transmission is multiplied by ``(eta_camera /
eta_light)^2``; by generalized reciprocity this is the same BSDF. :meth:`FourierTable.eval`
reproduces that evaluation.

What is confirmed and what is ours (version 2)
----------------------------------------------
Confirmed against the Layer Laboratory's source (``tizian/layer-laboratory``:
``include/mitsuba/layer/storage.h``, ``src/liblayer/storage.cpp``, ``src/liblayer/fourier.cpp``,
``src/bsdfs/fourier.cpp``): the header fields and their order, the exact-size rule and its sum,
the ``(offset, ms, md)`` table of pair ``i N + o``, channel-major ``ms x md`` blocks with ``s``
slowest from ``-(ms-1)/2`` and ``d`` from 0, the values (``scatter_coeff(s, d, o, i) |mu_o| /
(2 pi w_i |mu_i|)``, i.e. ``c_sd`` above, real), the evaluation formula and its azimuths, the
marginal table (``ms_max // 2 + 1`` coefficients ``(j == 0 ? 1 : 2) c_{-j,j}`` per pair, integrated
over ``o``, evaluated as a cosine series in ``2 phi_i``), and ``Y, R, B`` channels.

layersim's own: flag 0x04 (imaginary parts and the sine half of the marginal table; the Layer
Laboratory checks neither version nor flags, and refuses such files by their size instead of
misreading them); every nonzero coefficient of the solved operator is stored (the Layer
Laboratory keeps a per-pair box found by ``find_truncation`` with error ``1e-3``); the
transmission factor follows pbrt-v3 and Mitsuba 0.6 for both versions (the Layer Laboratory's
Mitsuba 2 plugin multiplies by ``eta^2`` when the light is below, the inverse of pbrt-v3's
radiance-mode factor).

Not representable: the unscattered (delta) transmission of media (layersim keeps it in the JSON
metadata, so that :meth:`FourierTable.to_bsdf` restores it; renderers ignore it).

References: layerlab ``include/layer/storage.h``, ``src/storage.cpp`` (``BSDFStorage``); pbrt-v3
``FourierBSDFTable::Read`` and ``FourierBSDF::f``; Mitsuba 0.6 ``src/bsdfs/fourier.cpp``; the Layer
Laboratory's Mitsuba 2 ``BSDFStorage`` (files above); Zeltner & Jakob 2018 eq. (7), (10); Jakob's
layerlab tutorial sec. 6.5.
"""

from .layout import (FLAG_BSDF, FLAG_COMPLEX, FLAG_EXTRAPOLATED, HEADER_SIZE, MAGIC,
                     file_nodes, integrate_catmull_rom, n_marginal)
from .table import FourierTable, export, read

__all__ = ["FLAG_BSDF", "FLAG_COMPLEX", "FLAG_EXTRAPOLATED", "HEADER_SIZE", "MAGIC",
           "FourierTable", "export", "file_nodes", "integrate_catmull_rom", "n_marginal", "read"]
