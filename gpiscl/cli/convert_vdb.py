"""gpiscl convert-vdb: one float grid of a .vdb file to an .npz grid (api.convert_vdb).
Runs under a Python with numpy and an OpenVDB binding but no pyopencl or OpenEXR."""
from __future__ import annotations

import sys

from .. import api


def add_parser(sub):
    v = sub.add_parser("convert-vdb", help="an OpenVDB grid to the .npz grid format",
                       description="Copy one float grid of a .vdb file to an .npz grid "
                       "(values, origin, voxel_size) usable as a grid mean. Needs OpenVDB's "
                       "Python binding.")
    v.add_argument("input", help=".vdb file")
    v.add_argument("output", help=".npz file to write")
    v.add_argument("--grid", help="grid name (default: the only grid, or 'density')")
    return v


def run(a) -> int:
    info = api.convert_vdb(a.input, a.output, a.grid)
    print(f"wrote {a.output}: grid '{info['grid']}', {info['shape']} samples, voxel "
          f"{info['voxel_size']:g}, origin {info['origin']}", file=sys.stderr)
    return 0
