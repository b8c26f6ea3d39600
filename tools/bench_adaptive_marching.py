"""Function-space marching: the adaptive step (fs_march.h) against the old uniform step,
equal-time MSE against a converged reference, same run.

    python tools/bench_adaptive_marching.py [--resolution 24] [--seconds 4]
        [--reference-seconds 40] [--spp 4] [--repeats 3] [scenes...]

Per scene (function-space objects only; others are skipped):
  * reference: the adaptive rule at a tight tolerance (1e-7) rendered for
    --reference-seconds with its own seed; its per-pixel variance is subtracted from
    every MSE below, so the MSEs estimate the error against the true image;
  * equal samples: each variant at --spp, median of --repeats renders (variants
    alternate, so load from other users of the machine hits all alike): paths per CPU
    second of this process (PoCL's threads included; time.process_time), GP
    values drawn per flight (one object along one ray; bisection included) and
    step-rule moment evaluations per flight (2 rows each);
  * equal time: each variant at the spp its paths per CPU second buy in --seconds, with another
    seed: `adaptive` (the scene's miss_tolerance, default 2e-6), `uniform 0.9` and
    `uniform 0.99` (the old fixed step, neighbours at correlation c, set on the compiled
    objects: scenes cannot select it). MSE over pixels and channels, its ratio to
    adaptive's, and the whole image's mean relative to the reference's with its z-score
    (the bias that equal time cannot average away).

Window of the online sampler (fs_march.h): the next value's conditional variance given
the last w samples on a uniform grid of spacing h, relative to 40 samples (numpy):
    SE  h = 0.3: w=4 +120x  w=8 +3.2x  w=16 +8%     (variance 9e-6 of sigma^2)
        h = 0.5: w=4 +3.1x  w=8 +63%   w=16 +7%     (variance 0.007)
        h = 0.8: w=4 +9%    w=8 +0.7%  w=16 +4e-5   (variance 0.25)
        h = 1.2: w=4 +1e-3  w=8 +3e-6               (variance 0.71)
    RQ alpha 1  h = 0.3: w=4 +35%  w=8 +2%  w=16 +1e-4;  h = 0.5: w=8 +4e-4

Measured (PoCL CPU, a 2-core machine shared with other sessions, 2026-12-02; the defaults
above: 24^2, 4 CPU s, reference 40 s, medians of 3). Before = main at 2ecaf8b (bisection,
refine 6), after = the root search (refine 0), the fixed slope inversion and rows that
carry their means; two runs of each, back to back. MSE of uniform 0.9 / 0.99 relative
to adaptive, run 1; run 2, and GP values per flight (adaptive):
    fs_sphere_se           before 0.79 / 1.85; 0.81 / 1.98, 6.22   after 0.75 / 2.13; 0.88 / 1.60, 4.93
    knob                   before 1.46 / 1.00; 1.00 / 1.00, 8.20   after 1.00 / 1.00; 0.95 / 1.00, 7.05
    wedge_volume           before 0.62 / 0.52; 1.19 / 1.05, 1.80   after 0.95 / 0.89; 0.92 / 1.00, 1.57
    fs_volume_room_global  before 1.08 / 0.95; 1.14 / 1.39, 10.62  after 1.25 / 2.05; 1.00 / 1.48, 8.61
The uniform baseline shares the root search and the slope law, so the ratios barely move;
between runs the same code's paths per CPU s differ by up to 1.5x here (other sessions'
load), more than the change. Paths per CPU s of the default sampler, before and after
alternating in 6 rounds (24^2, 32 spp), median ratio after / before (range): fs_sphere_se
1.16 (0.93-1.60), knob 1.08 (0.90-1.47), wedge_volume 0.87 (0.61-1.57; 1.6-1.8 values a
flight, nothing to gain), fs_volume_room_global 1.18 (1.09-1.41).

Measured 2026-12-02 (the mean cap of fs_march.h's fs_mean_step: a grid mean's slope bound
over each try's stretch, sphere tracing from ball to ball far from the zero set), knob
only: the other three scenes take the same steps as before (their means never reach the
cap: fs_sphere_se 4.91 samples and 4.97 evaluations a flight at 8 spp on both trees;
wedge_volume's slope 0.05 and the room's constant mean give caps of metres). Before =
main at 40b0be2, after = this change, alternating, 2 rounds each (the 2-core machine at
load ~9, so the absolute rates are low). Paths per CPU s adaptive / uniform 0.9 / uniform
0.99, then GP values and rule evaluations per flight of the adaptive default:
    before  1.23e4 / 3.05e4 / 2.47e4;  1.17e4 / 2.85e4 / 2.38e4    7.05, 6.62
    after   1.84e4 / 3.30e4 / 2.86e4;  1.51e4 / 2.85e4 / 2.62e4    3.93, 3.46
adaptive / uniform 0.9: 0.40, 0.41 before, 0.56, 0.53 after; after / before 1.50, 1.28
(and 1.41 in one 2048-spp render each: 57.9 against 81.7 CPU s). The MSE columns of
these runs were all alike (each reference's few sun glints dominate them), and their
mean/ref z of the adaptive default (-2.4 to -3.8) was the same before and after. Where
the knob's time went before: every adaptive step was the mean cap's (none rejected, one
evaluation each): flights are mostly fresh rays entering the occupancy shell at |mean|
~24 sd and closing in by single sphere-tracing balls (~3 GP steps) and then 6 sd / lip
steps (0.045 of a 1.4 length scale) near the surface, against 0.65 for uniform 0.9, which
is biased there (+4.9%, z 18, at 4 s references). What is left is the near zone: its
steps are the cap's guarantee. The image under a uniform environment without the floor
(256 spp, 24^2): after against two before renders +0.055 +- 0.030%, before against
before -0.108 +- 0.035% (the renders' stderr is ~20% low: median z^2 0.61-0.66, 0.455
expected, for both pairs).

Measured 2026-12-03 (the two-node Gauss-Radau step rule, fs_march.h "Step rule"; the
defaults above, one run on the 2-core machine at load ~6 from other jobs). Paths per CPU
s adaptive / uniform 0.9 / uniform 0.99, MSE of uniform 0.9 / 0.99 relative to adaptive's,
GP values and rule evaluations per flight of the adaptive default:
    fs_sphere_se           2.82e4 / 3.47e4 / 1.58e4   0.85 / 1.98   5.05, 9.53
    knob                   1.53e4 / 3.08e4 / 2.75e4   0.99 / 0.99   3.93, 6.92
    wedge_volume           9.40e4 / 1.03e5 / 9.22e4   0.80 / 0.91   1.61, 3.14
    fs_volume_room_global  7.68e3 / 9.67e3 / 3.93e3   0.84 / 1.26   9.20, 21.23
Adaptive / uniform 0.9 paths per CPU s: 0.81, 0.50, 0.92, 0.79; uniform 0.99's GP values
per flight are 4.3x (sphere) and 4.3x (room) the adaptive's. The second node costs ~1.2
evaluations a step more than the one-node rule (5 -> 9.5 a flight on the sphere), the
price of not skipping dips in a step's last third. At these sizes every MSE is the
variance's: uniform 0.9's miss bias (2-7% of the crossings, Rice) is below the noise of a
4 s render, so equal time favours the cheapest sampler; at equal time the MSE of two
unbiased samplers can differ by no more than their cost per path, so the issue's 10x
against uniform 0.99 is out of reach by construction (at most its ~2x here). The knob's
mean/ref z of every variant scatters by +-3 with its sun glints (heavy-tailed pixels:
short renders read low).

Measured 2026-12-03 after fs_sampling.h's covariance exps in double4 lanes (2270dd2), the
defaults above, one run at load ~1-2: paths per CPU s adaptive / uniform 0.9 / uniform
0.99, MSE of uniform 0.9 / 0.99 relative to adaptive's (GP values and evaluations per
flight unchanged, the same steps):
    fs_sphere_se           3.36e4 / 4.99e4 / 2.36e4   0.62 / 1.51
    knob                   1.72e4 / 3.45e4 / 2.86e4   1.00 / 1.00
    wedge_volume           5.85e4 / 6.85e4 / 5.82e4   1.04 / 1.06
    fs_volume_room_global  1.25e4 / 1.36e4 / 6.01e3   0.94 / 1.28
Adaptive / uniform 0.9: 0.67, 0.50, 0.85, 0.92. The lanes sped up the systems with many
rows most (same-run A/B, tree before vs after: the room x1.44 adaptive, x1.57 uniform
0.9; the sphere x1.13 / x1.34), i.e. uniform's longer windows more than adaptive's short
ones, so the ratio to uniform 0.9 barely moved; uniform 0.99 gained as much and stays
1.3-1.5x the MSE on the sphere and the room.
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

from gpiscl.host.layout import records as layouts  # noqa: E402
from gpiscl.host.render.device import Device  # noqa: E402
from gpiscl.host.render.integrator import WavefrontIntegrator  # noqa: E402
from gpiscl.host.scene.loading import load_scene  # noqa: E402
from gpiscl.host.compile.scene import compile_scene  # noqa: E402

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
    """The render and the CPU seconds it took in this process (PoCL's CPU device runs its
    threads here): other users of a shared machine slow the wall clock, not this."""
    integ = WavefrontIntegrator(dev, scene, settings, None)
    t = time.process_time()
    res = integ.render(spp if spp else 1 << 20, time_limit=seconds)
    return res, time.process_time() - t


def failures(st) -> str:
    bad = st.nan_paths + st.gpis_failed + st.killed_paths
    return f" FAILED PATHS: {st.summary()}" if bad else ""


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=SCENES)
    ap.add_argument("--resolution", type=int, default=24)
    ap.add_argument("--seconds", type=float, default=4.0, help="equal-time budget (CPU s)")
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
        pixels = args.resolution ** 2
        variants = {k: compiled(path, args.resolution, step_corr=c, seed=2)[:2]
                    for k, c in VARIANTS.items()}
        for scene, settings in variants.values():   # warm-up: program builds
            render(dev, scene, settings, spp=1)
        # equal samples: the variants alternate; median paths/s
        rates, stats = {k: [] for k in variants}, {}
        for _ in range(args.repeats):
            for k, (scene, settings) in variants.items():
                res, sec = render(dev, scene, settings, spp=args.spp)
                rates[k].append(res.stats.paths / sec)
                stats[k] = res.stats
        rate = {k: statistics.median(r) for k, r in rates.items()}
        # reference and equal time: spp from the measured rates
        ref_spp = max(args.spp, round(rate["adaptive"] * args.reference_seconds / pixels))
        ref, ref_sec = render(dev, ref_scene, ref_settings, spp=ref_spp)
        ref_img, ref_var = ref.image.mean, ref.image.stderr ** 2
        print(f"\n{name}: reference {ref_spp} spp in {ref_sec:.1f} s{failures(ref.stats)}")
        print(f"  {'variant':14s}{'spp':>6s}{'s':>7s}{'MSE':>11s}{'MSE/adaptive':>14s}"
              f"{'paths/cpu s':>12s}{'samples/flight':>16s}{'evals/flight':>14s}"
              f"{'mean/ref - 1':>14s}{'z':>7s}")
        rows = {}
        for k, (scene, settings) in variants.items():
            spp = max(1, round(rate[k] * args.seconds / pixels))
            res, sec = render(dev, scene, settings, spp=spp)
            img, var = res.image.mean, res.image.stderr ** 2
            mse = float(((img - ref_img) ** 2 - ref_var).mean())
            # whole-image mean against the reference's: the bias equal time keeps
            diff = float(img.mean() - ref_img.mean())
            se = float(np.sqrt((var.sum() + ref_var.sum())) / img.size)
            rows[k] = (spp, sec, mse, diff / float(ref_img.mean()), diff / se,
                       failures(res.stats))
        for k, (spp, sec, mse, bias, z, bad) in rows.items():
            st = stats[k]
            flights = max(st.fs_flights, 1)
            print(f"  {k:14s}{spp:6d}{sec:7.1f}{mse:11.3g}{mse / rows['adaptive'][2]:14.3g}"
                  f"{rate[k]:12.4g}{st.fs_samples / flights:16.2f}{st.fs_evals / flights:14.2f}"
                  f"{bias:+14.3%}{z:7.1f}{bad}{failures(st)}", flush=True)


if __name__ == "__main__":
    main()
