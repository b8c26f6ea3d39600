"""Grid files (.npz): reading, checking and writing the samples of grid means, sigma and
length-scale fields, and RGB colour grids.

    values      (nx, ny, nz) float array (RGB grids: (nx, ny, nz, 3)), x index first:
                values[i, j, k] is the sample at origin + voxel_size * (i, j, k); every
                dimension >= 2; finite
    origin      (3,) world position of values[0, 0, 0]
    voxel_size  scalar > 0, the sample spacing (cubic voxels)

Loaders raise ValueError naming the offending array; `problem_of` turns a loader into a
scene File check.
"""
from __future__ import annotations

import numpy as np

from ..gp.kernels import GridField
from ..gp.means import GridMean
from .float_range import MAGNITUDE, array_problem

GRID_KEYS = ("values", "origin", "voxel_size")
MIN_VOXEL = 1e-9


def problem_of(load):
    """A scene File check from a grid loader: None, or why the file is unusable (the
    loader's ValueError, which names the offending array)."""
    def problem(path) -> str | None:
        try:
            load(path)
        except ValueError as exc:
            return str(exc)
        return None
    return problem


def read_grid_arrays(path, keys=GRID_KEYS) -> dict:
    """The arrays of an .npz grid: exactly `keys`, with a valid origin and voxel size
    (ValueError naming the array otherwise). Values are left to the caller to check."""
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: np.asarray(z[k]) for k in z.files}
    except Exception as exc:  # zipfile, pickle and format errors alike
        raise ValueError(f"cannot read as an .npz archive ({type(exc).__name__})") from None
    missing = [k for k in keys if k not in arrays]
    if missing:
        raise ValueError(f"grid lacks array(s) {', '.join(repr(k) for k in missing)} "
                         f"(has: {', '.join(sorted(arrays)) or 'none'})")
    extra = sorted(set(arrays) - set(keys))
    if extra:
        raise ValueError(f"grid has unknown array(s) {', '.join(repr(k) for k in extra)} "
                         f"(expected {', '.join(keys)})")
    origin, h = arrays["origin"], arrays["voxel_size"]
    if origin.shape != (3,) or not np.issubdtype(origin.dtype, np.number) \
            or not np.all(np.isfinite(origin)):
        raise ValueError(f"grid array 'origin' must be 3 finite numbers (got shape "
                         f"{origin.shape})")
    if h.size != 1 or not np.issubdtype(h.dtype, np.number) or not np.isfinite(h.item()) \
            or not h.item() > 0:
        raise ValueError(f"grid array 'voxel_size' must be one positive number (got "
                         f"{h.ravel()[:3].tolist()})")
    # the grid's extent is voxel_size * samples and lookups divide by voxel_size: both
    # must stay within float32 (1e-300 divided by zero, a 1e20 origin vanished)
    if not MIN_VOXEL <= h.item() <= MAGNITUDE:
        raise ValueError(f"grid array 'voxel_size' must be in [{MIN_VOXEL:g}, {MAGNITUDE:g}] "
                         f"(got {h.item():g})")
    problem = array_problem(origin, "grid array 'origin'")
    if problem:
        raise ValueError(problem)
    return arrays


def check_grid_values(values, shape_ok: bool, expected: str, dtype=np.float64) -> np.ndarray:
    """values as dtype if real, finite and of the expected shape; ValueError otherwise."""
    if not shape_ok:
        raise ValueError(f"grid array 'values' must be {expected} (got shape {values.shape})")
    if not np.issubdtype(values.dtype, np.number) or np.iscomplexobj(values):
        raise ValueError(f"grid array 'values' must be real numbers (got {values.dtype})")
    values = values.astype(dtype, copy=False)   # a float32 bake read as float32: no copy
    problem = array_problem(values, "grid array 'values'")
    if problem:
        raise ValueError(problem)
    return values


def load_grid(path, dtype=np.float64) -> GridMean:
    """A GridMean from an .npz file; ValueError naming the array key when it is unusable.
    dtype: of the values (float32 for bakes stored in float32: no double copy)."""
    arrays = read_grid_arrays(path)
    v = arrays["values"]
    values = check_grid_values(v, v.ndim == 3 and min(v.shape) >= 2,
                               "3-D (nx, ny, nz) with every dimension >= 2", dtype)
    return GridMean(values, tuple(float(o) for o in arrays["origin"]),
                    float(arrays["voxel_size"].item()))


def load_field_grid(path):
    """A kernels.GridField (a multiplier of sigma or l) from an .npz file laid out like a
    mean grid; ValueError naming the array when it is unusable, including values <= 0
    (a standard deviation or length scale must stay positive)."""
    arrays = read_grid_arrays(path)
    v = arrays["values"]
    values = check_grid_values(v, v.ndim == 3 and min(v.shape) >= 2,
                               "3-D (nx, ny, nz) with every dimension >= 2")
    if not values.min() > 0.0:
        raise ValueError(f"grid array 'values' must be > 0: it multiplies sigma or the "
                         f"length scale (min {values.min():.4g} at index "
                         f"{list(np.unravel_index(np.argmin(values), values.shape))})")
    return GridField(values, tuple(float(o) for o in arrays["origin"]),
                     float(arrays["voxel_size"].item()))


def save_grid(path, grid: GridMean):
    np.savez(path, values=np.asarray(grid.values), origin=np.asarray(grid.origin, float),
             voxel_size=np.float64(grid.voxel_size))


def load_rgb_grid(path, upper: float | None = None):
    """(values (nx, ny, nz, 3) float64, origin (3,), voxel_size) of an RGB grid file;
    ValueError naming the array when it is unusable. upper: the largest allowed value."""
    arrays = read_grid_arrays(path)
    v = arrays["values"]
    values = check_grid_values(v, v.ndim == 4 and v.shape[3] == 3 and min(v.shape[:3]) >= 2,
                               "(nx, ny, nz, 3): RGB per sample, every n >= 2")
    if values.min() < 0.0:
        raise ValueError(f"grid array 'values' must be >= 0 (min {values.min():.4g})")
    if upper is not None and values.max() > upper:
        raise ValueError(f"grid array 'values' must be <= {upper:g}: a colour multiplies "
                         f"the albedo, which must stay <= 1 (max {values.max():.4g})")
    return values, arrays["origin"].astype(np.float64), float(arrays["voxel_size"].item())


def save_rgb_grid(path, values, origin, voxel_size):
    np.savez_compressed(path, values=np.asarray(values, np.float32),
                        origin=np.asarray(origin, np.float64),
                        voxel_size=np.float64(voxel_size))
