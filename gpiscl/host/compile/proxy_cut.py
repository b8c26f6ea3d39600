"""Does a GPIS object's proxy cut it? Rays sample an object only inside its proxy, so
where realizations have f < 0 on the proxy's boundary the render shows a flat cut face
there, which is right for a medium's container (the authors' wedge, a room of fog) and a
silent error for a proxy drawn too tight around a surface. compile/gpis.py warns unless
the scene says the cut is meant (the object's "clip": true).

The test is the occupancy bound's (compile/gpis.py occupancy_level) point by point: the
object can be present at a boundary point x where P(f(x) < 0) = Phi(-m(x) / sd(x)) >=
epsilon (the scene's occupancy epsilon, else its default), with the prior's mean and sd
there (sigma(x) fields included; occupancy_level's sigma_max flagged the bunny's and the
baked CSG's boundaries where sigma(x) is smaller). Points are spread over the boundary by
area, with a fixed seed: the same scene warns the same way every run.
"""
from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np

from ..scene.transforms import mesh_triangles

BOUNDARY_POINTS = 4096


def boundary_points(proxy: dict, n: int = BOUNDARY_POINTS, seed: int = 0):
    """(n, 3) points spread uniformly by area over a box, sphere or mesh proxy's surface;
    None for the unbounded "scene" proxy (its box is the scene's, not a cut)."""
    rng = np.random.default_rng(seed)
    if proxy["type"] == "scene":
        return None
    if proxy["type"] == "mesh":
        tris = mesh_triangles(proxy)
        area = 0.5 * np.linalg.norm(np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]),
                                    axis=1)
        pick = rng.choice(len(tris), size=n, p=area / area.sum())
        u, v = rng.random(n), rng.random(n)
        flip = u + v > 1.0
        u, v = np.where(flip, 1.0 - u, u), np.where(flip, 1.0 - v, v)
        t = tris[pick]
        return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    if proxy["type"] == "sphere":
        d = rng.standard_normal((n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return np.asarray(proxy["center"], float) + proxy["radius"] * d
    lo, hi = np.asarray(proxy["min"], float), np.asarray(proxy["max"], float)
    size = hi - lo   # > 0 in every component (scene/records.py box_extent)
    # face pairs normal to x, y, z, weighted by their areas
    areas = np.array([size[1] * size[2], size[0] * size[2], size[0] * size[1]])
    axis = rng.choice(3, size=n, p=areas / areas.sum())
    x = lo + rng.random((n, 3)) * size
    side = rng.random(n) < 0.5
    x[np.arange(n), axis] = np.where(side, lo[axis], hi[axis])
    return x


def cut_extent(mean, kernel, proxy: dict, eps: float):
    """(share, p): the share of the proxy's boundary where P(f < 0) >= eps under the prior
    (mean and the kernel's sd there, sigma(x) fields included), and the largest P(f < 0)
    on it; (0, 0) for the "scene" proxy."""
    x = boundary_points(proxy)
    if x is None:
        return 0.0, 0.0
    var = kernel.variance_at(x) if hasattr(kernel, "variance_at") else kernel.variance
    z = np.asarray(mean.value(x)) / np.sqrt(np.broadcast_to(np.asarray(var, float), len(x)))
    share = float(np.mean(z < NormalDist().inv_cdf(1.0 - eps)))
    return share, 0.5 * math.erfc(float(z.min()) / math.sqrt(2.0))
