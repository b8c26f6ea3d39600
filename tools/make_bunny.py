"""Writes the grids of the bunny example (scenes/bunny_grid.json): a mean grid baked from a
procedural mesh, and a colour grid.

The authors' bunny (gp-spsr/bunny.json) reads its mean and variance grids from bunny.vdb,
a stochastic Poisson reconstruction in data/example-scenes/gp-spsr of their public
repository (github.com/daseyb/gpis-light-transport), which gpiscl cannot ship (convert
theirs with `python -m gpiscl convert-vdb` and tools/convert_tungsten.py). This stand-in
follows the same
path from a surface to grids: a blobby rabbit (a smooth union of spheres and capsules) is
meshed by surface nets, the mesh's signed distance is baked with gpiscl's own mesh bake
(libigl, gpiscl/host/compile/sdf_bake.py), and the grid is stored like the authors' (about 45^3
samples, float32). The colour grid (16^3) paints a brown coat, a white belly and tail and
pink inner ears.

The sigma grid is a reconstruction's uncertainty, like the authors' variance grid: a
simulated scan sees the rabbit from one side (surface points whose normal faces the
scanner, SCAN_DIRECTION), and a GP with the scene's kernel conditioned on f = 0 at those
points (gpiscl.host.gp.posterior) has a posterior standard deviation that is small near
the scanned surface and returns to the prior's far from it. That standard deviation,
divided by the prior's and floored at SIGMA_FLOOR, is the sigma(x) multiplier: the
rendered surface is smooth where it was seen and rough where it was guessed.

    python tools/make_bunny.py [--resolution 44] [--mesh bunny.obj]

Outputs scenes/assets/bunny_mean.npz, bunny_color.npz and bunny_sigma.npz (compressed,
< 400 kB together); --mesh also writes the intermediate mesh.
"""
import argparse
from pathlib import Path

import numpy as np

from gpiscl.host.gp import SquaredExponential
from gpiscl.host.gp.posterior import Observations, Posterior
from gpiscl.host.io.grids import save_rgb_grid
from gpiscl.host.compile.sdf_bake import bake_mesh

ASSETS = Path(__file__).resolve().parent.parent / "scenes" / "assets"

# (kind, parameters) in world units: the rabbit sits on y = 0 facing +z
SPHERES = [((0.0, 0.40, -0.15), 0.40), ((0.0, 0.58, 0.08), 0.30),   # body
           ((0.0, 0.95, 0.30), 0.25),                                # head
           ((0.0, 0.38, -0.58), 0.12)]                               # tail
CAPSULES = [((s * 0.09, 1.12, 0.24), (s * 0.17, 1.58, 0.12), 0.065) for s in (-1, 1)]  # ears
CAPSULES += [((s * 0.20, 0.08, -0.05), (s * 0.22, 0.08, 0.32), 0.08) for s in (-1, 1)]  # feet
CAPSULES += [((s * 0.14, 0.40, 0.28), (s * 0.15, 0.08, 0.42), 0.065) for s in (-1, 1)]  # paws
BLEND = 0.06
BOUNDS = (np.array([-0.6, -0.15, -0.85]), np.array([0.6, 1.8, 0.7]))
# the simulated scan: surface points facing this direction (from the left, slightly above
# and in front): the camera of bunny_grid.json sees the seen and unseen halves
SCAN_DIRECTION = np.array([-1.0, 0.25, 0.15]) / np.linalg.norm([-1.0, 0.25, 0.15])
SCAN_POINTS = 1500          # drawn on the whole surface; about half face the scanner
SCAN_NOISE = 1e-4           # variance of each f = 0 observation (relative to sigma^2 = 1)
SCAN_LENGTH_SCALE = 0.15    # the scene's kernel length scale (bunny_grid.json)
SIGMA_FLOOR = 0.05
SIGMA_VOXEL = 0.05


def _smin(a, b, k):
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)


def rabbit_sdf(x):
    parts = [np.linalg.norm(x - np.asarray(c), axis=-1) - r for c, r in SPHERES]
    for a, b, r in CAPSULES:
        a, b = np.asarray(a), np.asarray(b)
        ba = b - a
        t = np.clip(((x - a) @ ba) / (ba @ ba), 0.0, 1.0)[..., None]
        parts.append(np.linalg.norm(x - a - t * ba, axis=-1) - r)
    d = parts[0]
    for p in parts[1:]:
        d = _smin(d, p, BLEND)
    return d


