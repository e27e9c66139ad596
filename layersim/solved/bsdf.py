"""The solved BSDF of a stack: evaluation, energy fractions and bin energies.

Directions follow ``docs/conventions.md``: unit vectors ``(..., 3)`` in the local frame, both
pointing away from the surface. This module is the one place where they are converted to the
solver's discrete-ordinates convention::

    mu_in = wi.z,   mu_out = -wo.z,   dphi = phi(wo) - phi(wi) - pi

(``mu > 0`` propagates down; ``dphi`` is the azimuth difference of the propagation directions,
0 for the specular and straight-through directions). The block follows from the signs:
top reflection ``Rt`` (wi.z > 0, wo.z > 0), bottom reflection ``Rb``, top-to-bottom transmission
``Ttb`` (wi.z > 0, wo.z < 0) and ``Tbt``.

``eval`` interpolates the Fourier coefficients between ordinates with cubic (Catmull-Rom type)
splines in both elevations, constant beyond the outermost ordinates, sums the cosine
series in ``dphi`` (a Warp kernel) and returns the positive part of that interpolant. The
series at the ordinates are non-negative (lobes cut in azimuth are tapered with a non-negative
kernel, :func:`layersim.operators.fourier.taper_factors`), but cubic weights are partly negative, so
between ordinates the interpolant can undershoot zero: by a few millionths of the BSDF's peak on
the steep flank of a narrow lobe, by ~1e-3 next to the critical angle of total internal
reflection (docs/method.md, "Non-negative evaluation", measured by
``benchmarks/features/eval_positivity.py``); those values are returned as 0. ``albedo`` and
``bin_energies`` interpolate the incident elevation
linearly instead: a convex combination of the energies at the ordinates, so that they are never
negative and never exceed 1 where the ordinates do not. Delta parts (the unscattered
transmission through media, the mirror reflection of smooth interfaces;
:mod:`layersim.operators.deltas`) are not part of ``eval``; ``albedo`` and ``bin_energies`` include
them and :meth:`BSDF.specular` reports them. Smooth dielectric boundaries are applied by
:mod:`layersim.solved.boundary`.
"""

from __future__ import annotations

import json
import os
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..aniso.bsdf import AnisoEvaluator
from .boundary import BoundaryEvaluator
from .directions import bin_arguments, direction_pairs, incident_directions
from ..errors import FileFormatError, OperatorError
from .isobsdf import IsoEvaluator
from ..operators.operator import from_arrays
from .sampling import sampler_for
from ..specular_paths.bsdf import FORMAT_VERSION_PATHS, SpecularPathsBSDF

FORMAT_VERSION = 1
#: First bytes of a saved BSDF: a zip archive (numpy ``.npz``) of plain arrays.
ZIP_MAGIC = b"PK\x03\x04"
#: Files holding anisotropic (coupled-mode) operators are written as version 2; isotropic ones
#: stay version 1, readable by older layersim versions.
FORMAT_VERSION_ANISO = 2

#: Evaluator class of each operator representation (:attr:`layersim.operators.operator.Operator.
#: representation`): built from one operator, it provides ``table``, ``eval(wi, wo)``,
#: ``albedo(wi)`` and ``bins(wi, mu_edges, phi_edges)`` on flattened, validated directions.
EVALUATORS = {"isotropic": IsoEvaluator, "anisotropic": AnisoEvaluator}


def channel_pairs(a: "BSDF", b: "BSDF", mismatch: str) -> list:
    """Per-channel operator pairs of two BSDFs for stack algebra: equal channel counts pair
    up, a one-channel BSDF pairs with every channel of the other. Other counts raise
    :class:`OperatorError` with ``mismatch.format(a=a.channels, b=b.channels)``."""
    if a.channels != b.channels and 1 not in (a.channels, b.channels):
        raise OperatorError(mismatch.format(a=a.channels, b=b.channels))
    pick = lambda x, c: x.operators[0 if x.channels == 1 else c]
    return [(pick(a, c), pick(b, c)) for c in range(max(a.channels, b.channels))]


def refuse_boundary(what: str, *bsdfs: "BSDF") -> None:
    """Refuse stack algebra (``what``: "add", "subtract") on BSDFs with smooth dielectric
    boundaries: their operators' blocks hold the radiance inside the boundary, which
    :mod:`layersim.solved.boundary` applies only at evaluation."""
    if any(b.boundary for b in bsdfs):
        raise OperatorError(
            f"cannot {what} a BSDF with a smooth dielectric boundary (roughness 0 at the "
            "top or bottom of its stack): its blocks describe the light inside that boundary; "
            "solve the whole stack as one scene instead")


