"""Where the function-space march spends its work on grid-mean scenes (issue 33): per
scene, stage times, bounces, shadow rays, flights, and fs_march.h's work counters (steps,
rule tries and evaluations, mean-program evaluations, what set each step's first try,
how often the monotone stretch lifted the mean cap, the occupancy clip's marches),
then paths per CPU second of the exact default against the uniform 0.99 / 0.9 steps.

    python tools/profile_grid_scenes.py [SCENE ...] [--resolution 32] [--spp 4]
        [--repeats 3] [--no-rates]

The counters come from a build with FS_PROFILE (GPISCL_FS_PROFILE=1: layout/records.py
FS_PROFILE_COUNTERS, int32 over the whole render, so keep renders short); the rates from
the ordinary build, variants alternating, medians of --repeats, CPU seconds of this process
(PoCL's threads run here). docs/design/grid-means.md has the measured tables.
"""
from __future__ import annotations

import argparse
import copy
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from gpiscl.host.layout import records as layouts  # noqa: E402
from gpiscl.host.render.device import Device  # noqa: E402
from gpiscl.host.render.integrator import WavefrontIntegrator  # noqa: E402
from gpiscl.host.scene.loading import load_scene  # noqa: E402
from gpiscl.host.compile.scene import compile_scene  # noqa: E402

SCENES = ("scenes/knob.json", "scenes/knob_no_csg.json", "scenes/csg_baked.json",
          "scenes/bunny_grid.json")
VARIANTS = {"exact": None, "uniform 0.99": 0.99, "uniform 0.9": 0.9}


def compiled(path: str, resolution: int, step_corr=None):
    """The scene at `resolution`^2, compiled; step_corr > 0 puts every function-space
    object on the uniform step."""
    data = copy.deepcopy(load_scene(str(ROOT / path)).data)
    data["camera"]["resolution"] = [resolution, resolution]
    scene = compile_scene(load_scene(data).data)
    objs = scene.gpis.objects
    if step_corr:
        fs = objs["sampler"] == layouts.GPIS_SAMPLERS["function_space"]
        objs["step_corr"][fs] = step_corr
    return scene, data["render"]


def render(dev, scene, settings, spp):
    integ = WavefrontIntegrator(dev, scene, settings, None)
    t = time.process_time()
    res = integ.render(spp)
    return integ, res, time.process_time() - t


def profile(dev, path, resolution, spp):
    """One render of the FS_PROFILE build: a dict of per-path and per-flight figures."""
    os.environ["GPISCL_FS_PROFILE"] = "1"
    try:
        scene, settings = compiled(path, resolution)
        render(dev, scene, settings, 1)                       # the build
        integ, res, sec = render(dev, scene, settings, spp)
    finally:
        del os.environ["GPISCL_FS_PROFILE"]
    st = res.stats
    c = {k: int(integ.counters_host[layouts.COUNTERS[k]]) for k in layouts.FS_PROFILE_COUNTERS}
    t = integ.program.timings
    t.resolve()
    return st, c, dict(t.seconds), sec


def report(name, st, c, stages, sec):
    fl = max(st.fs_flights, 1)
    steps = max(c["fs_steps"], 1)
    total = sum(stages.values())
    print(f"\n{name}: {st.paths} paths in {sec:.2f} CPU s; per path: {st.rays / st.paths:.2f} "
          f"rays (bounces), {st.shadow_rays / st.paths:.2f} shadow rays, "
          f"{st.fs_flights / st.paths:.2f} flights")
    print(f"  per flight: {c['fs_steps'] / fl:.2f} steps, {c['fs_tries'] / fl:.2f} tries, "
          f"{st.fs_evals / fl:.2f} rule evaluations, {st.fs_samples / fl:.2f} GP values, "
          f"{c['fs_mean_evals'] / fl:.2f} mean evaluations (+{c['fs_hops'] / fl:.2f} "
          f"sphere-tracing hops), {c['fs_lip_scans'] / fl:.2f} brick-bound scans, "
          f"{c['fs_var_walks'] / fl:.2f} variation walks")
    print(f"  first try set by: mean cap {c['fs_cap_mean'] / steps:.1%} (the sigma field's "
          f"{c['fs_cap_field'] / steps:.1%}), FS_H_MAX "
          f"{c['fs_cap_hmax'] / steps:.1%}, growth {c['fs_cap_grow'] / steps:.1%}, ray end "
          f"{c['fs_cap_end'] / steps:.1%}; near the zero set (|m| < (Z + kappa) sd) "
          f"{c['fs_near_steps'] / steps:.1%}")
    print(f"  monotone stretch (fs_mean_step): {c['fs_mono_scans'] / fl:.2f} slope-range "
          f"scans a flight, cap lifted on {c['fs_mono_steps'] / steps:.1%} of the steps, "
          f"steps certified by the mean alone (no rule) {c['fs_cert_steps'] / steps:.1%}")
    print(f"  occupancy clip (gpis_proxy.h): {c['fs_occ_entries'] / fl:.2f} proxy entries a "
          f"flight, {c['fs_occ_marches'] / fl:.2f} that march, {c['fs_occ_evals'] / fl:.2f} "
          f"march mean evaluations")
    print("  stage device seconds: " + ", ".join(
        f"{k} {v:.2f} ({v / total:.0%})" for k, v in sorted(stages.items(), key=lambda kv: -kv[1])
        if v / total >= 0.02))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=SCENES)
    ap.add_argument("--resolution", type=int, default=32)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-rates", action="store_true", help="counters only")
    ap.add_argument("--device", default=None)
    args = ap.parse_args()
    dev = Device(args.device)
    print(f"device: {dev.name}; {args.resolution}^2 px, {args.spp} spp")
    for path in args.scenes:
        name = Path(path).stem
        report(name, *profile(dev, path, args.resolution, args.spp))
        if args.no_rates:
            continue
        variants = {k: compiled(path, args.resolution, c) for k, c in VARIANTS.items()}
        for scene, settings in variants.values():
            render(dev, scene, settings, 1)
        rates = {k: [] for k in variants}
        for _ in range(args.repeats):
            for k, (scene, settings) in variants.items():
                _, res, sec = render(dev, scene, settings, args.spp)
                rates[k].append(res.stats.paths / sec)
        med = {k: statistics.median(r) for k, r in rates.items()}
        print("  paths per CPU s: " + ", ".join(f"{k} {v:.4g}" for k, v in med.items())
              + f"; exact / uniform 0.99 {med['exact'] / med['uniform 0.99']:.2f}, "
              f"/ uniform 0.9 {med['exact'] / med['uniform 0.9']:.2f}", flush=True)


if __name__ == "__main__":
    main()
