"""Next-event estimation at function-space GPIS hits (fs_normal_pdf.h) against BSDF
sampling: variance at equal samples and at equal time, same run.

    python tools/bench_mirror_nee.py [--resolution 32] [--spp 64] [--seconds 10]
        [--reference-seconds 60] [--repeats 3] [scenes...]

Variants (render settings, not scene keys):
  * `bsdf`     render.nee off: BSDF sampling alone, everywhere;
  * `sampled`  NEE on, but function-space hits use only their sampled normal (fs_nee
               off: the mirror stays delta, the rough conductor has light samples
               evaluated at the sampled normal): the renderer before this change;
  * `nee+mis`  NEE that picks the normal (mirror: the half vector; conductor: A/B
               mixture) with the power heuristic against BSDF sampling.
Per scene: a reference (`nee+mis` for --reference-seconds, its own seed). Per variant:
paths/s (median of --repeats renders at --spp, variants alternating so load from other
users of the machine hits all alike), at equal samples the sample variance svar/spp
(mean over pixels and channels of stderr^2 * spp) and MSE*spp (the MSE against the
reference less the reference's variance, times spp: the per-sample variance, median of
the repeats); at equal time (--seconds, another seed) the MSE; ratios are to `nee+mis`.
The MSE, not the sample variance, is the measure: BSDF sampling under a sun meets it in
~1 path in 10^4, so most of its pixels have seen no firefly and their sample variance is
~0 while their error is the whole glint. The image means against the reference's (z)
check that the variants agree.

Measured (PoCL CPU, 2 cores shared with other jobs; defaults: 32^2 px, 64 spp x 3,
10 s, reference 60 s; two runs, run 1 / run 2):
  fs_mirror_ball_sun  MSE at equal time relative to nee+mis: bsdf 7.2e3 / 7.1e3, sampled
                      6.4e3 / 6.6e3; MSE*spp at equal spp 52 / 51 (a lower bound: at 64
                      spp BSDF sampling has mostly not met the sun, so its error is the
                      missing glint, not yet the fireflies'); paths/s nee+mis / bsdf
                      0.94 / 0.91; image mean against the reference: nee+mis -0.29% /
                      -0.04%, bsdf +13.5% / +10.9% and sampled +11.1% / +9.6% (fireflies;
                      z ~0.9 by their own sample variances). After merging main's faster
                      march (one run, --repeats 1): MSE at equal time bsdf 1.23e4, sampled
                      1.09e4; MSE*spp at equal spp 84; paths/s nee+mis / bsdf 0.78
  wedge_volume        (rough copper, alpha 0.1, tiny quad light; the diffuse walls
                      dominate the image) MSE at equal time relative to nee+mis: bsdf
                      2.8 / 3.1, sampled 0.93 / 1.27; MSE*spp at equal spp: bsdf 3.4 /
                      3.2, sampled 1.07 / 1.07: the GPIS normal spread (sigma / l = 0.1)
                      and the lobe are alike there, so the lobe strategy adds little.
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

from gpiscl.host.compile.scene import compile_scene  # noqa: E402
from gpiscl.host.render.device import Device  # noqa: E402
from gpiscl.host.render.integrator import WavefrontIntegrator  # noqa: E402
from gpiscl.host.scene.loading import load_scene  # noqa: E402

SCENES = ("scenes/fs_mirror_ball_sun.json", "scenes/wedge_volume.json")
VARIANTS = {"bsdf": {"nee": False}, "sampled": {"fs_nee": False}, "nee+mis": {}}


def compiled(path: str, resolution: int, seed: int):
    data = copy.deepcopy(load_scene(str(ROOT / path)).data)
    data["camera"]["resolution"] = [resolution, resolution]
    data["render"]["seed"] = seed
    return compile_scene(load_scene(data).data), data["render"]


def render(dev, scene, settings, extra, spp=None, seconds=None):
    integ = WavefrontIntegrator(dev, scene, {**settings, **extra}, None)
    t = time.perf_counter()
    res = integ.render(spp if spp else 1 << 20, time_limit=seconds)
    return res, time.perf_counter() - t


def failures(st) -> str:
    bad = st.nan_paths + st.gpis_failed + st.killed_paths
    return f" FAILED PATHS: {st.summary()}" if bad else ""


def whole(img):
    return float(img.mean.mean()), float(np.sqrt((img.stderr.astype(np.float64) ** 2).sum())
                                         / img.mean.size)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenes", nargs="*", default=SCENES)
    ap.add_argument("--resolution", type=int, default=32)
    ap.add_argument("--spp", type=int, default=64, help="equal-samples renders")
    ap.add_argument("--seconds", type=float, default=10.0, help="equal-time budget")
    ap.add_argument("--reference-seconds", type=float, default=60.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--device", default=None)
    args = ap.parse_args()
    dev = Device(args.device)
    print(f"device: {dev.name}; {args.resolution}^2 px; equal samples {args.spp} spp "
          f"(median of {args.repeats}); equal time {args.seconds:g} s; reference: nee+mis "
          f"for {args.reference_seconds:g} s")
    for path in args.scenes:
        name = Path(path).stem
        scene, settings = compiled(path, args.resolution, seed=1)
        for extra in VARIANTS.values():   # warm-up: program builds
            render(dev, scene, settings, extra, spp=1)
        ref, _ = render(dev, *compiled(path, args.resolution, seed=9), VARIANTS["nee+mis"],
                        seconds=args.reference_seconds)
        ref_img = ref.image.mean.astype(np.float64)
        ref_var = ref.image.stderr.astype(np.float64) ** 2

        def mse(img):   # against the reference, its own variance taken out
            return float(((img.mean - ref_img) ** 2 - ref_var).mean())

        rates, var, err = ({k: [] for k in VARIANTS} for _ in range(3))
        for r in range(args.repeats):
            for k, extra in VARIANTS.items():
                res, sec = render(dev, *compiled(path, args.resolution, seed=10 + r), extra,
                                  spp=args.spp)
                rates[k].append(res.stats.paths / sec)
                var[k].append(float((res.image.stderr.astype(np.float64) ** 2).mean())
                              * args.spp)
                err[k].append(mse(res.image) * args.spp)
        rate, v_spp, e_spp = ({k: statistics.median(v) for k, v in d.items()}
                              for d in (rates, var, err))
        timed = {}
        for k, extra in VARIANTS.items():
            res, sec = render(dev, *compiled(path, args.resolution, seed=2), extra,
                              seconds=args.seconds)
            timed[k] = (res.stats.spp_reached, sec, mse(res.image), whole(res.image),
                        failures(res.stats))
        ref_mean = whole(ref.image)
        print(f"\n{name}: reference {ref.stats.spp_reached:.0f} spp, image mean "
              f"{ref_mean[0]:.5g} +- {ref_mean[1]:.2g}{failures(ref.stats)}")
        print(f"  {'variant':9s}{'paths/s':>10s}{'svar/spp':>10s}{'MSE*spp':>10s}{'ratio':>8s}"
              f"{'spp@T':>8s}{'s':>6s}{'MSE@T':>11s}{'ratio':>10s}{'mean/ref-1':>12s}{'z':>7s}")
        for k in VARIANTS:
            spp, sec, mt, (m, se), bad = timed[k]
            z = (m - ref_mean[0]) / np.hypot(se, ref_mean[1])
            print(f"  {k:9s}{rate[k]:10.4g}{v_spp[k]:10.3g}{e_spp[k]:10.3g}"
                  f"{e_spp[k] / e_spp['nee+mis']:8.3g}{spp:8.1f}{sec:6.1f}{mt:11.3g}"
                  f"{mt / timed['nee+mis'][2]:10.3g}{m / ref_mean[0] - 1:+12.3%}{z:7.2f}{bad}",
                  flush=True)


if __name__ == "__main__":
    main()
