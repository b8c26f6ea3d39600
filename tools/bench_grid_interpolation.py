"""Render time of grid means interpolated trilinearly vs by the cubic spline, same run.

    python tools/bench_grid_interpolation.py [--repeats 3] [--resolution 96] [--spp 8]
                                             [scenes...]

Every sampled mean (mesh, grid, procedural) of each scene is set to "linear" and to
"cubic"; the variants alternate (tools/bench_occupancy.py time_variants). The cubic
spline reads 64 coefficients per evaluation instead of 8 and has a different slope bound
(occupancy marches, weight-space search). Prints median seconds per render and the ratio
cubic / linear (> 1: cubic costs more).
"""
from __future__ import annotations

import argparse
import copy
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))

from bench_occupancy import time_variants  # noqa: E402
from gpiscl.host.device import Device  # noqa: E402
from gpiscl.host.scene import load_scene  # noqa: E402

SCENES = ("scenes/knob_no_csg.json", "scenes/bunny_grid.json", "scenes/csg_baked.json")
SAMPLED = ("mesh", "grid", "procedural")


def _set(mean: dict, interpolation: str):
    if mean.get("type") in SAMPLED:
        mean["interpolation"] = interpolation
    for key in ("left", "right", "child"):
        if isinstance(mean.get(key), dict):
            _set(mean[key], interpolation)


def variant(path: str, interpolation: str, resolution: int):
    data = copy.deepcopy(load_scene(str(ROOT / path)).data)
    data["camera"]["resolution"] = [resolution, resolution]
    for shape in data["shapes"]:
        if shape["type"] == "gpis":
            _set(shape["mean"], interpolation)
    return load_scene(data).data


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


if __name__ == "__main__":
    main()
