"""Write a scene dict (the format of ``docs/conventions.md``) as TOML text.

The scene format needs only a small part of TOML: top-level tables (``[stack]``,
``[discretization]``), arrays of tables (``[[layer]]``) and values that are strings, booleans,
numbers, arrays and inline tables (a film). ``tomllib`` reads the text back to the same dict.
"""

from __future__ import annotations

import json
import math
from typing import Any, Mapping

__all__ = ["dumps"]


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"TOML scene values must be finite, got {v!r}")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)        # a TOML basic string has JSON's escapes
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{k} = {_value(x)}" for k, x in v.items()) + " }"
    raise ValueError(f"cannot write {type(v).__name__} {v!r} as a TOML scene value")


def _table(d: Mapping[str, Any]) -> list[str]:
    return [f"{k} = {_value(v)}" for k, v in d.items()]


def dumps(scene: Mapping[str, Any], header: str = "") -> str:
    """TOML text of ``scene``: its tables (dict values) and arrays of tables (lists of dicts),
    each key with a value of :func:`_value`; ``header`` lines become comments on top."""
    lines = [f"# {x}" if x else "#" for x in header.splitlines()]
    plain = {k: v for k, v in scene.items() if not isinstance(v, (Mapping, list))}
    lines += _table(plain)
    for key, value in scene.items():
        if isinstance(value, Mapping):
            lines += ["", f"[{key}]", *_table(value)]
        elif isinstance(value, list):
            for item in value:
                lines += ["", f"[[{key}]]", *_table(item)]
    return "\n".join(lines).lstrip("\n") + "\n"
