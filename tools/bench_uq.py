"""UQ throughput: realizations per second of `python -m gpiscl uq` on a small GPIS scene,
and what the per-realization setup costs next to one render of the same paths.

    python tools/bench_uq.py [--resolution 32] [--spp 4] [--realizations 8] [--repeats 3]

Numbers are medians over --repeats runs (after one warm-up that compiles the program).
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from gpiscl.api import render_result  # noqa: E402
from gpiscl.host.render.device import Device  # noqa: E402
from gpiscl.host.uq.realizations import render_realizations  # noqa: E402


def scene(resolution: int) -> dict:
    """A diffuse GPIS blob on a floor under a sky: every path may bounce off the GPIS."""
    return {
        "camera": {"position": [0, 1.2, 3.5], "look_at": [0, 0.3, 0], "fov": 40,
                   "resolution": [resolution, resolution]},
        "render": {"max_depth": 4},
        "lights": [{"type": "environment", "radiance": 1.0}],
        "shapes": [
            {"type": "rectangle", "center": [0, -0.5, 0], "u": [0, 0, -4], "v": [4, 0, 0]},
            {"type": "gpis", "proxy": {"type": "box", "min": [-1, -0.5, -1],
                                       "max": [1, 1.5, 1]},
             "mean": {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.6},
             "kernel": {"type": "squared_exponential", "sigma": 0.2, "length_scale": 0.3},
             "sampler": {"type": "weight_space", "features": 64},
             "bsdf": {"type": "diffuse", "albedo": 0.7}},
        ],
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=int, default=32)
    ap.add_argument("--spp", type=int, default=4, help="samples per realization (K)")
    ap.add_argument("--realizations", type=int, default=8, help="N")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--device")
    args = ap.parse_args()
    device = Device(args.device)
    sc = scene(args.resolution)
    n, k = args.realizations, args.spp
    render_realizations(sc, 2, 2, device=device)          # warm-up: program build / cache

    uq, plain = [], []
    for r in range(args.repeats):
        start = time.perf_counter()
        run = render_realizations(sc, n, k, seed=r, device=device)
        uq.append(time.perf_counter() - start)
        start = time.perf_counter()
        render_result(sc, spp=n * k, seed=r, device=device)   # same paths, one integrator
        plain.append(time.perf_counter() - start)
    t_uq, t_plain = statistics.median(uq), statistics.median(plain)
    paths = run.paths
    print(f"device: {device.name}")
    print(f"scene: {args.resolution}x{args.resolution}, N = {n} realizations x K = {k} spp "
          f"({paths} paths), median of {args.repeats}")
    print(f"uq:            {t_uq:8.3f} s  {n / t_uq:8.3g} realizations/s  "
          f"{paths / t_uq:10.4g} paths/s")
    print(f"plain render:  {t_plain:8.3f} s  (N*K spp, a realization per path)  "
          f"{paths / t_plain:10.4g} paths/s")
    print(f"per-realization overhead: {(t_uq - t_plain) / n * 1e3:.1f} ms "
          f"({(t_uq - t_plain) / t_uq:.0%} of the uq time)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