def foreign_file(head: bytes, path) -> str:
    """What a file that does not start with :data:`ZIP_MAGIC` is, as far as its first bytes
    (``head``) and name tell, for the message that refuses it as a saved BSDF."""
    path = Path(path)
    if not head:
        return "the file is empty (not a saved layersim BSDF)"
    if head.startswith(b"SCATFUN"):
        return ("a tabulated Fourier .bsdf file, not a saved layersim BSDF (.lsim); read it "
                "with layersim.bsdffile.read, or give it to 'layersim eval', 'plot' or 'export'")
    if head.startswith(b"tensor_f"):
        return ("an RGL material (tensor file, top-side reflection only) as 'layersim export "
                "--format rgl' writes it, not a saved layersim BSDF (.lsim); read it with "
                "layersim.bsdffile.rgl.read")
    if path.suffix.lower() == ".toml":
        return ("a scene file, not a saved layersim BSDF (.lsim); solve it first "
                "('layersim solve' writes the .lsim file)")
    return "not a saved layersim BSDF (.lsim files are written by BSDF.save and 'layersim solve')"


#: Order of the saved parameters of a near-specular interface (:attr:`BSDF.lobes`); files
#: without the last ones (``k``) load with their defaults.
_LOBE_KEYS = ("eta", "alpha_u", "alpha_v", "distribution", "rotation", "k")

#: Sides of a stack, in the names of saved boundaries and lobes.
_SIDES = ("top", "bottom")


def _surroundings_arrays(boundary: dict, lobes: dict, prefix: str) -> dict:
    """A channel's smooth boundaries and near-specular lobes (:attr:`BSDF.boundary`,
    :attr:`BSDF.lobes`) as named arrays beside its operator's (``{prefix}boundary_{side}``:
    the index outside; ``{prefix}lobe_{side}``: the lobe's parameters in :data:`_LOBE_KEYS`
    order, as text)."""
    d = {f"{prefix}boundary_{side}": np.array(eta) for side, eta in boundary.items()}
    for side, lobe in lobes.items():
        d[f"{prefix}lobe_{side}"] = np.array([str(lobe.get(k, 0.0)) for k in _LOBE_KEYS])
    return d


def _read_boundary(d, prefix: str) -> dict:
    """The smooth boundaries saved by :func:`_surroundings_arrays` (empty if none)."""
    return {side: float(d[f"{prefix}boundary_{side}"]) for side in _SIDES
            if f"{prefix}boundary_{side}" in d}


def _read_lobes(d, prefix: str) -> dict:
    """The near-specular lobes saved by :func:`_surroundings_arrays` (empty if none)."""
    return {side: {k: (str(v) if k == "distribution" else float(v))
                   for k, v in zip(_LOBE_KEYS, d[f"{prefix}lobe_{side}"])}
            for side in _SIDES if f"{prefix}lobe_{side}" in d}


# ---------------------------------------------------------------------------------------------
# BSDF
# ---------------------------------------------------------------------------------------------

