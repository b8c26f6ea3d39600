"""Struct and Queue: one description yields the numpy dtype (host) and the C text (device),
so the two cannot drift apart; tests/test_layouts.py checks the offsets on the device."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PAGE = 4096

# C type name -> (numpy base dtype, element count, alignment in bytes)
_C_TYPES = {
    "int": (np.int32, 1, 4),
    "uint": (np.uint32, 1, 4),
    "float": (np.float32, 1, 4),
    "double": (np.float64, 1, 8),
    "float4": (np.float32, 4, 16),
    "int4": (np.int32, 4, 16),
    "uint4": (np.uint32, 4, 16),
}


@dataclass(frozen=True)
class Struct:
    """A C struct with natural OpenCL alignment; fields are (C type, name) pairs."""

    name: str
    fields: tuple

    @property
    def dtype(self) -> np.dtype:
        names, formats, offsets = [], [], []
        offset, max_align = 0, 4
        for ctype, fname in self.fields:
            base, count, align = _C_TYPES[ctype]
            offset = -(-offset // align) * align
            names.append(fname)
            formats.append((base, (count,)) if count > 1 else base)
            offsets.append(offset)
            offset += np.dtype(base).itemsize * count
            max_align = max(max_align, align)
        size = -(-offset // max_align) * max_align
        return np.dtype({"names": names, "formats": formats, "offsets": offsets,
                         "itemsize": size})

    def c_declaration(self) -> str:
        body = "\n".join(f"    {ctype} {fname};" for ctype, fname in self.fields)
        return f"typedef struct {{\n{body}\n}} {self.name};\n"

    def zeros(self, n: int) -> np.ndarray:
        return np.zeros(n, dtype=self.dtype)

    def page_aligned_zeros(self, n: int) -> np.ndarray:
        """zeros(n) starting on a 4096-byte boundary (numpy's large arrays start 16 bytes
        past one): a CPU device can use such an array in place (render.device.to_device),
        where an unaligned one is copied."""
        raw = np.zeros(n * self.dtype.itemsize + PAGE, np.uint8)
        start = -raw.ctypes.data % PAGE
        return raw[start:start + n * self.dtype.itemsize].view(self.dtype)


@dataclass(frozen=True)
class Queue:
    """A structure-of-arrays work queue: one device buffer per field (kernels take them
    as a group of parameters, layout/stages.py queue)."""

    name: str
    fields: tuple  # (C type, field name)

    def numpy_dtype(self, fname: str) -> np.dtype:
        ctype = dict((f, c) for c, f in self.fields)[fname]
        base, count, _ = _C_TYPES[ctype]
        return np.dtype((base, (count,))) if count > 1 else np.dtype(base)
