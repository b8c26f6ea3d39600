"""Posterior GPIS: the "observations" of a gpis record -> host Posterior -> the object's
share of the scene's posterior tables that fs_posterior.h reads (the record and its
limits: scene/observations.py).

    "observations": {"file": "points.xyz", "noise": 1e-3, "normals": false,
                     "normal_noise": 1e-2}

file: .xyz / .txt (whitespace-separated rows "x y z" or "x y z nx ny nz", '#' comments)
or .npy of shape (n, 3) or (n, 6), in world coordinates. Every point is observed on the
surface, f(x) = 0, with standard deviation `noise` (world units: f is a signed distance,
so this is the points' scatter across the surface); with "normals": true the file's
normals are observed as the gradient (three derivative rows per point, standard
deviation `normal_noise`), which also tells inside from outside.

Function space: the observations join every ray's conditioning set exactly
(fs_sampling.h, FsPost). Cost on the device: for each conditioned row, n kernel
evaluations and an n x n triangular solve (n = observation rows: points, times 4 with
normals), so a segment of R rows costs ~R n^2 / 2 multiply-adds: a few hundred rows are
practical, a thousand only for small images (docs/design/scene-key-costs.md,
'Observations'). MAX_ROWS bounds n: the factor (n^2 / 2 doubles) and the per-row v cache
(FS_MAX_ROWS n doubles per work item) grow with it.

Weight space: each ray conditions its path's realization by Matheron's rule
(ws_posterior.h), reading the same tables plus the noise deviations stored after the
factor; SE and RQ kernels only, at most WS_MAX_ROWS rows.
"""
from __future__ import annotations

import numpy as np

from ..layout.function_space_records import FS_OBS, OBS_KINDS
from ..gp.posterior import Posterior, surface_observations
from ..io.points import load_points
from ..scene.observations import MAX_ROWS


def build_posterior(o: dict, kernel, mean) -> Posterior:
    """The host posterior of a resolved "observations" record."""
    pts = load_points(o["file"])
    nrm = pts[:, 3:] if o["normals"] else None
    obs = surface_observations(pts[:, :3], nrm, noise=o["noise"] ** 2,
                               normal_noise=o["normal_noise"] ** 2)
    return Posterior(kernel, mean, obs)


def pack_posterior(post: Posterior) -> tuple[np.ndarray, np.ndarray]:
    """(rows, doubles): the n FsObs observation rows, and alpha (n), the packed lower
    factor L (n(n+1)/2, row-major as fs_tri) and the noise deviations (n) in float64
    (fs_posterior.h, ws_posterior.h; function space never reads the deviations, weight
    space draws each path's noise with them)."""
    obs = post.obs
    n = len(obs)
    if n > MAX_ROWS:
        raise ValueError(f"{n} observation rows exceed {MAX_ROWS}")
    rows = FS_OBS.zeros(n)
    rows["px"], rows["py"], rows["pz"] = obs.x.T
    u = np.where(obs.is_value[:, None], 0.0, np.nan_to_num(obs.u))
    rows["ux"], rows["uy"], rows["uz"] = u.T
    rows["value"] = obs.y
    rows["kind"] = np.where(obs.is_value, OBS_KINDS["value"], OBS_KINDS["deriv"])
    doubles = np.concatenate([post.alpha, post.L[np.tril_indices(n)], np.sqrt(obs.noise)])
    return rows, doubles.astype("<f8")