class BSDF:
    """Solved BSDF of a layer stack (one operator per colour channel).

    Use :func:`layersim.solve` to make one and :meth:`load` to read a saved one.

    Attributes
    ----------
    operators : list of layersim.operators.operator.Operator
        One per channel (all of one representation).
    plan : layersim.plan.Plan or None
    info : dict
        Scene name, timings and other metadata (saved with the BSDF).
    boundary : dict
        Smooth dielectric boundaries kept out of the operators' blocks, ``{"top" | "bottom":
        index of the medium outside}``, the same for all channels: the blocks then hold the
        radiance just inside that boundary, on the Snell-matched grid of
        :func:`layersim.operators.quadrature.snell_matched`, and evaluation applies the boundary's
        Fresnel transmission and refraction (:mod:`layersim.solved.boundary`). Empty for ordinary
        stacks.
    lobes : list of dict
        Per channel, the near-specular rough boundaries among them, ``{"top": parameters}``
        of :class:`layersim.solved.lobe.NearSpecularLobe`: their direct reflection is that lobe and
        their transmittance the rough one (:mod:`layersim.solved.lobe`). On a side without a
        boundary (a bare near-specular conductor) the lobe replaces the operator's own delta
        reflection on that side, which stands for it in the adding equations. Empty dicts
        otherwise.
    """

    def __init__(self, operators: list, plan=None, info: dict | None = None,
                 boundary: dict | None = None, lobes: list | None = None):
        if not operators:
            raise ValueError("a BSDF needs at least one operator")
        self.operators = list(operators)
        self.plan = plan
        self.info = dict(info or {})
        self.boundary = dict(boundary or {})
        self.lobes = [{} for _ in self.operators] if lobes is None else [dict(x) for x in lobes]
        if len(self.lobes) != len(self.operators):
            raise ValueError(f"lobes holds {len(self.lobes)} entries for "
                             f"{len(self.operators)} channel(s): give one dict per channel")
        self._evaluators: dict = {}

    # ---- basic properties --------------------------------------------------------------

    @property
    def channels(self) -> int:
        return len(self.operators)

    @property
    def opaque(self) -> bool:
        return self.operators[0].opaque

    @property
    def grid(self):
        return self.operators[0].grid

    @property
    def error_estimate(self) -> float | None:
        """Estimated relative L2 error of the bin energies (18 x 36 bins per side, worst
        incidence of 0, 30, 60, 80 degrees) from the discretisation, or None if the solve
        did not estimate it (``layersim.solve(..., error_estimate=True)`` or ``tol=``;
        :mod:`layersim.plan.accuracy`)."""
        acc = self.info.get("accuracy")
        return None if acc is None else float(acc["estimate"])

    @property
    def anisotropic(self) -> bool:
        """True if the operators couple Fourier modes (see :mod:`layersim.aniso`)."""
        return self.operators[0].representation == "anisotropic"

    def evaluator(self, c: int):
        """The evaluator of channel ``c`` (:data:`EVALUATORS`, by the operator's
        representation; built on first use)."""
        if c not in self._evaluators:
            op = self.operators[c]
            ev = EVALUATORS[op.representation](op)
            if self.boundary or self.lobes[c]:
                ev = BoundaryEvaluator(op, ev, self.boundary, self.lobes[c])
            self._evaluators[c] = ev
        return self._evaluators[c]

    def series_table(self, c: int):
        """The per-pair series table of channel ``c``
        (:class:`layersim.solved.isobsdf.SeriesTable` or
        :class:`layersim.aniso.bsdf.SeriesTable2D`)."""
        return self.evaluator(c).table

    def rotational_average(self) -> "BSDF":
        """This BSDF averaged over rotations about the normal (itself when isotropic): the
        importance-sampling proposal of anisotropic stacks (:mod:`layersim.solved.sampling`)."""
        ops = [op.rotational_average() for op in self.operators]
        if all(a is b for a, b in zip(ops, self.operators)):
            return self
        return BSDF(ops, info=self.info, boundary=self.boundary, lobes=self.lobes)

    def _per_channel(self, fn):
        out = [fn(c) for c in range(self.channels)]
        if self.channels == 1:
            return out[0]
        if isinstance(out[0], tuple):
            return tuple(np.stack([o[k] for o in out], axis=-1) for k in range(len(out[0])))
        if isinstance(out[0], dict):
            return {k: np.stack([o[k] for o in out], axis=-1) for k in out[0]}
        return np.stack(out, axis=-1)

    # ---- evaluation --------------------------------------------------------------------

    def eval(self, wi, wo) -> np.ndarray:
        """BSDF value f(wi, wo) in 1/sr, without the cosine factor (radiance convention).

        Parameters
        ----------
        wi, wo : array_like, shape (..., 3)
            Unit directions toward the light and the viewer (broadcast against each other).

        Returns
        -------
        ndarray, shape (...) (or (..., 3) for RGB)
            Never negative: the positive part of the spline interpolant (module docstring).
            Zero for configurations whose block is left out (opaque stack lit from below) and on
            the horizon (z = 0). Delta parts (unscattered transmission of media, mirror
            reflection and refraction of smooth interfaces) are not included: see
            :meth:`specular`.
        """
        return np.maximum(self.interpolant(wi, wo), 0.0)

    def interpolant(self, wi, wo) -> np.ndarray:
        """The spline interpolant of the solved series that :meth:`eval` takes the positive
        part of (1/sr; same arguments and shape). Between ordinates it can undershoot zero
        slightly (module docstring); ``benchmarks/features/eval_positivity.py`` measures by how
        much."""
        wi, wo, shape = direction_pairs(wi, wo)
        return self._per_channel(lambda c: self.evaluator(c).eval(wi, wo).reshape(shape))

    def specular(self, wi) -> dict:
        """The delta parts of the BSDF for beams from ``wi`` (..., 3): mirror reflection of
        smooth interfaces and straight-through transmission, which :meth:`eval` leaves out.

        Returns
        -------
        dict
            ``{"top": (energy, wo), "bottom": (energy, wo)}``: the fraction of the incident
            power that leaves through each side in the one direction ``wo`` (unit vectors,
            shape ``wi.shape``; energy shape ``wi.shape[:-1]``, plus a channel axis for RGB).
            Energies are interpolated linearly in the incident elevation between the
            ordinates, like :meth:`albedo`, which includes them.
        """
        wi = self._incident(wi)
        shape = wi.shape[:-1]
        flat = wi.reshape(-1, 3)
        per = [self.evaluator(c).specular(flat) for c in range(self.channels)]
        out = {}
        for side in ("top", "bottom"):
            energy = np.stack([p[side][0].reshape(shape) for p in per], axis=-1)
            out[side] = (energy[..., 0] if self.channels == 1 else energy,
                         per[0][side][1].reshape(shape + (3,)))
        return out

    # ---- importance sampling (layersim.solved.sampling) ----------------------------------------

    def sample(self, wi, u):
        """Importance-sample outgoing directions (:mod:`layersim.solved.sampling`).

        Parameters
        ----------
        wi : array_like, shape (..., 3)
            Unit directions toward the light (local frame).
        u : array_like, shape (..., 2)
            Uniform variates in [0, 1), broadcast against ``wi``.

        Returns
        -------
        layersim.solved.sampling.Sample
            ``(wo, weight, pdf)``: ``wo`` (..., 3), ``weight = f(wi, wo) |wo.z| / pdf`` per
            channel, ``pdf`` (...) in 1/sr, and ``valid`` (...), False for rows where no
            direction is drawn: ``wi`` on the horizon, or ``wi.z < 0`` when the stack is opaque
            (no light enters from below). There ``wo = (0, 0, 0)``, ``weight = 0`` and
            ``pdf = 0``, as Mitsuba 3 returns an invalid sample; no exception, so that the
            other rows of a batch stay usable. Check ``valid`` (or ``pdf > 0``) before using
            ``wo``.
        """
        return sampler_for(self).sample(wi, u)

    def pdf(self, wi, wo) -> np.ndarray:
        """Solid-angle density (1/sr) with which :meth:`sample` draws ``wo``. See
        :mod:`layersim.solved.sampling`."""
        return sampler_for(self).pdf(wi, wo)

    # ---- energy ------------------------------------------------------------------------

    def _incident(self, wi):
        return incident_directions(wi, self.opaque, "a conductor or diffuse layer")

    def albedo(self, wi):
        """Energy fractions ``(R, T)`` of a beam arriving from ``wi``: R leaves on the side it
        came from, T on the other. Each has shape ``wi.shape[:-1]`` (plus a channel axis).

        Computed with the discretisation's own quadrature at the ordinates and interpolated
        linearly in the incident elevation, so that they agree with the operator's energy
        balance (R + T = 1 to rounding for non-absorbing stacks, R + T <= 1 otherwise).
        """
        wi = self._incident(wi)
        shape = wi.shape[:-1]
        flat = wi.reshape(-1, 3)
        return self._per_channel(lambda c: tuple(
            x.reshape(shape) for x in self.evaluator(c).albedo(flat)))

    def bin_energies(self, wi, mu_edges, phi_edges) -> dict:
        """Fraction of the power of a beam from ``wi`` leaving into each solid-angle bin.

        Parameters
        ----------
        wi : array_like, shape (3,)
            One incident direction.
        mu_edges : array_like (n_mu + 1,)
            Increasing edges in |cos theta_o| within [0, 1].
        phi_edges : array_like (n_phi + 1,)
            Increasing edges in the azimuth phi_o of ``wo`` (radians) within [0, 2 pi].

        Returns
        -------
        dict
            ``{"top": (n_mu, n_phi), "bottom": (n_mu, n_phi)}`` (a trailing channel axis for
            RGB). The angular distribution is that of the spline interpolant (integrated exactly
            in elevation, Gauss-Legendre on each piece, and analytically in azimuth), scaled so
            that over the whole hemisphere it carries the energy of :meth:`albedo` (the
            quadrature's; the two differ by the discretisation error, ~1e-5 at n ~ 200): bins
            covering a hemisphere sum exactly to R or T. Each delta part (:meth:`specular`) is
            added to the bin that holds its direction (mirror or straight-through).
        """
        wi = self._incident(wi)
        mu_edges, phi_edges = bin_arguments(wi, mu_edges, phi_edges)
        return self._per_channel(lambda c: self.evaluator(c).bins(wi, mu_edges, phi_edges))

    # ---- persistence -------------------------------------------------------------------

    def save(self, path) -> Path:
        """Write the solved operators and metadata to ``path`` (numpy ``.npz`` container;
        reload with :meth:`BSDF.load`)."""
        if not isinstance(path, (str, os.PathLike)):
            raise TypeError("BSDF.save takes a path (str or pathlib.Path), got "
                            f"{type(path).__name__}")
        path = Path(path)
        version = FORMAT_VERSION_ANISO if self.anisotropic else FORMAT_VERSION
        arrays = {"format": np.array("layersim-bsdf"), "version": np.array(version),
                  "channels": np.array(self.channels),
                  "info": np.array(json.dumps(self.info, default=str))}
        for c, op in enumerate(self.operators):
            arrays.update(op.to_arrays(prefix=f"c{c}_"))
            arrays.update(_surroundings_arrays(self.boundary, self.lobes[c], prefix=f"c{c}_"))
        with open(path, "wb") as fh:
            np.savez_compressed(fh, **arrays)
        return path

    @classmethod
    def load(cls, path) -> "BSDF":
        """Read a BSDF written by :meth:`save`.

        The file is a zip archive of plain numeric and text arrays, read without pickle
        (``allow_pickle=False``): a saved BSDF never holds Python objects.

        Raises
        ------
        TypeError
            If ``path`` is not a path (str or os.PathLike).
        FileFormatError
            If the file is empty, truncated, damaged, of another kind (a ``.bsdf`` table, a
            scene, other data) or written by a newer layersim; the message names the file and
            what it is instead.
        OSError
            If the file cannot be opened.
        """
        if not isinstance(path, (str, os.PathLike)):
            raise TypeError("BSDF.load takes the path (str or pathlib.Path) of a file written "
                            f"by BSDF.save or 'layersim solve', got {type(path).__name__}")
        path = Path(path)
        with open(path, "rb") as fh:
            head = fh.read(8)
            if head[:len(ZIP_MAGIC)] != ZIP_MAGIC:
                raise FileFormatError(f"{path}: {foreign_file(head, path)}")
            fh.seek(0)
            return cls._read(fh, path)

    @classmethod
    def _read(cls, fh, path) -> "BSDF":
        """The BSDF in the open zip archive ``fh`` (the file at ``path``; see :meth:`load`)."""
        try:
            with np.load(fh, allow_pickle=False) as d:
                if "format" not in d.files or str(d["format"]) != "layersim-bsdf":
                    raise FileFormatError(f"{path}: a zip archive, but not a saved layersim "
                                          "BSDF (BSDF.save / 'layersim solve' write those)")
                version = int(d["version"])
                if version > FORMAT_VERSION_PATHS:
                    raise FileFormatError(f"{path}: format version {version} is newer than "
                                          f"this layersim ({FORMAT_VERSION_PATHS}); upgrade "
                                          "layersim")
                if version == FORMAT_VERSION_PATHS:
                    # a stack of specular paths: the scene that rebuilds them
                    return SpecularPathsBSDF.from_arrays(d)
                channels = range(int(d["channels"]))
                ops = [from_arrays(d, prefix=f"c{c}_") for c in channels]
                boundary = _read_boundary(d, prefix="c0_")
                lobes = [_read_lobes(d, prefix=f"c{c}_") for c in channels]
                info = json.loads(str(d["info"]))
        except FileFormatError:
            raise
        except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile,
                zlib.error) as exc:
            raise FileFormatError(f"{path}: a damaged or truncated layersim BSDF file "
                                  f"({type(exc).__name__}: {exc}); save or solve it again"
                                  ) from None
        return cls(ops, None, info, boundary=boundary, lobes=lobes)

    def __repr__(self) -> str:
        op = self.operators[0]
        ms = f", ms={op.ms}" if self.anisotropic else ""
        return (f"BSDF({self.info.get('scene', '?')}: n={op.grid.n}, md={op.m}{ms}, "
                f"{self.channels} channel(s), {'opaque' if self.opaque else 'transmissive'})")
