"""Writes scenes/assets/wedge.obj: the triangular prism of the authors' wedge scenes.

Their wedge.obj is in data/example-scenes/gp-medium-wedge of their public repository
(github.com/daseyb/gpis-light-transport), but gpiscl cannot ship it; this stand-in is a
right-triangle prism,
the triangle (-1, -1), (1, -1), (-1, 1) in the xy plane extruded over z in [-1, 1], so the
scenes' transform (scale 0.5, centre (0, 1, -0.49)) puts it on y in [0.5, 1.5] just in
front of a back wall at z = -1. Faces are wound counter-clockwise seen from outside.

    python tools/make_wedge.py [-o scenes/assets/wedge.obj]
"""
import argparse
from pathlib import Path

import numpy as np

TRIANGLE = np.array([[-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0]])


def wedge():
    """(vertices (6, 3), triangles (8, 3)), outward counter-clockwise winding."""
    front = np.c_[TRIANGLE, np.ones(3)]          # z = +1
    back = np.c_[TRIANGLE, -np.ones(3)]          # z = -1
    verts = np.vstack([front, back])
    faces = [[0, 1, 2], [3, 5, 4]]               # caps: +z and -z
    for a in range(3):                           # the three rectangular sides
        b = (a + 1) % 3
        faces += [[a, a + 3, b + 3], [a, b + 3, b]]
    faces = np.asarray(faces)
    # the triangle is counter-clockwise in xy, so these face outward; check it anyway
    tri = verts[faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    outward = ((tri.mean(1) - verts.mean(0)) * normals).sum(1)
    assert np.all(outward > 0), "a face is wound inward"
    return verts, faces


def write_obj(path, verts, faces):
    lines = ["# triangular prism for the wedge scenes (tools/make_wedge.py)"]
    lines += [f"v {x:g} {y:g} {z:g}" for x, y, z in verts]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    Path(path).write_text("\n".join(lines) + "\n")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--output", default=str(Path(__file__).resolve().parent.parent
                                                  / "scenes" / "assets" / "wedge.obj"))
    args = ap.parse_args()
    write_obj(args.output, *wedge())
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
