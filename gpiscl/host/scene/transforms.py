"""The scene format's transforms: scale, then rotate (degrees about x, then y, then z),
then translate; and mesh shapes placed in the world by them."""
from __future__ import annotations

import math

import numpy as np

from ..io.meshes import load_mesh


def euler_matrix(degrees) -> np.ndarray:
    ax, ay, az = np.radians(degrees)
    rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
    ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
    rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx


def transform_matrix(t: dict) -> np.ndarray:
    """The 3x4 object-to-world matrix of a resolved transform record."""
    lin = euler_matrix(t["rotate"]) @ np.diag(np.asarray(t["scale"], dtype=np.float64))
    return np.concatenate([lin, np.asarray(t["translate"], float)[:, None]], axis=1)


def mesh_triangles(shape: dict) -> np.ndarray:
    """(n, 3, 3) world-space triangles of a mesh shape or proxy, its transform applied."""
    verts, faces = load_mesh(shape["file"])
    t = shape.get("transform", {})
    verts = verts * np.asarray(t.get("scale", 1.0), dtype=np.float64)
    verts = verts @ euler_matrix(t.get("rotate", [0, 0, 0])).T
    verts = verts + np.asarray(t.get("translate", [0, 0, 0]), dtype=np.float64)
    return verts[faces]
