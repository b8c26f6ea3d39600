"""gpiscl convert-tungsten: a scene of the authors' Tungsten-based renderer as a gpiscl
scene file (api.convert_tungsten)."""
from __future__ import annotations

import sys

from .. import api


def add_parser(sub):
    t = sub.add_parser("convert-tungsten", help="a Tungsten (the paper's renderer) scene as "
                       "a gpiscl scene",
                       description="Convert the GPIS subset of a scene of the authors' "
                       "Tungsten-based renderer (gpis-light-transport) to a gpiscl scene "
                       "file; lossy mappings are printed as notes, and nothing is written "
                       "on an error.")
    t.add_argument("scene", help="Tungsten scene JSON")
    t.add_argument("output", help="gpiscl scene JSON to write")
    t.add_argument("--environment", help="substitute environment: a radiance, or an .exr or "
                   ".hdr map")
    t.add_argument("--grid-dir", help="where .npz grids converted from .vdb grids go "
                   "(default: the output's folder)")
    return t


def run(a) -> int:
    for note in api.convert_tungsten(a.scene, a.output, a.environment, a.grid_dir):
        print(f"note: {note}", file=sys.stderr)
    print(f"wrote {a.output}", file=sys.stderr)
    return 0
