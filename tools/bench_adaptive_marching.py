"""Function-space marching: the adaptive step (fs_march.h) against the old uniform step,
equal-time MSE against a converged reference, same run.

    python tools/bench_adaptive_marching.py [--resolution 24] [--seconds 4]
        [--reference-seconds 40] [--spp 4] [--repeats 3] [scenes...]

Per scene (function-space objects only; others are skipped):
  * reference: the adaptive rule at a tight tolerance (1e-7) rendered for
    --reference-seconds with its own seed; its per-pixel variance is subtracted from
    every MSE below, so the MSEs estimate the error against the true image;
  * variants, each rendered for --seconds (equal time) with another seed: `adaptive`
    (the scene's miss_tolerance, default 1e-5), `uniform 0.9` and `uniform 0.99` (the old
    fixed step, neighbours at correlation c, set on the compiled objects: scenes cannot
    select it). MSE over pixels and channels, and its ratio to adaptive's;
  * equal samples: each variant at --spp, median of --repeats renders (variants
    alternate, so load from other users of the machine hits all alike): paths/s, GP
    values drawn per flight (one object along one ray) and step-rule moment evaluations
    per flight, and the mean image relative to the reference (the bias that equal time
    cannot average away).
"""
from __future__ import annotations

import argparse
import copy
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from gpiscl.host import layouts  # noqa: E402
from gpiscl.host.device import Device  # noqa: E402
from gpiscl.host.integrator import WavefrontIntegrator  # noqa: E402
from gpiscl.host.scene import load_scene  # noqa: E402
from gpiscl.host.scene_compile import compile_scene  # noqa: E402

SCENES = ("scenes/fs_sphere_se.json", "scenes/knob.json", "scenes/wedge_volume.json",
          "scenes/fs_volume_room_global.json")
VARIANTS = {"adaptive": None, "uniform 0.9": 0.9, "uniform 0.99": 0.99}
REFERENCE_TOLERANCE = 1e-7


def compiled(path: str, resolution: int, step_corr=None, tolerance=None, seed=0):
    """The scene at `resolution`^2 with the render seed, compiled; step_corr > 0 puts
    every function-space object on the uniform step, tolerance overrides the adaptive
    rule's miss tolerance."""
    data = copy.deepcopy(load_scene(str(ROOT / path)).data)
    data["camera"]["resolution"] = [resolution, resolution]
    data["render"]["seed"] = seed
    scene = compile_scene(load_scene(data).data)
    objs = scene.gpis.objects
    fs = objs["sampler"] == layouts.GPIS_SAMPLERS["function_space"]
    if step_corr:
        objs["step_corr"][fs] = step_corr
    if tolerance:
        objs["miss_tolerance"][fs] = tolerance
    return scene, data["render"], int(fs.sum())


def render(dev, scene, settings, spp=None, seconds=None):
    integ = WavefrontIntegrator(dev, scene, settings, None)
    t = time.perf_counter()
    res = integ.render(spp if spp else 1 << 20, time_limit=seconds)
    return res, time.perf_counter() - t


def failures(st) -> str:
    bad = st.nan_paths + st.gpis_failed + st.killed_paths
    return f" FAILED PATHS: {st.summary()}" if bad else ""


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=SCENES)
    ap.add_argument("--resolution", type=int, default=24)
    ap.add_argument("--seconds", type=float, default=4.0, help="equal-time budget")
    ap.add_argument("--reference-seconds", type=float, default=40.0)
    ap.add_argument("--spp", type=int, default=4, help="equal-samples renders")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--device", default=None)
    args = ap.parse_args()
    dev = Device(args.device)
    print(f"device: {dev.name}; {args.resolution}^2 px; equal time {args.seconds:g} s, "
          f"reference {args.reference_seconds:g} s at tolerance {REFERENCE_TOLERANCE:g}; "
          f"equal samples {args.spp} spp, median of {args.repeats}")
    for path in args.scenes:
        name = Path(path).stem
        ref_scene, ref_settings, n_fs = compiled(path, args.resolution,
                                                 tolerance=REFERENCE_TOLERANCE, seed=1)
        if not n_fs:
            print(f"{name}: no function-space object, skipped")
            continue
        variants = {k: compiled(path, args.resolution, step_corr=c, seed=2)[:2]
                    for k, c in VARIANTS.items()}
        for scene, settings in variants.values():   # warm-up: program builds
            render(dev, scene, settings, spp=1)
        ref, _ = render(dev, ref_scene, ref_settings, seconds=args.reference_seconds)
        ref_img, ref_var = ref.image.mean, ref.image.stderr ** 2
        print(f"\n{name}: reference {ref.stats.paths} paths{failures(ref.stats)}")
        print(f"  {'variant':14s}{'paths':>9s}{'MSE':>12s}{'MSE/adaptive':>14s}"
              f"{'paths/s':>10s}{'samples/flight':>16s}{'evals/flight':>14s}"
              f"{'mean/ref - 1':>14s}")
        mse = {}
        for k, (scene, settings) in variants.items():
            res, _ = render(dev, scene, settings, seconds=args.seconds)
            err = (res.image.mean - ref_img) ** 2 - ref_var
            mse[k] = (float(err.mean()), res.stats.paths, failures(res.stats))
        # equal samples: alternate the variants, median paths/s
        rates = {k: [] for k in variants}
        stats = {}
        for _ in range(args.repeats):
            for k, (scene, settings) in variants.items():
                res, sec = render(dev, scene, settings, spp=args.spp)
                rates[k].append(res.stats.paths / sec)
                stats[k] = res
        for k in variants:
            st, img = stats[k].stats, stats[k].image.mean
            bias = float(img.mean() / ref_img.mean() - 1)
            flights = max(st.fs_flights, 1)
            print(f"  {k:14s}{mse[k][1]:9d}{mse[k][0]:12.4g}{mse[k][0] / mse['adaptive'][0]:14.3g}"
                  f"{statistics.median(rates[k]):10.4g}{st.fs_samples / flights:16.2f}"
                  f"{st.fs_evals / flights:14.2f}{bias:+14.3%}{mse[k][2]}{failures(st)}",
                  flush=True)


if __name__ == "__main__":
    main()
