"""Markov (state-space) free flight of fs_markov.h against the general conditional
sampler of fs_march.h, same run, medians of --repeats (the two alternate, so load from
other users of the machine hits both alike).

    python tools/bench_markov.py [--rays 4096] [--length 40] [--resolution 32] [--spp 4]
        [--repeats 3] [--refine N]

1. Free flight (tests/markov_wrappers.py's mk_flights): rays of --length l along a line
   through constant-mean Matern 3/2 and 5/2 (l = 1, sigma = 1, mean 0 and 2 sigma),
   continued through every hit with renewal_plus memory, at the default miss tolerance
   for both (equal accuracy: the same bound on missed crossings per l_d). GP samples/s
   (states drawn by Markov, values by the general sampler; bisection points included),
   ray length/s (l per second: samples per length differ), and their ratios.
2. Render: scenes/fs_volume_room_global.json with its kernel turned matern52 (same
   sigma and l) and memory renewal_plus: paths/s with the Markov sampler and with the
   general one forced (GpisObject.general = 1 on the compiled objects). The scene as
   shipped (global memory) always takes the general sampler: global memory conditions
   on rows off the ray, which breaks the ray's Markov property.

Measured 2026-12-02 (helper markov3: fs_mk_predict, the step predictor; PoCL CPU, 2
cores, load average 7-9 from other sessions, so single timings scatter by 10-20%; CPU time
of this process; defaults (refine 0), each line the median of 4 bench runs of 3 (two
sessions of two), base and predictor alternating):
    free flight   samples/s Markov / general   ratio   l/s ratio   base 40b0be2: ratio, l/s
    m32 mu 0      2.10e6 / 3.58e5              5.75x   7.35x       6.58x, 7.57x
    m32 mu 2      2.15e6 / 3.79e5              5.73x   7.46x       6.37x, 7.41x
    m52 mu 0      1.50e6 / 3.55e5              4.19x   5.58x       3.75x, 4.73x
    m52 mu 2      1.64e6 / 3.56e5              4.65x   6.75x       4.15x, 5.44x
    render 32^2, 4 spp   3.69e4 / 1.36e4 paths/s   2.73x                2.61x
The general sampler is the same code in both trees, yet its rate moved by up to 16%
between their runs (m52: 4.0e5 in the base's, 3.55e5 in the predictor's): the load. The
Markov sampler's own l/s, base -> predictor in the same session: m32 3.16e5 -> 3.33e5
(+5%), 9.09e5 -> 9.72e5 (+7%); m52 5.69e5 -> 5.84e5 (+3%), 1.27e6 -> 1.41e6 (+11%).
Per ray (CPU us, 40 l, medians of 5 alternating runs of tests/markov_wrappers.flights,
base / predictor): m32 mu 0 130.0 / 122.3 (1.06x), mu 2 43.7 / 42.8 (1.02x), m52 mu 0
74.8 / 70.4 (1.06x), mu 2 29.5 / 29.7 (0.99x). The predictor takes fewer samples per l
(m32 mu 0: 279 -> 252, m52: 108 -> 103) and 35% fewer rule evaluations (544 -> 350, 161 ->
110), so the samples/s ratio understates it: the l/s ratio is the equal-accuracy one.
Before it (main at c8b3f6c, quiet machine, medians of 3):
    free flight   samples/s Markov / general   ratio     l/s ratio
    m32 mu 0      2.94e6 / 5.03e5              5.85x     6.73x
    m32 mu 2      3.66e6 / 5.90e5              6.22x     7.23x
    m52 mu 0      2.33e6 / 5.61e5              4.15x     5.25x
    m52 mu 2      2.67e6 / 5.63e5              4.74x     6.21x
    render 32^2, 4 spp   5.98e4 / 2.22e4 paths/s   2.69x
    render 64^2, 16 spp  7.61e4 / 1.93e4 paths/s   3.94x
Against its base 2ecaf8b at refine 6 (helper's runs, load ~5, alternating): samples/s
ratios 6.2-6.4x / 6.2x / 3.8-3.9x / 4.6x, then 2.9-3.0x / 3.1-3.3x / 1.9-2.1x / 2.5-2.6x
at the base; renders 2.75-2.85x at 32^2 (base 2.0-2.1x), 3.98x at 64^2 (base 2.43x).
The Markov sampler itself is 1.75-2.1x faster per sample than at the base (same runs):
closed-form A(h), Q(h) with one incomplete gamma by Estrin's scheme (a transition 53 ->
18 ns), the rule's rate bracketed by normal-tail bounds with erfc only near a threshold
(fs_mk_rule_ratio, the same decisions), the moments without the sqrt/divide chain, one
sincos per Box-Muller pair, O(n^3) bridges with reciprocal pivots, no mean program on a
ray where the mean's Lipschitz bound is 0, and the down-crossing slope search that crept
up on its root by halvings (shared: ~18 evaluations of S a hit -> ~5; the general
sampler gains from it too). Per call now (wrapper loops, min of 7, m32 / m52): transition
18 / 24 ns, a rule evaluation with its transition ~72 ns (the exact rate alone 125), a
step's state draw with its transition 78 / 141 ns, a bridge draw 145 / 230 ns (base 206 /
363), the slope law at a hit 135 / 213 ns (base 263 / 418), the down-crossing slope ~0.45
us (base 1.4). The rate at 32^2 is mostly the host's: at 64^2 and 16 spp the kernels'
share shows. Where a flight's time goes, the predictor and what was tried besides it:
fs_markov.h's header ("Step rule", "Cost").
Measured 2026-12-03 (the two-node step rule in both samplers; defaults, one run, load ~6):
samples/s Markov / general and ratio, l/s ratio: m32 mu 0 2.21e6 / 3.41e5 6.47x, 8.24x;
m32 mu 2 1.87e6 / 2.80e5 6.67x, 8.53x; m52 mu 0 1.46e6 / 3.01e5 4.84x, 6.42x; m52 mu 2
1.68e6 / 2.85e5 5.87x, 7.92x; render 32^2, 4 spp 3.63e4 / 1.15e4 paths/s 3.17x. Per ray
the second node raised m32's samples 252 -> 303 and evaluations 350 -> 723 (fs_markov.h).
What stands between this and the issue's 30x: the goal assumed a Cholesky over whole
rays; the general sampler keeps a window of 16 rows and evaluates its step rule on <= 14,
~1.6-2 us of CPU per sample. 30x would be ~55-65 ns a sample. A Markov step costs its
own transition and state draw (~78 ns quiet, a Box-Muller log and sincos inside) plus
1.4 rule evaluations with the predictor (~72 ns each) and the predictor: ~0.2 us before
bisections and hits. Even the rule's floor (an oracle taking the largest accepted step
at every step, its search not counted: 175 instead of ~235 steps a ray for m32, 58
instead of ~80 for m52) at one evaluation a step would do 374 / 146 evaluations plus
samples a ray against 602 / 213 now (820 / 269 with the fixed growth factors): at most
~1.6x more from the step sequence, not 5x. Beyond that: a different rule (fewer, longer steps at the same miss
bound), or work-items that step in lockstep so PoCL can vectorise across rays (not with
per-ray branching as now).
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
sys.path.insert(0, str(ROOT / "tests"))

from gpiscl.host.compile.scene import compile_scene  # noqa: E402
from gpiscl.host.gp import Constant, Matern32, Matern52  # noqa: E402
from gpiscl.host.layout import records as layouts  # noqa: E402
from gpiscl.host.layout import function_space_records as FL  # noqa: E402
from gpiscl.host.render.device import Device  # noqa: E402
from gpiscl.host.render.integrator import WavefrontIntegrator  # noqa: E402
from gpiscl.host.scene.loading import load_scene  # noqa: E402
from markov_wrappers import flights  # noqa: E402

SCENE = "scenes/fs_volume_room_global.json"


def flight_rates(dev, kernel, mu, rays, length, repeats, refine):
    """Median samples/s and length/s, and per-ray samples, for Markov and general."""
    rates = {True: [], False: []}
    per_ray = {}
    for _ in range(repeats):
        for markov in (True, False):
            t = time.process_time()
            out = flights(dev, kernel, Constant(mu), rays, markov=markov,
                          memory="renewal_plus", refine=refine, t1=length, seed=5,
                          restarts=1 << 20)
            sec = time.process_time() - t
            bad = int(np.count_nonzero(out[:, 5]))
            rates[markov].append((out[:, 6].sum() / sec, rays * length / sec))
            per_ray[markov] = (out[:, 6].mean(), out[:, 4].mean(), bad)
    med = {k: (statistics.median(r[0] for r in v), statistics.median(r[1] for r in v))
           for k, v in rates.items()}
    return med, per_ray


def room(kernel_type: str, resolution: int, general: int):
    data = copy.deepcopy(load_scene(str(ROOT / SCENE)).data)
    data["camera"]["resolution"] = [resolution, resolution]
    for s in data["shapes"]:
        if s["type"] == "gpis":
            s["kernel"] = {"type": kernel_type, "sigma": s["kernel"]["sigma"],
                           "length_scale": s["kernel"]["length_scale"]}
            s["sampler"] = {"type": "function_space", "memory": "renewal_plus"}
    data = load_scene(data).data
    scene = compile_scene(data)
    objs = scene.gpis.objects
    objs["general"][objs["sampler"] == layouts.GPIS_SAMPLERS["function_space"]] = general
    return scene, data["render"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rays", type=int, default=4096)
    ap.add_argument("--length", type=float, default=40.0)
    ap.add_argument("--resolution", type=int, default=32)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--refine", type=int, default=FL.DEFAULT_REFINE,
                    help="free flight: root-search points forced per hit (default: the "
                         "scenes' default)")
    ap.add_argument("--device", default=None)
    args = ap.parse_args()
    dev = Device(args.device)
    print(f"device: {dev.name}; median of {args.repeats}")
    print(f"\nfree flight: {args.rays} rays x {args.length:g} l, renewal_plus, default tolerance, "
          f"refine {args.refine}")
    print(f"  {'kernel':8s}{'mu':>4s}{'sampler':>9s}{'samples/s':>12s}{'l/s':>11s}"
          f"{'samples/ray':>13s}{'hits/ray':>10s}{'failed':>8s}")
    flights(dev, Matern32(), Constant(0.0), 64, markov=True)    # builds the program
    for name, kern in (("m32", Matern32(1.0, 1.0)), ("m52", Matern52(1.0, 1.0))):
        for mu in (0.0, 2.0):
            med, per = flight_rates(dev, kern, mu, args.rays, args.length, args.repeats,
                                    args.refine)
            for markov in (True, False):
                s, ln = med[markov]
                spr, hits, bad = per[markov]
                print(f"  {name:8s}{mu:4g}{'Markov' if markov else 'general':>9s}{s:12.4g}"
                      f"{ln:11.4g}{spr:13.1f}{hits:10.2f}{bad:8d}")
            print(f"  {'':12s}{'ratio':>9s}{med[True][0] / med[False][0]:12.3g}"
                  f"{med[True][1] / med[False][1]:11.3g}", flush=True)

    print(f"\nrender: {Path(SCENE).stem} turned matern52 / renewal_plus, "
          f"{args.resolution}^2 px, {args.spp} spp")
    variants = {g: room("matern52", args.resolution, g) for g in (0, 1)}
    for scene, settings in variants.values():     # warm-up: program builds
        WavefrontIntegrator(dev, scene, settings, None).render(1)
    rates, stats = {0: [], 1: []}, {}
    for _ in range(args.repeats):
        for g, (scene, settings) in variants.items():
            integ = WavefrontIntegrator(dev, scene, settings, None)
            t = time.process_time()
            res = integ.render(args.spp)
            rates[g].append(res.stats.paths / (time.process_time() - t))
            stats[g] = res.stats
    for g, name in ((0, "Markov"), (1, "general")):
        st = stats[g]
        fl = max(st.fs_flights, 1)
        bad = st.nan_paths + st.gpis_failed + st.killed_paths
        print(f"  {name:8s} paths/s {statistics.median(rates[g]):10.4g}  samples/flight "
              f"{st.fs_samples / fl:7.2f}  evals/flight {st.fs_evals / fl:7.2f}"
              f"  failed {bad}")
    print(f"  ratio    {statistics.median(rates[0]) / statistics.median(rates[1]):.3g}")


if __name__ == "__main__":
    main()
