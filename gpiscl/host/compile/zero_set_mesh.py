"""The zero set of a GPIS mean inside its proxy as a triangle mesh, for the surface
counterpart of means without a closed-form zero set (compile/classical.py).

The mean (gp/means.py, the host's numpy evaluator of every mean program: primitives, CSG,
transforms, mesh, grid and procedural grids) is sampled on a grid over the proxy's
bounding box and libigl's marching cubes extracts {mu = 0}. A box proxy's grid lies on the
box, so the surface ends at its faces; a sphere or mesh proxy keeps the triangles whose
centroid lies inside it (the cut is accurate to a cell). A cut surface stays open: the
GPIS has no face where its proxy cuts it either (a hit is a crossing into f < 0).

Cell size (docs/design/classical-limits.md, Sec. 4.2): h <= l / CELLS_PER_LENGTH and
h <= extent / CELLS_PER_EXTENT, raised until the grid has at most MAX_CELLS cells.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..gp.means import Mean
from ..io.output_files import write_atomically
from ..scene.proxies import analyse, bounding_proxy

CELLS_PER_LENGTH = 4        # cells across one length scale of the kernel
CELLS_PER_EXTENT = 64       # cells across the proxy's largest extent, at least
MAX_CELLS = 1 << 21         # ~128^3: 2.7 s for the tests' CSG mean (loaded 2-core host)
EVAL_CHUNK = 1 << 18        # points per mean evaluation (bounds the gradient arrays)


@dataclass
class ZeroSetMesh:
    vertices: np.ndarray    # (n, 3) float64
    faces: np.ndarray       # (m, 3) int64, counter-clockwise seen from outside (mu > 0)
    slopes: np.ndarray      # (m,) |grad mu| at each face's centroid
    cell: np.ndarray        # (3,) the grid's cell size per axis
    value_range: tuple      # (min, max) of the mean over the grid, for error messages


def grid_counts(lo, hi, length_scale: float) -> np.ndarray:
    """Samples per axis over [lo, hi]: cells of at most min(l / CELLS_PER_LENGTH,
    extent / CELLS_PER_EXTENT), coarsened to at most MAX_CELLS cells in all."""
    extent = np.asarray(hi, float) - np.asarray(lo, float)
    h = min(length_scale / CELLS_PER_LENGTH, float(extent.max()) / CELLS_PER_EXTENT)
    cells = np.maximum(np.ceil(extent / h), 1.0)
    total = float(np.prod(cells))
    if total > MAX_CELLS:
        cells = np.maximum(np.floor(cells * (MAX_CELLS / total) ** (1.0 / 3.0)), 1.0)
    return cells.astype(np.int64) + 1


def proxy_distance(proxy: dict, x: np.ndarray) -> np.ndarray:
    """Signed distance bound to a sphere, box or convex mesh proxy, negative inside."""
    if proxy["type"] == "sphere":
        return np.linalg.norm(x - np.asarray(proxy["center"], float), axis=-1) - proxy["radius"]
    if proxy["type"] == "mesh":
        planes = np.asarray(analyse(proxy)[0], float)
        return np.max(x @ planes[:, :3].T - planes[:, 3], axis=-1)
    lo, hi = np.asarray(proxy["min"], float), np.asarray(proxy["max"], float)
    return np.max(np.maximum(lo - x, x - hi), axis=-1)


def mean_values(mean: Mean, points: np.ndarray) -> np.ndarray:
    return np.concatenate([np.zeros(0)] + [mean.value(points[i:i + EVAL_CHUNK])
                                           for i in range(0, len(points), EVAL_CHUNK)])


def mean_gradients(mean: Mean, points: np.ndarray) -> np.ndarray:
    return np.concatenate([np.zeros((0, 3))] + [mean.gradient(points[i:i + EVAL_CHUNK])
                                                for i in range(0, len(points), EVAL_CHUNK)])


def zero_set_mesh(mean: Mean, proxy: dict, length_scale: float) -> ZeroSetMesh:
    """{mean = 0} inside a box, sphere or convex mesh proxy (classical.py refuses a scene
    proxy: its box is known only when the scene compiles)."""
    import igl
    box = bounding_proxy(proxy)
    if box["type"] == "box":
        lo, hi = np.asarray(box["min"], float), np.asarray(box["max"], float)
    else:
        lo = np.asarray(box["center"], float) - box["radius"]
        hi = np.asarray(box["center"], float) + box["radius"]
    n = grid_counts(lo, hi, length_scale)
    axes = [np.linspace(lo[i], hi[i], n[i]) for i in range(3)]
    # igl's layout: x fastest (S(x + y nx + z nx ny))
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    values = mean_values(mean, points)
    verts, faces, _ = igl.marching_cubes(values, points, int(n[0]), int(n[1]), int(n[2]), 0.0)
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    verts = np.asarray(verts, float)
    # marching cubes makes zero-area triangles where the surface passes through grid
    # points (192 of 60296 on a unit sphere at h = 0.025): nothing to hit, no normal
    tri = verts[faces]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=-1)
    faces = faces[area2 > 1e-9 * float(np.max(hi - lo) / np.max(n)) ** 2]
    if len(faces) and proxy["type"] != "box":
        centroids = verts[faces].mean(axis=1)
        faces = faces[proxy_distance(proxy, centroids) <= 0.0]
    used = np.unique(faces)
    remap = np.full(len(verts), -1, np.int64)
    remap[used] = np.arange(len(used))
    verts, faces = verts[used], remap[faces]
    tri = verts[faces]
    grad = mean_gradients(mean, tri.mean(axis=1))
    # wound so that face normals point up the mean's gradient (outside): igl's winding is
    # checked against the mean rather than assumed
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    if np.sum(np.einsum("ij,ij->i", normal, grad)) < 0.0:
        faces = faces[:, ::-1]
    cell = (hi - lo) / np.maximum(n - 1, 1)
    return ZeroSetMesh(verts, faces, np.linalg.norm(grad, axis=-1), cell,
                       (float(values.min()), float(values.max())))


def write_obj(verts: np.ndarray, faces: np.ndarray, folder: Path) -> Path:
    """A plain OBJ named by the sha256 of its text in folder (written once, atomically:
    concurrent renders never see half a file). OSError or SceneError if it cannot be."""
    lines = [f"v {a!r} {b!r} {c!r}" for a, b, c in verts.tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces.tolist()]
    text = ("\n".join(lines) + "\n").encode()
    path = folder / f"{hashlib.sha256(text).hexdigest()[:32]}.obj"
    if not path.exists():
        write_atomically(path, lambda tmp: Path(tmp).write_bytes(text))
    return path
