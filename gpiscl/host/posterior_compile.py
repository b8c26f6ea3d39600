"""Posterior GPIS in a scene: the "observations" of a gpis record -> host Posterior ->
the device block that fs_posterior.h reads.

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
normals), so a segment of R rows costs ~R n^2 / 2 multiply-adds; tools/bench_posterior.py
measures it. Measured on PoCL, 2 shared cores (SE, N = 16): 17 us per prior segment,
0.35 ms at n = 100, 25 ms at n = 1000; a 16x16 x 8 spp sphere render takes 0.03 s
(prior), 0.5 s (n = 100), 1.8 s (200), 6.6 s (400), ~45 s (1000). So a few hundred rows
are practical, a thousand only for small images. MAX_ROWS bounds n: the factor (n^2 / 2
doubles) and the per-row v cache (FS_MAX_ROWS n doubles per work item) grow with it.

Weight space: each ray conditions its path's realization by Matheron's rule
(ws_posterior.h), reading the same block plus the noise deviations appended after the
factor; SE and RQ kernels only, at most WS_MAX_ROWS rows.
"""
from __future__ import annotations

import numpy as np

from .gp.device_layout import MEAN_NODE
from .gp.function_space_layout import FS_OBS, OBS_KINDS
from .gp.posterior import Posterior, surface_observations

POSTERIOR_KIND = 48          # FS_POSTERIOR_KIND in fs_posterior.h, WS_POSTERIOR_KIND
MAX_ROWS = 4096
# WS_POST_MAX in ws_posterior.h: a ray's solve vector lives in private memory (8 bytes a row)
WS_MAX_ROWS = 512
# kernels whose cross-covariance slopes ws_posterior.h bounds along a ray
WS_KERNELS = ("squared_exponential", "rational_quadratic")
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
            raise ValueError(f"cannot read points ({str(exc).splitlines()[0]})") from None
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
    return a


def points_problem(path: str):
    """scene_schema File check: None, or why the file is unusable."""
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
    if weight_space and g["kernel"]["type"] not in WS_KERNELS:
        return "kernel.type", (f"weight-space posteriors (pathwise conditioning) support the "
                               f"{' and '.join(WS_KERNELS)} kernels only, whose "
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


def build_posterior(o: dict, kernel, mean) -> Posterior:
    """The host posterior of a resolved "observations" record."""
    pts = load_points(o["file"])
    nrm = pts[:, 3:] if o["normals"] else None
    obs = surface_observations(pts[:, :3], nrm, noise=o["noise"] ** 2,
                               normal_noise=o["normal_noise"] ** 2)
    return Posterior(kernel, mean, obs)


def pack_posterior(post: Posterior) -> np.ndarray:
    """MeanNode records to place just before the object's mean program (fs_posterior.h)."""
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
    tri = post.L[np.tril_indices(n)]          # row-major packed, as fs_tri
    # the noise deviations trail the factor: weight space draws each path's noise with them
    # (ws_posterior.h); fs_posterior.h never reads past the factor
    raw = (rows.tobytes() + np.ascontiguousarray(post.alpha, "<f8").tobytes()
           + np.ascontiguousarray(tri, "<f8").tobytes()
           + np.ascontiguousarray(np.sqrt(obs.noise), "<f8").tobytes())
    size = MEAN_NODE.dtype.itemsize
    raw += bytes(-len(raw) % size)
    block = np.frombuffer(raw, MEAN_NODE.dtype).copy()
    header = MEAN_NODE.zeros(1)
    header["kind"] = POSTERIOR_KIND
    header["flags"] = len(block)
    header["p0"] = (n, 0.0, 0.0, 0.0)
    return np.concatenate([block, header])


def posterior_rows(nodes: np.ndarray, objects: np.ndarray) -> np.ndarray:
    """Observation rows of each object's posterior (0: none), read as fs_posterior_of does."""
    out = np.zeros(len(objects), np.int64)
    for k, first in enumerate(objects["mean_first"]):
        if first > 0 and nodes[first - 1]["kind"] == POSTERIOR_KIND:
            out[k] = int(nodes[first - 1]["p0"][0])
    return out
