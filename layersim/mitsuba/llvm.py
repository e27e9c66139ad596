"""Where Dr.Jit finds LLVM for Mitsuba 3's ``llvm_*`` variants.

Dr.Jit's LLVM backend loads ``libLLVM`` (>= 16) at run time, from ``$DRJIT_LIBLLVM_PATH`` or
a few standard names; Debian 12's ``libllvm19`` installs it as
``/usr/lib/x86_64-linux-gnu/libLLVM-19.so``, a name Dr.Jit does not try.
"""

from __future__ import annotations

import glob
import os

#: Where system packages put libLLVM 16 or later.
PATTERNS = ("/usr/lib/x86_64-linux-gnu/libLLVM-1[6-9]*.so*",
            "/usr/lib/x86_64-linux-gnu/libLLVM-2[0-9]*.so*",
            "/usr/lib/llvm-1[6-9]/lib/libLLVM*.so*")


def find_libllvm() -> str | None:
    """``$DRJIT_LIBLLVM_PATH`` if set, else the newest system libLLVM >= 16, else None."""
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return os.environ["DRJIT_LIBLLVM_PATH"]
    for pattern in PATTERNS:
        found = sorted(glob.glob(pattern))
        if found:
            return found[-1]
    return None


def point_drjit_to_llvm() -> None:
    """Set ``DRJIT_LIBLLVM_PATH`` for this process where it is unset and a libLLVM is found
    (before Dr.Jit first starts its LLVM backend)."""
    path = find_libllvm()
    if path:
        os.environ.setdefault("DRJIT_LIBLLVM_PATH", path)
