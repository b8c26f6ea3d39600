"""Triangle mesh files (.obj, .ply, .stl) through trimesh."""
from __future__ import annotations

import numpy as np

from .float_range import array_problem


def load_mesh(path):
    """(vertices (n, 3) float64, faces (m, 3) int64) of a mesh file, as stored."""
    import trimesh  # imported on use: most scenes have no meshes

    mesh = trimesh.load(path, force="mesh")
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)


def mesh_problem(path):
    """A scene File check: None, or why the mesh file is unusable."""
    import trimesh
    problem = obj_index_problem(path)
    if problem:
        return problem
    try:
        # process=False: processing drops the faces of NaN vertices without a word
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for a corrupt file
        # the type only: a message may quote the file, which can be anything a scene names
        return f"cannot read mesh ({type(exc).__name__})"
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        return "mesh has no triangles"
    return array_problem(mesh.vertices, "mesh")


def obj_index_problem(path):
    """OBJ indices start at 1 (negative: from the end); trimesh reads 0 as the last vertex."""
    if not path.lower().endswith(".obj"):
        return None
    with open(path, "rb") as f:
        for number, line in enumerate(f, 1):
            if line.startswith(b"f ") and any(t.split(b"/")[0] in (b"0", b"-0")
                                              for t in line.split()[1:]):
                return f"OBJ face on line {number} uses vertex index 0 (indices start at 1)"
    return None
