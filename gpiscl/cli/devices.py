"""gpiscl devices: the OpenCL devices present (api.devices), the default marked."""
from __future__ import annotations

from .. import api


def add_parser(sub):
    return sub.add_parser("devices", help="list OpenCL platforms and devices")


def run(_a) -> int:
    found = api.devices()
    if not found:
        print("no OpenCL devices found; pip install 'pyopencl[pocl]' for the CPU runtime")
        return 1
    for d in found:
        mark = "*" if d["default"] else " "
        print(f"{mark} {d['index']}  {d['platform']} / {d['name']}  [{d['type']}, "
              f"{d['compute_units']} compute units]")
    print("* default (override with --device P:D, cpu or gpu, or PYOPENCL_CTX)")
    return 0
