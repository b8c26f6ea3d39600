"""Render time of grid means interpolated trilinearly vs by the cubic spline, same run.

    python tools/bench_grid_interpolation.py [--repeats 3] [--resolution 96] [--spp 8]
                                             [scenes...]

Every sampled mean (mesh, grid, procedural) of each scene is set to "linear" and to
"cubic"; the variants alternate (tools/bench_occupancy.py time_variants). The cubic
spline reads 64 coefficients per evaluation instead of 8 and has a different slope bound
(occupancy marches, weight-space search). Prints median seconds per render and the ratio
cubic / linear (> 1: cubic costs more), then a weight-space sphere with its analytic mean
against the same sphere baked to a grid (linear, cubic).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

from bench_occupancy import scene_variant, time_variants  # noqa: E402
from gpiscl.host.render.device import Device  # noqa: E402
import numpy as np  # noqa: E402

SCENES = ("scenes/knob_no_csg.json", "scenes/bunny_grid.json", "scenes/csg_baked.json")
SAMPLED = ("mesh", "grid", "procedural")
SPHERE = "scenes/ws_sphere_se.json"     # its mean: a unit sphere at the origin


def _set(mean: dict, interpolation: str):
    if mean.get("type") in SAMPLED:
        mean["interpolation"] = interpolation
    for key in ("left", "right", "child"):
        if isinstance(mean.get(key), dict):
            _set(mean[key], interpolation)


def variant(path: str, interpolation: str, resolution: int):
    return scene_variant(path, resolution, lambda g: _set(g["mean"], interpolation))


def baked_sphere_variants(resolution: int) -> dict:
    """scenes/ws_sphere_se.json (weight space) with its analytic unit-sphere mean, and with
    the same sphere's exact distances sampled on a 48^3 grid over [-1.5, 1.5]^3, linear and
    cubic: what a grid mean costs the certified search against the analytic mean."""
    n, lo = 48, -1.5
    h = -2 * lo / (n - 1)
    idx = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1)
    path = Path(tempfile.mkdtemp()) / "sphere.npz"
    np.savez(path, values=np.linalg.norm(lo + h * idx, axis=-1) - 1.0,
             origin=np.full(3, lo), voxel_size=np.float64(h))
    out = {"analytic": scene_variant(SPHERE, resolution, lambda g: None)}
    for interp in ("linear", "cubic"):
        grid = {"type": "grid", "file": str(path), "interpolation": interp}
        out[f"grid {interp}"] = scene_variant(SPHERE, resolution,
                                              lambda g, m=grid: g.update(mean=m))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=SCENES)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--resolution", type=int, default=96)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--device", default=None)
    args = ap.parse_args()
    dev = Device(args.device)
    print(f"device: {dev.name}; {args.resolution}^2 px, {args.spp} spp, median of "
          f"{args.repeats}")
    print(f"{'scene':28s} {'linear s':>9s} {'cubic s':>9s} {'cubic/lin':>9s}")
    for path in args.scenes:
        data = {k: variant(path, k, args.resolution) for k in ("linear", "cubic")}
        times, _ = time_variants(dev, data, args.spp, args.repeats)
        print(f"{Path(path).stem:28s} {times['linear']:9.2f} {times['cubic']:9.2f} "
              f"{times['cubic'] / times['linear']:9.2f}", flush=True)
    times, _ = time_variants(dev, baked_sphere_variants(args.resolution), args.spp,
                             args.repeats)
    print("\nweight-space sphere, analytic mean vs a 48^3 grid of its distances:")
    for name, t in times.items():
        print(f"{name:28s} {t:9.2f} s {t / times['analytic']:9.2f} x analytic")


if __name__ == "__main__":
    main()