def surface_nets(values, origin, h):
    """A closed triangle mesh of the zero set of samples values[i, j, k] at
    origin + h (i, j, k): one vertex per sign-changing cell (the mean of its edge
    crossings), one quad per sign-changing grid edge, wound outward (values < 0 inside)."""
    n = np.asarray(values.shape)
    offsets = np.array([(a, b, c) for a in (0, 1) for b in (0, 1) for c in (0, 1)])
    corner = np.stack([values[a:n[0] - 1 + a, b:n[1] - 1 + b, c:n[2] - 1 + c]
                       for a, b, c in offsets], -1)
    neg = corner < 0
    active = neg.any(-1) & ~neg.all(-1)
    total = np.zeros(corner.shape[:3] + (3,))
    count = np.zeros(corner.shape[:3])
    for p in range(8):
        for q in range(p + 1, 8):
            if np.abs(offsets[p] - offsets[q]).sum() != 1:
                continue                                    # not a cube edge
            vp, vq = corner[..., p], corner[..., q]
            cross = (vp < 0) != (vq < 0)
            t = np.where(cross, vp / np.where(cross, vp - vq, 1.0), 0.0)
            total += cross[..., None] * (offsets[p] + t[..., None] * (offsets[q] - offsets[p]))
            count += cross
    index = -np.ones(corner.shape[:3], np.int64)
    cells = np.argwhere(active)
    index[tuple(cells.T)] = np.arange(len(cells))
    verts = origin + h * (cells + total[tuple(cells.T)] / count[tuple(cells.T)][:, None])
    faces = []
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        lo = [slice(0, n[0]), slice(0, n[1]), slice(0, n[2])]
        hi = list(lo)
        lo[a], hi[a] = slice(0, n[a] - 1), slice(1, n[a])
        flip = (values[tuple(lo)] < 0) != (values[tuple(hi)] < 0)
        edges = np.argwhere(flip)
        # the four cells around the edge need 1 <= index <= n - 2 along b and c
        ok = (edges[:, b] >= 1) & (edges[:, b] <= n[b] - 2) & \
             (edges[:, c] >= 1) & (edges[:, c] <= n[c] - 2)
        edges = edges[ok]
        quad = []
        for db, dc in ((-1, -1), (0, -1), (0, 0), (-1, 0)):  # counter-clockwise about +a
            e = edges.copy()
            e[:, b] += db
            e[:, c] += dc
            quad.append(index[tuple(e.T)])
        quad = np.stack(quad, 1)
        inward = values[tuple(edges.T)] >= 0                # outside at the low end
        quad[inward] = quad[inward][:, ::-1]
        faces += [quad[:, [0, 1, 2]], quad[:, [0, 2, 3]]]
    return verts, np.concatenate(faces)


def rabbit_mesh(resolution: int = 96):
    lo, hi = BOUNDS
    h = float(np.max(hi - lo)) / (resolution - 1)
    counts = np.ceil((hi - lo) / h).astype(int) + 1
    axes = [lo[a] + h * np.arange(counts[a]) for a in range(3)]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    return surface_nets(rabbit_sdf(x), lo, h)


def colour(x):
    """Brown coat, white belly and tail, pink inner ears (smooth blends, in [0, 1])."""
    coat, white, pink = np.array([0.55, 0.36, 0.22]), np.array([0.9, 0.88, 0.85]), \
        np.array([0.9, 0.55, 0.6])
    belly = np.clip((x[..., 2] - 0.15) / 0.15, 0, 1) * np.clip((0.75 - x[..., 1]) / 0.1, 0, 1)
    tail = np.clip(1.0 - np.linalg.norm(x - np.array([0.0, 0.38, -0.62]), axis=-1) / 0.2, 0, 1)
    ear = np.clip((x[..., 1] - 1.2) / 0.1, 0, 1) * np.clip((x[..., 2] - 0.16) / 0.06, 0, 1)
    w = np.maximum(belly, tail * 1.5).clip(0, 1)[..., None]
    c = coat * (1 - w) + white * w
    e = ear[..., None]
    return c * (1 - e) + pink * e


def scan_sigma(verts, faces, seed=0):
    """(values, origin, voxel size) of the sigma(x) multiplier grid (module docstring)."""
    import trimesh
    mesh = trimesh.Trimesh(verts, faces, process=False)
    points, tri = trimesh.sample.sample_surface(mesh, SCAN_POINTS, seed=seed)
    seen = mesh.face_normals[tri] @ SCAN_DIRECTION > 0.0
    post = Posterior(SquaredExponential(1.0, SCAN_LENGTH_SCALE), None,
                     Observations.values(points[seen], 0.0, SCAN_NOISE))
    lo, hi = BOUNDS[0] - 0.2, BOUNDS[1] + 0.2
    counts = np.ceil((hi - lo) / SIGMA_VOXEL).astype(int) + 1
    axes = [lo[a] + SIGMA_VOXEL * np.arange(counts[a]) for a in range(3)]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    sd = np.concatenate([np.sqrt(np.maximum(post.variance(c), 0.0))
                         for c in np.array_split(x, max(1, len(x) // 8192))])
    values = np.maximum(sd, SIGMA_FLOOR).reshape(*counts)
    return values, lo, SIGMA_VOXEL, int(seen.sum())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolution", type=int, default=44, help="mean grid samples (longest axis)")
    ap.add_argument("--mesh", help="also write the surface-nets mesh here (.obj/.ply)")
    args = ap.parse_args()
    verts, faces = rabbit_mesh()
    if args.mesh:
        import trimesh
        trimesh.Trimesh(verts, faces, process=False).export(args.mesh)
    grid = bake_mesh(verts, faces, resolution=args.resolution, margin=0.12)
    np.savez_compressed(ASSETS / "bunny_mean.npz",
                        values=np.asarray(grid.values, np.float32),
                        origin=np.asarray(grid.origin, np.float64),
                        voxel_size=np.float64(grid.voxel_size))
    lo, hi = BOUNDS
    n = 16
    h = float(np.max(hi - lo)) / (n - 1)
    counts = np.ceil((hi - lo) / h).astype(int) + 1
    axes = [lo[a] + h * np.arange(counts[a]) for a in range(3)]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    save_rgb_grid(ASSETS / "bunny_color.npz", colour(x), lo, h)
    sigma, s_origin, s_h, n_seen = scan_sigma(verts, faces)
    np.savez_compressed(ASSETS / "bunny_sigma.npz", values=sigma.astype(np.float32),
                        origin=np.asarray(s_origin, np.float64), voxel_size=np.float64(s_h))
    print(f"mesh: {len(verts)} vertices, {len(faces)} triangles; mean grid "
          f"{grid.shape} voxel {grid.voxel_size:.4g} origin {np.round(grid.origin, 4)}; "
          f"colour grid {tuple(counts)}; sigma grid {sigma.shape} from {n_seen} scanned "
          f"points (multiplier {sigma.min():.3g}..{sigma.max():.3g})")


if __name__ == "__main__":
    main()
