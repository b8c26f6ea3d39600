"""OpenVDB grids -> the .npz grids gpiscl reads (io/grids.load_grid's layout).

No PyPI package reads .vdb files correctly today, so this needs OpenVDB's own Python
binding (module `openvdb`, or `pyopenvdb` in releases up to 10): Debian's and Ubuntu's
python3-openvdb package ships it for the system Python (which is why this module and the
convert-vdb command import nothing beyond numpy and gpiscl's own grid code), as do
conda-forge's `openvdb` package and builds of OpenVDB with OPENVDB_BUILD_PYTHON_MODULE=ON.
Without it the command says so instead of guessing at the file format.

The active bounding box of one float grid is copied to a dense array (x index first);
voxels outside the active set take the grid's background value, as the authors' renderer
does for inactive voxels. Only uniform, axis-aligned voxel transforms are accepted: the
.npz layout has one voxel size and an origin.
"""
from __future__ import annotations

import importlib

import numpy as np

from .grids import save_grid
from ..gp.means import GridMean
from ..errors import SceneError

HOW_TO_GET = ("no OpenVDB Python binding could be imported (modules 'openvdb' or "
              "'pyopenvdb'); install one: on Debian or Ubuntu `apt install python3-openvdb` "
              "and run this under the system Python (/usr/bin/python3 -m gpiscl convert-vdb "
              "..., with gpiscl on PYTHONPATH: it needs only numpy there), or "
              "`conda install -c conda-forge openvdb`, or build OpenVDB with "
              "-DOPENVDB_BUILD_PYTHON_MODULE=ON (no PyPI package reads .vdb files correctly)")


def import_openvdb():
    for name in ("openvdb", "pyopenvdb"):
        try:
            return importlib.import_module(name)
        except ImportError:
            continue
    return None


def convert_vdb(src: str, dst: str, grid_name: str | None = None) -> dict:
    """Write grid `grid_name` (default: the only grid, or "density") of src to dst (.npz)."""
    vdb = import_openvdb()
    if vdb is None:
        raise SceneError(src, "", HOW_TO_GET)
    try:
        grids, _meta = vdb.readAll(src)
    except Exception as exc:  # the binding raises its own types for unreadable files
        raise SceneError(src, "", f"cannot read as a .vdb file ({exc})") from None
    names = [g.name for g in grids]
    if grid_name is None:
        grid_name = names[0] if len(names) == 1 else "density"
    if grid_name not in names:
        raise SceneError(src, grid_name, f"no such grid (has: {', '.join(names) or 'none'})")
    grid = grids[names.index(grid_name)]
    lo, hi = (np.asarray(c, int) for c in grid.evalActiveVoxelBoundingBox())
    shape = tuple(int(n) for n in hi - lo + 1)
    if min(shape) < 2:
        raise SceneError(src, grid_name, f"active region {shape} is too thin for a grid")
    voxel = np.asarray(grid.transform.voxelSize(), float)
    if not np.allclose(voxel, voxel[0], rtol=1e-6):
        raise SceneError(src, grid_name, f"non-uniform voxel size {voxel.tolist()}")
    origin = np.asarray(grid.transform.indexToWorld(tuple(int(v) for v in lo)), float)
    step = np.asarray(grid.transform.indexToWorld(tuple(int(v) + 1 for v in lo)), float) - origin
    if not np.allclose(step, voxel, rtol=1e-6):
        raise SceneError(src, grid_name, "rotated voxel transforms are not supported")
    values = np.full(shape, float(grid.background), np.float64)
    grid.copyToArray(values, ijk=tuple(int(v) for v in lo))
    try:
        save_grid(dst, GridMean(values, tuple(origin), float(voxel[0])))
    except ValueError as exc:  # NaN samples and the like
        raise SceneError(src, grid_name, str(exc)) from None
    return {"grid": grid_name, "shape": shape, "origin": origin.tolist(),
            "voxel_size": float(voxel[0])}
