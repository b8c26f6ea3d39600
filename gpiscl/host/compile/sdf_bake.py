"""Grid means of triangle meshes and procedural functions: bakes, cached, and every
grid's per-cell slope bounds, cached.

Mesh bake: the mesh (transform applied to its vertices, so any affine map keeps exact
distances) is sampled on a cubic-voxel grid over its bounds plus a margin, with libigl's
signed_distance (positive outside). The sign: a watertight, consistently wound mesh uses
pseudonormals (exact, fastest; inward-wound closed meshes are flipped first); any other
mesh uses the generalized winding number w (libigl): inside where w > 1/2, which is the
documented rule for open or self-intersecting meshes and agrees with the closed case (open
meshes must be wound counter-clockwise seen from outside, as closed ones usually are).
Bakes are cached in $GPISCL_CACHE/sdf (default ~/.cache/gpiscl/sdf), keyed by the sha256
of the mesh file's bytes and the bake settings.

Procedural bakes (gp/knob.py's functions, procedural_mean) are cached in
$GPISCL_CACHE/procedural, keyed by the sha256 of knob.py's source and the settings; the
slope bounds of any grid mean (its brick bounds and lipschitz, and the cubic coefficients
they are taken from: seconds of numpy at 128^3, every time a scene is loaded) in
$GPISCL_CACHE/slopes, keyed by the grid's values, placement and interpolation and the
source of gp/means.py that computes them (prepare_slopes). A warm start then reads the
small brick bounds instead of recomputing them (docs/design/bakes.md, 'Caches').
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
from pathlib import Path

import numpy as np

from ..gp import knob, means
from ..gp.means import GridMean
from ..io.grids import load_grid, save_grid
from ..io.meshes import load_mesh
from ..layout.gp_records import GRID_BRICK

BAKE_VERSION = 1            # part of the cache key: bump when the bake's output changes
DEFAULT_MARGIN = 0.1        # of the mesh's largest bounding-box extent, per side


def cache_dir(kind: str = "sdf") -> Path:
    """The cache folder of one kind of bake ("sdf", "procedural", "slopes")."""
    root = os.environ.get("GPISCL_CACHE") or os.path.join(os.path.expanduser("~"), ".cache",
                                                          "gpiscl")
    return Path(root) / kind


def _store(path: Path, write, what: str) -> None:
    """write(tmp) then an atomic rename onto path: concurrent renders never see half a
    file, and a failure leaves no temporary behind. A read-only cache costs time, not the
    render: it is reported and skipped."""
    tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        print(f"gpiscl: cannot cache the {what} in {path.parent} ({exc.strerror}); "
              "set GPISCL_CACHE to a writable folder", file=sys.stderr)
    finally:                                # a full disk or a signal: no half file left
        tmp.unlink(missing_ok=True)


def _settings_key(settings: dict, *blobs) -> str:
    """sha256 over the blobs (bytes-like) and the settings as sorted JSON."""
    digest = hashlib.sha256()
    for b in blobs:
        digest.update(hashlib.sha256(b).digest())
    digest.update(json.dumps(settings, sort_keys=True).encode())
    return digest.hexdigest()


# ---- mesh bakes ------------------------------------------------------------------------

def grid_box(lo, hi, resolution: int, margin: float):
    """(origin, voxel size, counts): cubic voxels, `resolution` samples along the longest
    axis of [lo - margin, hi + margin], the box grown to whole voxels on the other axes."""
    lo, hi = np.asarray(lo, float) - margin, np.asarray(hi, float) + margin
    h = float(np.max(hi - lo)) / (resolution - 1)
    counts = np.maximum(np.ceil((hi - lo) / h - 1e-9).astype(int) + 1, 2)
    centre = 0.5 * (lo + hi)
    origin = centre - 0.5 * h * (counts - 1)
    return origin, h, counts


# points per libigl call: libigl holds the GIL for a whole call (a 256^3 bake is minutes on
# two cores), so Ctrl-C and SIGTERM could act only at its end; between chunks the signal
# handlers run (signals.py). Each point's distance is independent: results do not change.
BAKE_CHUNK = 1 << 16


def _signed_distance(points, verts, faces, watertight: bool, band=None) -> np.ndarray:
    if len(points) <= BAKE_CHUNK:
        return _signed_distance_chunk(points, verts, faces, watertight, band)
    return np.concatenate([_signed_distance_chunk(points[i:i + BAKE_CHUNK], verts, faces,
                                                  watertight, band)
                           for i in range(0, len(points), BAKE_CHUNK)])


def _signed_distance_chunk(points, verts, faces, watertight: bool, band=None) -> np.ndarray:
    import igl
    t = igl.SignedDistanceType
    sign = (t.SIGNED_DISTANCE_TYPE_PSEUDONORMAL if watertight
            else t.SIGNED_DISTANCE_TYPE_WINDING_NUMBER)
    if band is None or not watertight:
        # libigl 2.6.3's bounded winding-number query drops some points inside the band
        # (|d| > ~0.7 band, seen here), so open meshes take the full query and the clamp
        sd = igl.signed_distance(points, verts, faces, sign)[0]
        return sd if band is None else np.clip(sd, -band, band)
    # Narrow band: the bounded search skips faces farther than `band` (docs/design/bakes.md,
    # 'Mesh bakes') but leaves far points NaN, without a sign. Those are >= band from the surface,
    # where the fast winding number's far-field approximation cannot tip w across 1/2.
    sd = igl.signed_distance(points, verts, faces, sign, -band, band)[0]
    far = ~np.isfinite(sd)
    if np.any(far):
        w = igl.fast_winding_number(verts, faces, points[far])
        sd[far] = np.where(w > 0.5, -band, band)
    return np.clip(sd, -band, band)


def bake_mesh(verts, faces, resolution: int = 128, margin: float | None = None,
              band: float | None = None) -> GridMean:
    """Signed-distance GridMean of a triangle mesh (world units, positive outside).
    band: distances are clamped to [-band, band] (a narrow-band level set; faster)."""
    import trimesh
    mesh = trimesh.Trimesh(np.asarray(verts, float), np.asarray(faces, np.int64), process=True)
    watertight = bool(mesh.is_watertight and mesh.is_winding_consistent)
    if watertight and mesh.volume < 0:      # wound inward: the pseudonormals would flip
        mesh.invert()
    if not len(mesh.faces) or not np.ptp(mesh.vertices, axis=0).any():
        # trimesh merges corners closer than tol.merge: a tiny (or tinily scaled) mesh
        # collapses to a point, whose bake box would have no size
        extent = float(np.max(np.ptp(np.asarray(verts, float), axis=0)))
        raise ValueError(f"the mesh has no extent once corners closer than "
                         f"{trimesh.tol.merge:g} are merged (its size after the transform "
                         f"is {extent:g})")
    lo, hi = mesh.bounds
    if margin is None:
        margin = DEFAULT_MARGIN * float(np.max(hi - lo))
    origin, h, counts = grid_box(lo, hi, resolution, margin)
    axes = [origin[a] + h * np.arange(counts[a]) for a in range(3)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    sd = _signed_distance(points, np.asarray(mesh.vertices, float),
                          np.asarray(mesh.faces, np.int64), watertight, band)
    return GridMean(sd.reshape(tuple(counts)), tuple(origin), h)


def bake_key(path, resolution, margin, band, object_to_world) -> str:
    settings = {"version": BAKE_VERSION, "resolution": int(resolution),
                "margin": None if margin is None else float(margin),
                "band": None if band is None else float(band),
                "transform": None if object_to_world is None
                else np.asarray(object_to_world, float)[:3].tolist()}
    digest = hashlib.sha256(Path(path).read_bytes())
    digest.update(json.dumps(settings, sort_keys=True).encode())
    return digest.hexdigest()


def mesh_mean(path, resolution: int = 128, margin: float | None = None,
              band: float | None = None, object_to_world=None, cache: bool = True):
    """The baked GridMean of a mesh file, from the cache when an equal bake exists.
    Returns (grid, cache_hit)."""
    key = bake_key(path, resolution, margin, band, object_to_world)
    cached = cache_dir() / f"{key}.npz"
    if cache and cached.is_file():
        try:
            return load_grid(cached), True
        except ValueError:
            pass                            # a damaged entry: bake again and replace it
    verts, faces = load_mesh(path)
    if object_to_world is not None:
        m = np.asarray(object_to_world, float)
        verts = verts @ m[:3, :3].T + m[:3, 3]
    try:
        grid = bake_mesh(verts, faces, resolution, margin, band)
    except ValueError as exc:
        raise ValueError(f"{exc}: {path}") from None
    # float32, as the device holds it: a render from the cache equals the first one
    grid = GridMean(np.asarray(grid.values, np.float32).astype(np.float64), grid.origin,
                    grid.voxel_size)
    if cache:
        _store(cached, lambda tmp: save_grid(tmp, GridMean(np.asarray(grid.values, np.float32),
                                                           grid.origin, grid.voxel_size)),
               "SDF bake")
    return grid, False


# ---- procedural bakes --------------------------------------------------------------------

def procedural_mean(function: str, resolution: int, cache: bool = True, bakes=None):
    """knob.knob_grid(function, resolution), from the cache when an equal bake exists (the
    function's source unchanged). Returns (grid, cache_hit); the grid is the same float32
    array either way. bakes: a device's bakes (render/device_bakes.py: the same samples bit
    for bit) to bake with instead of numpy."""
    key = _settings_key({"version": BAKE_VERSION, "function": function,
                         "resolution": int(resolution)}, Path(knob.__file__).read_bytes())
    cached = cache_dir("procedural") / f"{key}.npz"
    if cache and cached.is_file():
        try:
            return load_grid(cached, np.float32), True
        except ValueError:
            pass
    grid = (bakes.procedural if bakes is not None else knob.knob_grid)(function, resolution)
    if cache:
        _store(cached, lambda tmp: save_grid(tmp, grid), "procedural bake")
    return grid, False


# ---- slope bounds of grid means ------------------------------------------------------------

def _slopes_key(grid: GridMean) -> str:
    values = np.ascontiguousarray(grid.values)
    settings = {"version": BAKE_VERSION, "shape": list(values.shape), "dtype": str(values.dtype),
                "origin": [float(o) for o in grid.origin], "voxel": float(grid.voxel_size),
                "interpolation": grid.interpolation, "brick": GRID_BRICK}
    # the array's own buffer, not a tobytes() copy of a whole grid
    return _settings_key(settings, memoryview(values).cast("B"),
                         Path(means.__file__).read_bytes())


_SLAB_CELLS = 4   # x layers of cells per means.cubic_cell_bounds pass


def _cubic_cell_bounds_in_slabs(coef: np.ndarray, h: float) -> np.ndarray:
    """means.cubic_cell_bounds over slabs of _SLAB_CELLS x layers: a cell's bound reads only
    its 4^3 coefficients, so each slab takes its cells' layers plus 3 and computes the same
    numbers; the ~50 full-grid temporaries then stay in cache (docs/design/bakes.md,
    'Slabs')."""
    cells = coef.shape[0] - 3
    return np.concatenate([means.cubic_cell_bounds(coef[i:i + _SLAB_CELLS + 3], h)
                           for i in range(0, cells, _SLAB_CELLS)])


_LINEAR_SLAB_CELLS = 16   # x layers of cells per means._corner_gradients2 pass


def _linear_slopes_in_slabs(values: np.ndarray, h: float):
    """(means.cell_slope_bounds, GridMean.lipschitz) of a trilinear grid, over slabs of
    _LINEAR_SLAB_CELLS x layers: a cell's bound reads its 8 corners only, so each slab
    takes its cells' layers plus 1 and computes the same numbers, and the largest squared
    corner gradient of all slabs is the whole grid's (bit for bit: tests/test_bake_cache).
    The whole-grid form held far more float64 temporaries (docs/design/bakes.md, 'Slabs')."""
    cells, parts, inner2 = values.shape[0] - 1, [], 0.0
    for i in range(0, cells, _LINEAR_SLAB_CELLS):
        c2 = means._corner_gradients2(np.asarray(values[i:i + _LINEAR_SLAB_CELLS + 1],
                                                 np.float64))
        inner2 = max(inner2, float(np.max(c2)))
        parts.append(np.sqrt(c2) / h)
    return np.concatenate(parts), means.grid_slope_bound(values, h, inner2)


def prepare_slopes(grid: GridMean, cache: bool = True, bakes=None) -> bool:
    """Give grid what its device records need (gp_records._grid_leaf): its whole-grid slope
    bound `lipschitz`, its brick bounds (means.brick_slope_bounds at GRID_BRICK) and, cubic,
    the coefficients they come from; from the cache when present, else computed and cached.
    They are GridMean's memoised values (cached_property, brick_bounds), which live in the
    instance once computed; setting them there is what computing them would do, with the
    same values. The cell bounds they are taken from are not kept (64 times the bricks'
    bytes; GridMean.cell_bounds recomputes them if asked). bakes: a device's bakes
    (render/device_bakes.py) for a trilinear grid's bounds, the same numbers bit for bit.
    Returns cache_hit."""
    names = ("bricks", "lipschitz") + (("coefficients",) if grid.interpolation == "cubic"
                                       else ())
    cached = cache_dir("slopes") / f"{_slopes_key(grid)}.npz"
    if cache and cached.is_file():
        try:
            with np.load(cached, allow_pickle=False) as z:
                arrays = {n: np.asarray(z[n]) for n in names}
            grid.__dict__["lipschitz"] = float(arrays["lipschitz"])
            grid.brick_bounds[GRID_BRICK] = arrays["bricks"]
            if "coefficients" in arrays:
                grid.__dict__["coefficients"] = arrays["coefficients"]
            return True
        except (OSError, ValueError, KeyError, TypeError):
            pass                            # damaged or older: compute again and replace it
    h = float(grid.voxel_size)
    if grid.interpolation == "linear" and bakes is not None:
        bricks, lipschitz = bakes.linear_slopes(grid.values, h, GRID_BRICK)
        grid.brick_bounds[GRID_BRICK], grid.__dict__["lipschitz"] = bricks, lipschitz
    elif grid.interpolation == "cubic":
        grid.__dict__["cell_bounds"] = _cubic_cell_bounds_in_slabs(grid.coefficients, h)
    else:
        grid.__dict__["cell_bounds"], grid.__dict__["lipschitz"] = \
            _linear_slopes_in_slabs(grid.values, h)
    arrays = {"bricks": means.brick_slope_bounds(grid, GRID_BRICK),
              "lipschitz": np.float64(grid.lipschitz)}
    if grid.interpolation == "cubic":
        arrays["coefficients"] = grid.coefficients
    grid.__dict__.pop("cell_bounds", None)
    if cache:
        _store(cached, lambda tmp: np.savez(tmp, **arrays), "grid slope bounds")
    return False
