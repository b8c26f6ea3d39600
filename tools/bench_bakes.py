"""Scene preparation on the device against its numpy twin, same run: the knob's procedural
bake (gp/knob.py knob_grid vs render/device_bakes.py) and a trilinear grid's slope bounds
(compile/sdf_bake.py's slabs over gp/means.py vs the device), uncached.

    python tools/bench_bakes.py [--resolution 128] [--repeats 3] [--function knob_outer]

Prints the median seconds of each and the median of per-round ratios (numpy / device).
The device program is built (and PoCL's cache filled) by a warm-up call first: a render
builds it once, and only when a bake is not cached.
"""
from __future__ import annotations

import argparse
import statistics
import time

from gpiscl.host.compile import sdf_bake
from gpiscl.host.gp import knob
from gpiscl.host.gp.means import GridMean
from gpiscl.host.layout.gp_records import GRID_BRICK
from gpiscl.host.render.device import Device
from gpiscl.host.render.device_bakes import DeviceBakes


def _seconds(fn):
    t = time.perf_counter()
    out = fn()
    return time.perf_counter() - t, out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--function", default="knob_outer", choices=sorted(knob.FUNCTIONS))
    ap.add_argument("--device", default=None)
    args = ap.parse_args(argv)
    bakes = DeviceBakes(Device(args.device))
    bakes.linear_slopes(bakes.procedural(args.function, 9).values, 0.1, GRID_BRICK)  # build
    rows = {"procedural": [], "slopes": []}
    for _ in range(args.repeats):
        knob.knob_grid.cache_clear()
        t_host, grid = _seconds(lambda: knob.knob_grid(args.function, args.resolution))
        t_dev, _ = _seconds(lambda: bakes.procedural(args.function, args.resolution))
        rows["procedural"].append((t_host, t_dev))
        fresh = [GridMean(grid.values, grid.origin, grid.voxel_size) for _ in range(2)]
        t_host, _ = _seconds(lambda: sdf_bake.prepare_slopes(fresh[0], cache=False))
        t_dev, _ = _seconds(lambda: sdf_bake.prepare_slopes(fresh[1], cache=False,
                                                            bakes=bakes))
        rows["slopes"].append((t_host, t_dev))
    print(f"{args.function} at resolution {args.resolution} ({grid.values.shape}), "
          f"medians of {args.repeats} on {bakes.device.name}")
    for name, pairs in rows.items():
        host = statistics.median(h for h, _ in pairs)
        dev = statistics.median(d for _, d in pairs)
        ratio = statistics.median(h / d for h, d in pairs)
        print(f"  {name:11s} numpy {host:8.3f} s   device {dev:8.3f} s   x{ratio:.1f}")


if __name__ == "__main__":
    main()
