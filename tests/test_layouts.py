"""The host's numpy dtypes and the device's structs agree field by field."""
import numpy as np
import pyopencl as cl
import pytest

from gpiscl.host.layout import function_space_records, gp_records
from gpiscl.host.layout import records as layouts
from gpiscl.host.layout.struct import Struct


def _offset_kernel(struct) -> str:
    # OpenCL C has no offsetof: measure addresses within a private instance.
    lines = [f"{struct.name} s;", f"out[0] = sizeof({struct.name});"]
    for i, (_, fname) in enumerate(struct.fields):
        lines.append(f"out[{i + 1}] = (int)((char*)&s.{fname} - (char*)&s);")
    body = "\n    ".join(lines)
    return f"__kernel void offsets_{struct.name}(__global int* out) {{\n    {body}\n}}\n"


def test_every_struct_is_measured():
    """ALL_STRUCTS holds every Struct the layout modules define, each once."""
    defined = {v.name for m in (layouts, gp_records, function_space_records)
               for v in vars(m).values() if isinstance(v, Struct)}
    names = [s.name for s in layouts.ALL_STRUCTS]
    assert len(names) == len(set(names))
    assert set(names) == defined


@pytest.mark.parametrize("struct", layouts.ALL_STRUCTS, ids=lambda s: s.name)
def test_struct_offsets_match_device(device, struct):
    src = (layouts.c_header() + function_space_records.c_declarations()
           + _offset_kernel(struct))
    prg = cl.Program(device.ctx, src).build()
    out = np.zeros(len(struct.fields) + 1, np.int32)
    buf = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    getattr(prg, f"offsets_{struct.name}")(device.queue, (1,), None, buf)
    cl.enqueue_copy(device.queue, out, buf)
    dtype = struct.dtype
    assert out[0] == dtype.itemsize
    assert list(out[1:]) == [dtype.fields[f][1] for _, f in struct.fields]


