"""Run-time settings of layersim, read from the environment once.

Every ``LAYERSIM_*`` environment variable is read here and nowhere else. :func:`settings`
returns the active :class:`Settings`; :func:`configure` overrides some of them for the duration
of a ``with`` block (arguments of a call, tests)::

    with layersim.config.configure(threads=1, park_dir=None):
        bsdf = layersim.solve(scene)

=========================  ==================  ===========================================
variable                   field               meaning (default)
=========================  ==================  ===========================================
``LAYERSIM_DEVICE``        ``device``          Warp device of the projection kernels
                                               (``cpu``; ``cuda`` for a GPU)
``LAYERSIM_MAX_MEMORY``    ``max_memory``      bytes a solve may plan for (half the
                                               available memory)
``LAYERSIM_MAX_SECONDS``   ``max_seconds``     seconds a solve may plan for, estimated by
                                               the plan (600; ``off``: no limit)
``LAYERSIM_PARK_DIR``      ``park_dir``        directory of the temporary files that hold
                                               idle blocks of coupled solves (the system's
                                               temporary directory; ``off``: in memory)
``LAYERSIM_MALLOC_ARENAS`` ``malloc_arenas``   glibc malloc arenas, capped at start-up by
                                               the command line and benchmarks (1; 0
                                               keeps glibc's default)
``LAYERSIM_THREADS``       ``threads``         worker threads for projection batches,
                                               blocks, products and substitutions (cores)
``LAYERSIM_ORDER_THREADS`` ``order_threads``   threads for independent Fourier orders of
                                               the isotropic adding (1)
``LAYERSIM_WARP_VERBOSE``  ``warp_verbose``    Warp's banner and build messages (off)
``LAYERSIM_CACHE_DIR``     ``cache_dir``       directory of tables computed once and kept
                                               between runs (energy-compensation albedos,
                                               FGD tables; ``~/.cache/layersim``; ``off``:
                                               none)
=========================  ==================  ===========================================
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import re
import tempfile
from dataclasses import dataclass

from .errors import LayersimError


#: Warp device names layersim runs kernels on.
DEVICE_NAME = re.compile(r"cpu|cuda(:[0-9]+)?")


class ConfigError(LayersimError, ValueError):
    """A ``LAYERSIM_*`` variable or a :func:`configure` argument that cannot be used."""


@dataclass(frozen=True)
class Settings:
    """The settings of one run; see the module docstring for their variables.

    Attributes
    ----------
    device : str
        Warp device name for the projection kernels (``"cpu"``, ``"cuda"``, ``"cuda:1"``).
    max_memory : int or None
        Bytes a solve may plan for; None: half the memory available when the plan is made.
    max_seconds : float or None
        Seconds a solve may plan for (:func:`layersim.plan.budget.estimate_seconds`); None: no
        limit.
    park_dir : str or None
        Directory for the temporary files of coupled solves; None keeps everything in memory.
    malloc_arenas : int
        Cap on glibc's malloc arenas that programs owning their process apply at start-up
        (:func:`layersim.outofcore.memory.cap_arenas`; irreversible, so the library itself
        never applies it); 0 leaves the process's setting alone.
    threads : int
        Worker threads of :mod:`layersim.threads` (>= 1; 1 runs in the calling thread).
    order_threads : int
        Threads for the Fourier orders of the isotropic adding (>= 1).
    warp_verbose : bool
        Whether Warp prints its banner and kernel build messages.
    cache_dir : str or None
        Directory of tables computed once and reused by later runs (the albedo tables of
        :mod:`layersim.compensation`, the FGD tables of :mod:`layersim.statistical.fgd`); None
        keeps them in memory only.
    """

    device: str = "cpu"
    max_memory: int | None = None
    max_seconds: float | None = 600.0
    park_dir: str | None = dataclasses.field(default_factory=tempfile.gettempdir)
    malloc_arenas: int = 1
    threads: int = dataclasses.field(default_factory=lambda: os.cpu_count() or 1)
    order_threads: int = 1
    warp_verbose: bool = False
    cache_dir: str | None = dataclasses.field(default_factory=lambda: os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "layersim"))

    def __post_init__(self):
        for name in ("threads", "order_threads"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ConfigError(f"{name} must be an integer >= 1, got {value!r}")
        if not isinstance(self.malloc_arenas, int) or self.malloc_arenas < 0:
            raise ConfigError(f"malloc_arenas must be an integer >= 0, got "
                              f"{self.malloc_arenas!r}")
        if self.max_memory is not None and (not isinstance(self.max_memory, int)
                                            or self.max_memory <= 0):
            raise ConfigError(f"max_memory must be a positive number of bytes, got "
                              f"{self.max_memory!r}")
        if self.max_seconds is not None and (not isinstance(self.max_seconds, (int, float))
                                             or not self.max_seconds > 0):
            raise ConfigError(f"max_seconds must be a positive number of seconds, got "
                              f"{self.max_seconds!r}")
        if not isinstance(self.device, str) or not DEVICE_NAME.fullmatch(self.device):
            raise ConfigError(f"device must be a Warp device name ('cpu', 'cuda' or "
                              f"'cuda:N'), got {self.device!r}")

    @classmethod
    def from_env(cls, environ=None) -> "Settings":
        """Settings from ``LAYERSIM_*`` variables of ``environ`` (default ``os.environ``);
        unset or empty variables keep their defaults. Raises :class:`ConfigError` naming the
        variable for a value that cannot be read."""
        env = os.environ if environ is None else environ
        changes = {}
        for name, (var, parse) in _VARIABLES.items():
            text = env.get(var, "").strip()
            if not text:
                continue
            try:
                changes[name] = parse(text)
            except ValueError:
                raise ConfigError(f"{var}={text!r}: {_EXPECTED[name]}") from None
        try:
            return cls(**changes)
        except ConfigError as exc:
            name = next(n for n in _VARIABLES if str(exc).startswith(n))
            raise ConfigError(f"{_VARIABLES[name][0]}: {exc}") from None


def _bytes(text: str) -> int:
    return int(float(text))


def _seconds(text: str) -> float | None:
    return None if text.lower() == "off" else float(text)


def _park(text: str) -> str | None:
    return None if text.lower() == "off" else text


def _flag(text: str) -> bool:
    return text not in ("0", "false", "no", "off")


_VARIABLES = {
    "device": ("LAYERSIM_DEVICE", str),
    "max_memory": ("LAYERSIM_MAX_MEMORY", _bytes),
    "max_seconds": ("LAYERSIM_MAX_SECONDS", _seconds),
    "park_dir": ("LAYERSIM_PARK_DIR", _park),
    "malloc_arenas": ("LAYERSIM_MALLOC_ARENAS", int),
    "threads": ("LAYERSIM_THREADS", int),
    "order_threads": ("LAYERSIM_ORDER_THREADS", int),
    "warp_verbose": ("LAYERSIM_WARP_VERBOSE", _flag),
    "cache_dir": ("LAYERSIM_CACHE_DIR", _park),
}
_EXPECTED = {
    "device": "expected a Warp device name ('cpu', 'cuda' or 'cuda:N')",
    "max_memory": "expected a number of bytes (e.g. 4e9)",
    "max_seconds": "expected a number of seconds (e.g. 600) or 'off'",
    "park_dir": "expected a directory or 'off'",
    "malloc_arenas": "expected an integer >= 0",
    "threads": "expected an integer >= 1",
    "order_threads": "expected an integer >= 1",
    "warp_verbose": "expected 0 or 1",
    "cache_dir": "expected a directory or 'off'",
}

_active: Settings | None = None


def settings() -> Settings:
    """The active settings: the environment's, read on first use, or a :func:`configure`
    block's."""
    global _active
    if _active is None:
        _active = Settings.from_env()
    return _active


@contextlib.contextmanager
def configure(**changes):
    """Override some settings (fields of :class:`Settings`) inside a ``with`` block.

    Raises
    ------
    ConfigError
        For an unknown field or an invalid value, before anything changes.
    """
    global _active
    unknown = sorted(set(changes) - set(_VARIABLES))
    if unknown:
        raise ConfigError(f"unknown setting(s) {', '.join(unknown)}; expected one of "
                          + ", ".join(_VARIABLES))
    before = settings()
    _active = dataclasses.replace(before, **changes)
    try:
        yield _active
    finally:
        _active = before
