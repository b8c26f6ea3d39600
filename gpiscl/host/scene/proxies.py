"""Convex mesh proxies: a closed convex triangle mesh bounds a GPIS as the intersection of
its faces' half-spaces, which the device clips rays against exactly (gpis_proxy.h).

Only convex meshes: a non-convex proxy needs several intervals per ray, and clipping to
its convex hull instead would silently change what the scene means (the authors' wedge
cuts a volume GPIS to the prism's shape), so it is an error.
"""
from __future__ import annotations

import functools
import json

import numpy as np

from ..io.meshes import closed_mesh
from .transforms import mesh_triangles

# planes closer than this (relative to the mesh's size) are one face; vertices this far
# outside a face plane make the mesh non-convex
_REL_TOL = 1e-6


@functools.lru_cache(maxsize=16)
def _analyse(file: str, transform_json: str):
    tris = mesh_triangles({"file": file, "transform": json.loads(transform_json)})
    verts = tris.reshape(-1, 3)
    lo, hi = verts.min(0), verts.max(0)
    size = float(np.max(hi - lo))
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    n = np.cross(b - a, c - a)
    area2 = np.linalg.norm(n, axis=1)
    keep = area2 > (_REL_TOL * size) ** 2
    if not np.any(keep):
        return None, lo, hi, "has no faces of non-zero area"
    n = n[keep] / area2[keep, None]
    d = np.sum(n * a[keep], axis=1)
    # outward normals: a closed mesh wound inwards has negative signed volume
    if np.sum(a * np.cross(b, c)) < 0.0:
        n, d = -n, -d
    if not closed_mesh(tris):
        return None, lo, hi, "must be a closed (watertight) mesh to bound a GPIS"
    planes = np.unique(np.round(np.concatenate([n, d[:, None]], 1) / (_REL_TOL * size))
                       * (_REL_TOL * size), axis=0)
    outside = verts @ planes[:, :3].T - planes[:, 3]
    if np.max(outside) > 10 * _REL_TOL * size:
        return None, lo, hi, ("must be convex: a proxy is clipped as the intersection of "
                              "its faces' half-spaces (split a non-convex object into "
                              "several GPIS objects, or use a box or sphere proxy)")
    return planes.astype(np.float32), lo, hi, None


def analyse(proxy: dict):
    """(planes (p, 4) float32 as n.x <= w with unit outward n, lo, hi, problem or None)."""
    return _analyse(str(proxy["file"]), json.dumps(proxy.get("transform", {}), sort_keys=True))


def bounding_proxy(proxy: dict) -> dict:
    """A box or sphere proxy containing `proxy`: itself unless it is a mesh (then its
    bounding box), for the host's conservative bounds over the proxy."""
    if proxy["type"] != "mesh":
        return proxy
    _, lo, hi, _ = analyse(proxy)
    return {"type": "box", "min": lo.tolist(), "max": hi.tolist()}


def mesh_proxy_problem(g: dict):
    """Schema check of a gpis record: (key, reason) if its mesh proxy cannot bound it."""
    if g["proxy"]["type"] != "mesh":
        return None
    problem = analyse(g["proxy"])[3]
    return None if problem is None else ("proxy.file", problem)
