"""The "observations" record of a posterior GPIS: checks and the device's limits.

    "observations": {"file": "points.xyz", "noise": 1e-3, "normals": false,
                     "normal_noise": 1e-2}

Every point is observed on the surface, f(x) = 0 (compile/posterior.py builds the
posterior and documents the model and its cost).
"""
from __future__ import annotations

import numpy as np

from ..io.points import load_points
from ..kinds.gp_kernels import GP_KERNELS
from ..layout.constants import WS_POST_MAX

MAX_ROWS = 4096
WS_MAX_ROWS = WS_POST_MAX   # a ray's solve vector lives in private memory


def points_problem(path: str):
    """A scene File check: None, or why the file is unusable."""
    try:
        load_points(path)
    except ValueError as exc:
        return str(exc)
    return None


def observation_rows(points: np.ndarray, normals: bool) -> int:
    return len(points) * (4 if normals else 1)


def observations_problem(g: dict):
    """Record check of a gpis shape: (key, reason) or None."""
    o = g.get("observations")
    if o is None:
        return None
    weight_space = g["sampler"]["type"] == "weight_space"
    # kernels whose cross-covariance slopes ws_posterior.h bounds along a ray
    if weight_space and not GP_KERNELS[g["kernel"]["type"]].traits["ws_posterior"]:
        names = GP_KERNELS.with_trait("ws_posterior")
        return "kernel.type", (f"weight-space posteriors (pathwise conditioning) support the "
                               f"{' and '.join(names)} kernels only, whose "
                               f"cross-covariance slopes the root search bounds; use one, or "
                               f"the function_space sampler")
    pts = load_points(o["file"])
    if o["normals"]:
        if pts.shape[1] != 6:
            return "observations.normals", ("normals: true needs rows of 6 numbers "
                                            "(x y z nx ny nz) in the points file")
        if np.any(np.linalg.norm(pts[:, 3:], axis=1) == 0.0):
            return "observations.normals", "the points file has zero normals"
    rows = observation_rows(pts, o["normals"])
    if rows > MAX_ROWS:
        what = "points x 4 (normals)" if o["normals"] else "points"
        return "observations.file", (f"{rows} observation rows ({what}) exceed {MAX_ROWS}: "
                                     f"every conditioned sample costs O(rows^2) on the "
                                     f"device; subsample the points")
    if weight_space and rows > WS_MAX_ROWS:
        what = "points x 4 (normals)" if o["normals"] else "points"
        return "observations.file", (f"{rows} observation rows ({what}) exceed "
                                     f"{WS_MAX_ROWS} for the weight_space sampler (every ray "
                                     f"solves with them in private memory); subsample the "
                                     f"points or use the function_space sampler")
    return None
