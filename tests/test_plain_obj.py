"""Plain OBJ files are read without trimesh (io/meshes.py: importing it costs ~58 MB of
scipy and PIL), into the triangles trimesh gives; everything else still goes to trimesh."""
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from gpiscl.host.io.meshes import closed_mesh, load_mesh, mesh_problem, read_plain_obj

ROOT = Path(__file__).resolve().parent.parent
QUADS = """# a cube of quads, with texture and normal indices and negative indices
v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1
vt 0 0\nvn 0 0 1\no cube\ns off
f 1/1/1 4/1/1 3/1/1 2/1/1\nf 5/1/1 6/1/1 7/1/1 8/1/1\nf 1//1 2//1 6//1 5//1
f 2 3 7 6\nf 3 4 8 7\nf -8 -4 -1 -5
"""


def _trimesh_triangles(path, process):
    m = trimesh.load(path, force="mesh", process=process)
    return np.asarray(m.vertices)[m.faces]


@pytest.mark.parametrize("name", ["box", "icosphere", "torus", "open_box", "quads"])
def test_plain_obj_gives_trimesh_triangles_and_closedness(tmp_path, name):
    path = tmp_path / f"{name}.obj"
    if name == "quads":
        path.write_text(QUADS)
    else:
        box = trimesh.creation.box()
        {"box": box, "icosphere": trimesh.creation.icosphere(2),
         "torus": trimesh.creation.torus(1.0, 0.3),
         "open_box": trimesh.Trimesh(box.vertices, box.faces[:-2])}[name].export(path)
    verts, faces = read_plain_obj(path)
    for process in (False, True):
        np.testing.assert_array_equal(verts[faces], _trimesh_triangles(path, process))
    np.testing.assert_array_equal(load_mesh(path)[0][load_mesh(path)[1]], verts[faces])
    tris = verts[faces]
    watertight = trimesh.Trimesh(tris.reshape(-1, 3), np.arange(tris.size // 3).reshape(-1, 3),
                                 process=True).is_watertight
    assert closed_mesh(tris) == watertight == (name in ("box", "icosphere", "torus", "quads"))
    assert mesh_problem(str(path)) is None


@pytest.mark.parametrize("text", [
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 2 2 0\nf 1 2 4 3 5\n",     # a pentagon
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 1 2 4 3\n",        # triangles and quads
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\nf 1 2 3\n",                      # a line element
    "v 0 0 0\nv 1 0 0\nf 1 2 3\n",                                      # index past the end
    "v 0 0 0\nv 1 0 0\nv 0 1 0\n",                                      # no faces
])
def test_anything_else_goes_to_trimesh(tmp_path, text):
    path = tmp_path / "other.obj"
    path.write_text(text)
    assert read_plain_obj(path) is None


def test_a_nan_vertex_is_still_refused(tmp_path):
    path = tmp_path / "nan.obj"
    path.write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    assert "NaN" in mesh_problem(str(path))


def test_a_mesh_proxy_scene_compiles_without_importing_trimesh():
    code = ("import sys\nfrom gpiscl import load_scene\n"
            "from gpiscl.host.compile.scene import compile_scene\n"
            f"s = load_scene({str(ROOT / 'scenes' / 'wedge_volume.json')!r})\n"
            "compile_scene(s.data, s.source)\nprint('trimesh' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"
