"""Exceptions raised by layersim.

Every error a user can trigger with bad input derives from :class:`LayersimError`, so that the
command line can print it as one line and exit non-zero. Messages say what is wrong, where, and
what to do instead.
"""

from __future__ import annotations


class LayersimError(Exception):
    """Base class of all errors caused by user input or infeasible requests."""


class SceneError(LayersimError, ValueError):
    """A scene description is malformed.

    Attributes
    ----------
    layer : int or None
        Index of the offending layer (0 = top), or None for stack-level fields.
    kind : str or None
        Kind of the offending layer (``"dielectric"``, ...).
    field : str or None
        Name of the offending field.
    """

    def __init__(self, message: str, layer: int | None = None, kind: str | None = None,
                 field: str | None = None, source: str | None = None):
        where = []
        if source:
            where.append(str(source))
        if layer is not None:
            where.append(f"layer {layer}" + (f" ({kind})" if kind else ""))
        if field is not None:
            where.append(f"field '{field}'")
        prefix = ": ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)
        self.layer, self.kind, self.field, self.source = layer, kind, field, source


class InfeasibleError(LayersimError):
    """A request is well-formed but cannot be carried out within the stated limits
    (memory, discretisation size, representability). The message names the limit and what to
    change."""


class OperatorError(LayersimError, ValueError):
    """Two layer operators cannot be combined (different discretisations, missing blocks, ...)."""


class FileFormatError(LayersimError, ValueError):
    """A file is not a valid layersim/BSDF file (wrong magic, truncated, inconsistent sizes)."""


class BackendUnavailableError(LayersimError, RuntimeError):
    """A Monte Carlo backend is not installed, has no device, or its device cannot build the
    walk; the message names the device and the driver's reason, and says what to install or
    which backend to use instead."""


class ClusterError(LayersimError, RuntimeError):
    """A Dask cluster cannot be reached, or its workers cannot run the walk (layersim missing
    there, or another version); the message names the scheduler or the workers and what to do."""


class SweepError(LayersimError, ValueError):
    """A sweep file (``layersim mc SWEEP.toml``) is malformed; the message names the file and
    the field (``angles[2]``)."""

    def __init__(self, message: str, field: str | None = None, source: str | None = None):
        where = [str(p) for p in (source, f"field '{field}'" if field else None) if p]
        super().__init__(": ".join(where + [message]))
        self.field, self.source = field, source
