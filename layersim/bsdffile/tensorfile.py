"""The ``tensor_file`` container of the RGL material format (Dupuy & Jakob 2018): named
n-dimensional arrays in one little-endian binary file, as Mitsuba 3 (``TensorFile``,
``src/core/tensor.cpp``) and pbrt-v4 (``Tensor``, ``src/pbrt/bxdfs.cpp``) read it.

Byte layout
-----------
======================  ===================================================================
``char[12]``            ``b"tensor_file\\0"``
``uint8[2]``            version: ``1, 0`` (pbrt-v4 accepts nothing else)
``uint32``              number of fields
per field               ``uint16`` name length, the name (ASCII, no terminator), ``uint16``
                        ndim, ``uint8`` dtype (below), ``uint64`` byte offset of the data
                        from the start of the file, ``ndim x uint64`` shape
data                    each field's values, C order (last axis fastest), at its offset
======================  ===================================================================

Dtype codes (both readers): 1 uint8, 2 int8, 3 uint16, 4 int16, 5 uint32, 6 int32, 7 uint64,
8 int64, 9 float16, 10 float32, 11 float64 (0 is invalid). The writer places every field's
data at an offset that is a multiple of 8 bytes: Mitsuba maps the file into memory and reads
the arrays in place.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from ..errors import FileFormatError
from .rawfile import read_bytes

MAGIC = b"tensor_file\0"
VERSION = (1, 0)
DTYPES = {1: np.uint8, 2: np.int8, 3: np.uint16, 4: np.int16, 5: np.uint32, 6: np.int32,
          7: np.uint64, 8: np.int64, 9: np.float16, 10: np.float32, 11: np.float64}
CODES = {np.dtype(t): c for c, t in DTYPES.items()}
ALIGN = 8


def _header_size(fields: dict) -> int:
    return 12 + 2 + 4 + sum(2 + len(name) + 2 + 1 + 8 + 8 * np.ndim(a)
                            for name, a in fields.items())


def to_bytes(fields: dict) -> bytes:
    """The file holding ``fields`` (name -> numpy array of a dtype listed above), in the
    order given."""
    arrays = {name: np.ascontiguousarray(a) for name, a in fields.items()}
    for name, a in arrays.items():
        if a.dtype not in CODES:
            raise TypeError(f"tensor field {name!r}: dtype {a.dtype} has no tensor_file code")
    offset = _header_size(arrays)
    head = [MAGIC, bytes(VERSION), struct.pack("<I", len(arrays))]
    body, offsets = [], {}
    for name, a in arrays.items():
        offset += -offset % ALIGN
        offsets[name] = offset
        offset += a.nbytes
    pos = _header_size(arrays)
    for name, a in arrays.items():
        key = name.encode("ascii")
        head.append(struct.pack("<H", len(key)) + key
                    + struct.pack("<HBQ", a.ndim, CODES[a.dtype], offsets[name])
                    + struct.pack(f"<{a.ndim}Q", *a.shape))
        body.append(b"\0" * (offsets[name] - pos))
        body.append(a.astype(a.dtype.newbyteorder("<"), copy=False).tobytes())
        pos = offsets[name] + a.nbytes
    return b"".join(head + body)


def write(path, fields: dict) -> Path:
    """Write ``fields`` as a tensor file at ``path``."""
    path = Path(path)
    path.write_bytes(to_bytes(fields))
    return path


def from_bytes(data: bytes, source: str = "tensor file") -> dict:
    """The fields of a tensor file (name -> numpy array), checked against its size."""
    def fail(why):
        raise FileFormatError(f"{source}: not a valid tensor file ({why})")

    if len(data) < 18 or data[:12] != MAGIC:
        fail("no 'tensor_file' header")
    if tuple(data[12:14]) != VERSION:
        fail(f"version {tuple(data[12:14])}, expected {VERSION}")
    (count,) = struct.unpack_from("<I", data, 14)
    pos, fields = 18, {}
    for _ in range(count):
        try:
            (length,) = struct.unpack_from("<H", data, pos)
            name = data[pos + 2:pos + 2 + length].decode("ascii")
            pos += 2 + length
            ndim, code, offset = struct.unpack_from("<HBQ", data, pos)
            pos += 11
            shape = struct.unpack_from(f"<{ndim}Q", data, pos)
            pos += 8 * ndim
        except (struct.error, UnicodeDecodeError) as exc:
            fail(f"truncated or garbled field table: {exc}")
        if code not in DTYPES:
            fail(f"field {name!r} has dtype code {code}")
        dtype = np.dtype(DTYPES[code]).newbyteorder("<")
        size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        if offset + size > len(data):
            fail(f"field {name!r} runs past the end of the file")
        fields[name] = np.frombuffer(data, dtype, int(np.prod(shape, dtype=np.int64)),
                                     offset).reshape(shape).astype(dtype.newbyteorder("="))
    return fields


def read(path) -> dict:
    """Read the fields of the tensor file at ``path``."""
    return from_bytes(read_bytes(path), source=str(path))
