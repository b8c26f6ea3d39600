"""Triangle mesh files (.obj, .ply, .stl) through trimesh, and plain OBJ files without it.

`import trimesh` pulls in scipy and PIL, a third of a small render's resident memory
(docs/design/startup.md, 'Imports'). A plain OBJ (v, f of triangles or of
quads only, vt / vn / o / g / s / usemtl / mtllib lines ignored) is read here into the
triangles trimesh gives, in its order (each quad as (0, 1, 2), (2, 3, 0)); anything else
goes to trimesh.
"""
from __future__ import annotations

import numpy as np

from .float_range import array_problem

_OBJ_IGNORED = (b"vt", b"vn", b"o", b"g", b"s", b"usemtl", b"mtllib")


def read_plain_obj(path):
    """(vertices (n, 3) float64, faces (m, 3) int64) of a plain OBJ file, or None when it
    has anything else (trimesh then reads it). Indices count from 1, negative ones back
    from the last vertex so far."""
    if not str(path).lower().endswith(".obj"):
        return None
    verts, faces = [], []
    try:
        with open(path, "rb") as f:
            for line in f:
                parts = line.split()
                if not parts or parts[0].startswith(b"#") or parts[0] in _OBJ_IGNORED:
                    continue
                if parts[0] == b"v" and len(parts) in (4, 5, 7):   # x y z [w | r g b]
                    verts.append([float(x) for x in parts[1:4]])
                elif parts[0] == b"f" and len(parts) in (4, 5):
                    n = len(verts)
                    idx = [int(p.split(b"/")[0]) for p in parts[1:]]
                    idx = [i - 1 if i > 0 else n + i for i in idx]
                    if min(idx) < 0 or max(idx) >= n or (faces and len(idx) != len(faces[0])):
                        return None     # trimesh's business (and mixed triangles and quads)
                    faces.append(idx)
                else:
                    return None
    except (ValueError, OSError):
        return None
    if not faces:
        return None
    v, fa = np.asarray(verts, np.float64), np.asarray(faces, np.int64)
    if fa.shape[1] == 4:
        fa = np.stack((fa[:, [0, 1, 2]], fa[:, [2, 3, 0]]), axis=1).reshape(-1, 3)
    return v, fa


def closed_mesh(triangles: np.ndarray) -> bool:
    """Whether (n, 3, 3) triangles form a closed surface: every edge shared by exactly two
    triangles once corners equal to 1e-8 are merged (trimesh's is_watertight after its
    vertex merge, without importing it)."""
    corners = np.round(np.asarray(triangles, np.float64).reshape(-1, 3) * 1e8)
    _, ids = np.unique(corners, axis=0, return_inverse=True)
    tri = ids.reshape(-1, 3)
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return bool(len(counts)) and bool(np.all(counts == 2))


def load_mesh(path):
    """(vertices (n, 3) float64, faces (m, 3) int64) of a mesh file, as stored."""
    plain = read_plain_obj(path)
    if plain is not None:
        return plain
    import trimesh  # imported on use: most scenes have no meshes

    mesh = trimesh.load(path, force="mesh")
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)


def mesh_problem(path):
    """A scene File check: None, or why the mesh file is unusable."""
    problem = obj_index_problem(path)
    if problem:
        return problem
    plain = read_plain_obj(path)
    if plain is not None:
        return array_problem(plain[0], "mesh") or extent_problem(*plain)
    import trimesh
    try:
        # process=False: processing drops the faces of NaN vertices without a word
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for a corrupt file
        # the type only: a message may quote the file, which can be anything a scene names
        return f"cannot read mesh ({type(exc).__name__})"
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        return "mesh has no triangles"
    return array_problem(mesh.vertices, "mesh") or extent_problem(mesh.vertices, mesh.faces)


def extent_problem(vertices, faces):
    """None, or why a mesh has nothing to show, bound or bake: every corner of its
    triangles at one point (a mesh mean's bake box would have no size)."""
    faces = np.asarray(faces, np.int64).reshape(-1)
    vertices = np.asarray(vertices, np.float64)
    if not len(faces) or faces.min() < 0 or faces.max() >= len(vertices):
        return None     # no triangles or bad indices: the readers say so
    if not np.ptp(vertices[faces], axis=0).any():
        return "the mesh has no extent (all vertices at one point)"
    return None


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
