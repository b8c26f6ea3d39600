"""Point files of observed surface points: .xyz / .txt rows "x y z" or "x y z nx ny nz"
('#' comments), or .npy of shape (n, 3) or (n, 6)."""
from __future__ import annotations

import re

import numpy as np

from .float_range import array_problem

EXTENSIONS = (".xyz", ".txt", ".npy")


def load_points(path: str) -> np.ndarray:
    """(n, 3) or (n, 6) float64 rows of a points file; ValueError with the reason."""
    if path.lower().endswith(".npy"):
        try:
            a = np.load(path, allow_pickle=False)
        except Exception as exc:  # numpy raises several types for a bad file
            raise ValueError(f"cannot read .npy ({type(exc).__name__})") from None
    else:
        try:
            a = np.loadtxt(path, comments="#", ndmin=2)
        except ValueError as exc:
            # numpy's message quotes the offending text: the file may be anything a scene
            # names (a symlink to /etc/passwd), so say where, never what
            at = re.search(r"at row (\d+), column (\d+)", str(exc))
            where = f" (row {int(at[1]) + 1}, column {at[2]})" if at else ""
            raise ValueError(f"cannot read points: not rows of numbers{where}") from None
        except UnicodeDecodeError:
            raise ValueError("cannot read points: not a text file") from None
    a = np.asarray(a)
    if a.dtype.kind not in "fiu":
        raise ValueError(f"points must be numbers, got dtype {a.dtype}")
    a = a.astype(np.float64)
    if a.ndim != 2 or a.shape[1] not in (3, 6):
        raise ValueError(f"points must be rows of 3 (x y z) or 6 (x y z nx ny nz) numbers, "
                         f"got shape {a.shape}")
    if len(a) == 0:
        raise ValueError("no points")
    if not np.isfinite(a).all():
        raise ValueError("points contain non-finite numbers")
    problem = array_problem(a, "points")   # float32 on the device, like meshes and grids
    if problem:
        raise ValueError(problem)
    return a
