"""Triangle mesh files (.obj, .ply, .stl) through trimesh."""
from __future__ import annotations

import numpy as np


def load_mesh(path):
    """(vertices (n, 3) float64, faces (m, 3) int64) of a mesh file, as stored."""
    import trimesh  # imported on use: most scenes have no meshes

    mesh = trimesh.load(path, force="mesh")
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)


def mesh_problem(path):
    """A scene File check: None, or why the mesh file is unusable."""
    import trimesh
    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as exc:  # trimesh raises many types for a corrupt file
        return f"cannot read mesh ({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})"
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        return "mesh has no triangles"
    if not np.isfinite(mesh.vertices).all():
        return "mesh has non-finite vertex coordinates"
    return None
