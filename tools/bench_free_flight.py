"""Function-space free flight alone: CPU microseconds per length scale of ray for the
adaptive step (the default miss_tolerance and 1e-7) against the old uniform step at
neighbour correlation 0.9 and 0.99, same run.

    python tools/bench_free_flight.py [--rays 4096] [--repeats 7] [--levels 0 1 2 3]

Fresh rays (renewal_plus memory, SE sigma = l = 1) of 30 length scales through a constant
mean mu (the level, in sigma); a flight ends at its first crossing. Times are CPU seconds
of this process (PoCL's CPU threads run here; time.process_time), so other users of a
shared machine do not skew them; variants are interleaved and each repetition's ratio to
uniform 0.9 is taken before the median. Also printed: GP values drawn and step-rule
evaluations per flight, and how many of those values the root search at the hit drew.

Measured (PoCL CPU, 2-core shared machine, 2026-12-02, after the root search of fs_march.h
and the slope inversion's fix): CPU us per length scale, adaptive 2e-6 / uniform 0.9 /
uniform 0.99, samples per flight (of which root search) in brackets:
    mu 0: 2.87 (6.97, 2.90) / 2.27 (9.31, 2.82) / 5.36 (20.65, 2.15)
    mu 1: 2.02 (12.61, 3.04) / 1.65 (20.82, 2.94) / 5.00 (58.12, 2.15)
    mu 2: 1.70 (23.92, 1.65) / 1.78 (50.48, 1.57) / 5.65 (154.71, 1.13)
    mu 3: 1.29 (24.67, 0.19) / 1.73 (64.99, 0.17) / 5.24 (206.58, 0.14)
The same flights before (main at 2ecaf8b, refine 6, bisection), run right after: adaptive
samples per flight 10.36 / 15.77 / 25.41 / 24.82 at mu 0 / 1 / 2 / 3. Same process,
interleaved (both samplers built in one run, medians of 7 ratios), CPU time per flight
after / before: adaptive 0.69 / 0.78 / 0.91 / 1.00, uniform 0.9 0.62 / 0.80 / 0.96 / 0.96,
uniform 0.99 0.71 / 0.90 / 0.98 / 1.00.

Measured 2026-12-02 after fs_march.h's mean-cap change (a constant mean has no cap: the
same steps, samples and evaluations as main at 40b0be2, bit for bit), 2048 rays, medians
of 3, before (40b0be2) and after alternating, two runs each (2-core machine at load ~9):
CPU us per l adaptive 2e-6 / uniform 0.9 / uniform 0.99, and adaptive / uniform 0.9:
    mu 1: before 3.88 / 3.06 / 9.09, 1.31; 3.89 / 3.24 / 9.44, 1.19
          after  3.57 / 2.80 / 7.94, 1.10; 3.74 / 3.09 / 9.01, 1.21
    mu 2: before 2.46 / 2.56 / 8.29, 1.01; 2.53 / 2.26 / 8.52, 1.19
          after  2.65 / 2.52 / 7.90, 1.05; 2.44 / 2.58 / 6.98, 1.07
    mu 3: before 2.15 / 2.59 / 8.86, 0.83; 1.72 / 2.23 / 8.15, 0.83
          after  1.77 / 2.32 / 8.67, 0.81; 1.86 / 2.59 / 7.97, 0.80
Samples per flight 12.70 / 24.04 / 24.75 (adaptive), 20.97 / 51.03 / 65.10 (0.9),
58.41 / 155.79 / 206.52 (0.99); rule evaluations per flight 18.05 / 41.04 / 40.48, i.e.
~1.85 per step (steps = samples - root points): nearly every other try is rejected. That
is where the adaptive default loses to uniform 0.9 at mu <= 2 here (it draws 40-60% of
the values but pays an evaluation of the rule's small system per try), and what a step
predictor from the bound's ratio (instead of the 2 / 1.5 / 1.1 ladder and halving) would
go after.
Measured 2026-12-03 (the two-node Gauss-Radau step rule; defaults, one run, load ~6 from
other jobs). CPU us per l, adaptive (2e-6) relative to uniform 0.9 / samples, evaluations
per flight of the adaptive default / uniform 0.99 relative to uniform 0.9:
    mu 0   4.55 us: 1.53x   7.21, 13.35   uniform 0.99 2.39x
    mu 1   3.16 us: 1.59x  13.26, 31.34                2.89x
    mu 2   2.56 us: 1.34x  26.49, 72.79                3.35x
    mu 3   2.48 us: 1.11x  29.93, 85.00                3.24x
Adaptive takes 0.46-0.77x uniform 0.9's GP values a flight (and far fewer than 0.99's:
0.14-0.35x) but ~2.5-2.9 rule evaluations a step (two nodes on every accepted try), which
is what keeps it 1.1-1.6x slower than uniform 0.9 per length; against uniform 0.99 (the
unbiased uniform setting) it is 1.5-2.6x faster. Tolerance 1e-7 costs 2-14% more.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import pyopencl as cl

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from gpiscl.host.gp import Constant, SquaredExponential  # noqa: E402
from gpiscl.host.layout import function_space_records as FL  # noqa: E402
from gpiscl.host.layout import gp_records  # noqa: E402
from gpiscl.host.layout.records import GPIS_MEMORIES  # noqa: E402
from gpiscl.host.render.device import Device  # noqa: E402
from gpiscl.host.render.program_sources import fs_sampler_options, fs_sampler_source  # noqa: E402

# one fresh flight per item along z (also tools/bench_function_space.py's): samples, rule
# evaluations, the hit distance (or t1), whether it hit and the samples of the root
# search; samples < 0: a failed solve
WRAPPER = r"""
__kernel void flight(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                     int window, int memory, int cap, double t1, double step_corr,
                     double tol, uint seed, __global double* scratch, __global double* out)
{
    int s = get_global_id(0);
    FsParams prm = {window, memory, cap, FS_DEFAULT_REFINE, step_corr, tol};
    FsRay r = {(double3)(0.001 * s, 0.0, 0.0), (double3)(0.0, 0.0, 1.0), 0.0, t1};
    FsRng rng = {seed, (uint)s, 0u, 0u, 0u};
    FsVertex v = {0};
    FsResult res = fs_free_flight(kp[0], mean, mc, prm, r, v, 0, rng, fs_scratch(scratch, s));
    out[5 * s] = res.status ? -1.0 : res.samples;
    out[5 * s + 1] = res.evals;
    out[5 * s + 2] = res.t;
    out[5 * s + 3] = res.hit;
    out[5 * s + 4] = res.roots;
}
"""
LENGTH = 30.0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rays", type=int, default=4096)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--levels", type=float, nargs="*", default=[0.0, 1.0, 2.0, 3.0])
    args = ap.parse_args()
    dev = Device()
    window = FL.DEFAULT_WINDOW
    prog = cl.Program(dev.ctx, fs_sampler_source(WRAPPER)).build(
        options=fs_sampler_options(window, 64) + [f"-DFS_DEFAULT_REFINE={FL.DEFAULT_REFINE}"])
    flight = cl.Kernel(prog, "flight")
    mf = cl.mem_flags
    kp = cl.Buffer(dev.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR,
                   hostbuf=gp_records.pack_kernel(SquaredExponential(sigma=1.0, length_scale=1.0)))
    scratch = cl.Buffer(dev.ctx, mf.READ_WRITE,
                        8 * FL.scratch_doubles(FL.max_rows(window, 64)) * args.rays)
    out = cl.Buffer(dev.ctx, mf.WRITE_ONLY, 40 * args.rays)
    variants = {f"adaptive {FL.DEFAULT_MISS_TOLERANCE:g}": (0.0, FL.DEFAULT_MISS_TOLERANCE),
                "adaptive 1e-7": (0.0, 1e-7), "uniform 0.9": (0.9, 0.0),
                "uniform 0.99": (0.99, 0.0)}
    print(f"device: {dev.name}; {args.rays} rays of {LENGTH:g} l, median of {args.repeats}")
    print(f"{'mu/sigma':>8} {'variant':16s}{'cpu us/l':>10s}{'/uniform 0.9':>14s}"
          f"{'samples/flight':>16s}{'of which root':>15s}{'evals/flight':>14s}{'hit':>7s}")
    for mu in args.levels:
        nodes = gp_records.pack_mean(Constant(mu))
        mb = cl.Buffer(dev.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=nodes)
        runs = {k: [] for k in variants}
        for rep in range(args.repeats + 1):           # the first is a warm-up
            for name, (corr, tol) in variants.items():
                t = time.process_time()
                flight(dev.queue, (args.rays,), None, kp, mb, np.int32(len(nodes)),
                       np.int32(window), np.int32(GPIS_MEMORIES["renewal_plus"]), np.int32(64),
                       np.float64(LENGTH), np.float64(corr), np.float64(tol), np.uint32(rep),
                       scratch, out)
                dev.queue.finish()
                sec = time.process_time() - t
                r = np.empty((args.rays, 5))
                cl.enqueue_copy(dev.queue, r, out)
                assert (r[:, 0] >= 0).all(), "a free flight failed"
                if rep:
                    runs[name].append((sec / r[:, 2].sum() * 1e6, r[:, 0].mean(),
                                       r[:, 1].mean(), r[:, 3].mean(), r[:, 4].mean()))
        base = [x[0] for x in runs["uniform 0.9"]]
        for name, xs in runs.items():
            us = [x[0] for x in xs]
            ratio = statistics.median(a / b for a, b in zip(us, base))
            print(f"{mu:8g} {name:16s}{statistics.median(us):10.3f}{ratio:14.2f}"
                  f"{xs[0][1]:16.2f}{xs[0][4]:15.2f}{xs[0][2]:14.2f}{xs[0][3]:7.3f}", flush=True)


if __name__ == "__main__":
    main()
