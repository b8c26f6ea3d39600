"""Render time with and without occupancy bounds (gpis_proxy.h), same run, median of N.

    python tools/bench_occupancy.py [--repeats 3] [--resolution 96] [--spp 8]
                                    [--eps 1e-4] [scenes...]

Each scene is rendered with every GPIS object's "bounds": {"occupancy": eps} and with
null (the whole proxy); the two variants alternate so that load from other users of the
machine hits both alike. Only the integrator's render is timed (the scene is compiled and
the programs built before). Prints seconds per render, rays traced and the ratio
off / on (> 1: the bounds pay).
"""
from __future__ import annotations

import argparse
import copy
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from gpiscl.host.render.device import Device  # noqa: E402
from gpiscl.host.render.integrator import WavefrontIntegrator  # noqa: E402
from gpiscl.host.scene.loading import load_scene  # noqa: E402
from gpiscl.host.compile.scene import compile_scene  # noqa: E402

SCENES = ("scenes/knob_no_csg.json", "scenes/knob.json", "scenes/ws_sphere_se.json")


def scene_variant(path: str, resolution: int, edit_gpis):
    """The resolved scene at path, square at `resolution`, each GPIS shape passed to
    edit_gpis(shape) (which changes it in place), validated again."""
    data = copy.deepcopy(load_scene(str(ROOT / path)).data)
    data["camera"]["resolution"] = [resolution, resolution]
    for shape in data["shapes"]:
        if shape["type"] == "gpis":
            edit_gpis(shape)
    return load_scene(data).data


def variant(path: str, eps, resolution: int):
    return scene_variant(path, resolution, lambda g: g.update(bounds={"occupancy": eps}))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=SCENES)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--resolution", type=int, default=96)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--eps", type=float, default=1e-4)
    ap.add_argument("--device", default=None)
    args = ap.parse_args()
    dev = Device(args.device)
    print(f"device: {dev.name}; {args.resolution}^2 px, {args.spp} spp, eps {args.eps:g}, "
          f"median of {args.repeats}")
    print(f"{'scene':28s} {'off s':>8s} {'on s':>8s} {'off/on':>7s} {'rays off':>10s} "
          f"{'rays on':>10s}")
    for path in args.scenes:
        data = {name: variant(path, eps, args.resolution)
                for name, eps in (("off", None), ("on", args.eps))}
        times, rays = time_variants(dev, data, args.spp, args.repeats)
        off, on = times["off"], times["on"]
        print(f"{Path(path).stem:28s} {off:8.2f} {on:8.2f} {off / on:7.2f} "
              f"{rays['off']:10d} {rays['on']:10d}", flush=True)


def time_variants(dev, variants: dict, spp: int, repeats: int):
    """Median render seconds and rays of each resolved scene variant (name -> data): the
    variants alternate so that load from other users of the machine hits all alike; only
    the integrator's render is timed (compiled and built before)."""
    compiled, times, rays = {}, {name: [] for name in variants}, {}
    for name, data in variants.items():
        compiled[name] = (compile_scene(data), dict(data["render"], spp=spp))
        WavefrontIntegrator(dev, *compiled[name], None).render(1)   # warm-up: builds
    for _ in range(repeats):
        for name in variants:
            # a fresh integrator per render: its statistics accumulate over renders
            integ = WavefrontIntegrator(dev, *compiled[name], None)
            t = time.perf_counter()
            res = integ.render(spp)
            times[name].append(time.perf_counter() - t)
            rays[name] = res.stats.rays
    return {name: statistics.median(t) for name, t in times.items()}, rays

if __name__ == "__main__":
    main()
