"""Cost of a posterior GPIS solve as the number of observations grows.

    python tools/bench_posterior.py [--sizes 100,1000,10000] [--normals]
                                    [--device-sizes 0,100,1000] [--rays 256]
                                    [--render-sizes 0,100,300]

Per size n (surface points on a sphere; --normals adds three derivative observations
per point, so 4n in all): seconds to build K, factor it (Cholesky) and solve for the
weights (and how much of that is building K), then per-point costs of the posterior mean
and variance, and the setup of one pathwise (Matheron) realization (one more solve).
Memory: two n x n float64 matrices (K and its factor), 1.6 GB at n = 10^4.

Renders (--render-sizes, 0 = the prior): the reconstructed sphere of
tests/test_posterior_render.py with n observed points, weight space and function space,
seconds and the ratio to the same sampler's prior.

Device (--device-sizes, 0 = the prior): function-space free flight through a posterior
GPIS (fs_sampling.h with the observations of compile/posterior.py), rays through a
sphere of observed points; microseconds per step-rule evaluation and per GP sample (one row:
n kernel evaluations, an n x n triangular solve, and its covariance entries).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

# OpenBLAS's threaded Cholesky is ~40x slower than one thread on a loaded 2-core machine
# (5 s vs 0.13 s at n = 1000 here); set OPENBLAS_NUM_THREADS to override.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from gpiscl.host.gp import Sphere, SquaredExponential  # noqa: E402
from gpiscl.host.gp.posterior import Posterior, surface_observations  # noqa: E402
from gpiscl.host.gp.spectral import RandomFeatures  # noqa: E402


FLIGHT = r"""
__kernel void flight(__global const GpKernel* kp, __global const MeanNode* means, int first,
                     int mc, __global const double* dirs, __global double* scratch,
                     __global int* out)
{
    int i = get_global_id(0);
    FsScratch S = fs_scratch(scratch, i);
    S.post = fs_posterior_of(means, first);
    FsParams prm = {16, GPIS_MEMORY_RENEWAL_PLUS, 8, 6, 0.0, 1e-5};
    double3 d = vload3(i, dirs);
    FsRay r = {-2.0 * d, d, 0.0, 4.0};
    FsRng rng = {1u, (uint)i, 0u, 0u, 0u};
    FsVertex v = {0};
    FsResult res = fs_free_flight(kp[0], means + first, mc, prm, r, v, 0, rng, S);
    out[3 * i] = res.evals;
    out[3 * i + 1] = res.samples;
    out[3 * i + 2] = res.status;
}
"""


def device_cost(sizes, rays: int):
    import pyopencl as cl
    from gpiscl.host.compile import posterior as PC
    from gpiscl.host.render.device import Device
    from gpiscl.host.render.program_sources import PYOPENCL_CL_DIR, kernel_source
    from gpiscl.host.layout import gp_records
    from gpiscl.host.layout import function_space_records as FL
    from gpiscl.host.render.program_sources import fs_sampler_source
    dev = Device()
    kernel = SquaredExponential(sigma=0.2, length_scale=0.3)
    mean = Sphere(radius=1.0)
    rng = np.random.default_rng(1)
    dirs = rng.standard_normal((rays, 3)) * [0.2, 0.2, 1.0]
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    src = fs_sampler_source(kernel_source("fs_posterior.h") + FLIGHT)
    print(f"\ndevice ({dev.name}), {rays} rays, N = 16, renewal_plus:")
    print(f"{'n obs':>8}{'evals':>10}{'samples':>8}{'us/eval':>12}{'us/sample':>9}")
    for n in sizes:
        prog = gp_records.pack_mean(mean)
        nodes, first = prog, 0
        if n:
            d = rng.standard_normal((n, 3))
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            post = Posterior(kernel, mean, surface_observations(0.9 * d, noise=1e-4))
            block = PC.pack_posterior(post)
            nodes, first = np.concatenate([block, prog]), len(block)
        defs = FL.defines(16, 8, post_rows=n)
        opts = [f"-I{PYOPENCL_CL_DIR}"] + [f"-D{k}={v}" for k, v in sorted(defs.items())]
        k = cl.Program(dev.ctx, src).build(options=opts).flight
        mf = cl.mem_flags

        def buf(a):
            return cl.Buffer(dev.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR,
                             hostbuf=np.ascontiguousarray(a))
        scratch = cl.Buffer(dev.ctx, mf.READ_WRITE, 8 * defs["FS_SCRATCH_DOUBLES"] * rays)
        out = np.zeros((rays, 3), np.int32)
        ob = cl.Buffer(dev.ctx, mf.WRITE_ONLY, out.nbytes)
        args = (buf(gp_records.pack_kernel(kernel)), buf(nodes), np.int32(first),
                np.int32(len(prog)), buf(dirs), scratch, ob)
        k(dev.queue, (rays,), None, *args).wait()      # warm-up (compilation per size)
        t0 = time.perf_counter()
        k(dev.queue, (rays,), None, *args).wait()
        dt = time.perf_counter() - t0
        cl.enqueue_copy(dev.queue, out, ob)
        assert np.all(out[:, 2] == 0), np.unique(out[:, 2])
        seg, rows = out[:, 0].sum(), out[:, 1].sum()
        print(f"{n:>8}{seg:>10}{rows:>8}{dt / seg * 1e6:>12.1f}{dt / rows * 1e6:>9.1f}")


def render_cost(sizes, resolution: int, spp: int, repeats: int):
    """Render seconds of the reconstructed-sphere scene of tests/test_posterior_render.py
    (a rough prior of radius 1.2 conditioned on n noisy points of the unit sphere), both
    samplers, and the ratio to each sampler's prior (n = 0), same run."""
    import tempfile
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_occupancy import time_variants
    from gpiscl.host.render.device import Device
    from gpiscl.host.scene.loading import load_scene
    from gpiscl.testing.scenes import noisy_sphere_points, sphere_scene
    folder = Path(tempfile.mkdtemp())
    variants = {}
    for n in sizes:
        for sampler in ("weight_space", "function_space"):
            obs = (None if n == 0 else
                   {"file": noisy_sphere_points(folder / f"p{n}.xyz", n, 0.03), "noise": 0.03})
            scene = sphere_scene(1.2, 0.6, spp, obs, res=resolution)
            scene["shapes"][0]["sampler"] = (
                {"type": sampler} if sampler == "weight_space"
                else {"type": "function_space"})
            variants[(sampler, n)] = load_scene(scene).data
    times, _ = time_variants(Device(), variants, spp, repeats)
    print(f"\nrenders, {resolution}^2 x {spp} spp, median of {repeats}:")
    print(f"{'n obs':>8}{'weight space [s]':>18}{'x prior':>9}{'function space [s]':>20}"
          f"{'x prior':>9}")
    for n in sizes:
        ws, fs = times[("weight_space", n)], times[("function_space", n)]
        print(f"{n:>8}{ws:>18.2f}{ws / times[('weight_space', sizes[0])]:>9.1f}"
              f"{fs:>20.2f}{fs / times[('function_space', sizes[0])]:>9.1f}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="100,1000,10000")
    ap.add_argument("--normals", action="store_true")
    ap.add_argument("--probes", type=int, default=2000)
    ap.add_argument("--device-sizes", default="0,100,1000")
    ap.add_argument("--rays", type=int, default=256)
    ap.add_argument("--render-sizes", default="0,100,300",
                    help="observation counts of the render comparison ('' skips it)")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    kernel = SquaredExponential(sigma=0.2, length_scale=0.3)
    mean = Sphere(radius=1.0)
    probes = rng.uniform(-1.0, 1.0, (args.probes, 3))
    print(f"{'n obs':>8}{'K + factor [s]':>16}{'of it K [s]':>13}{'mean [us/pt]':>14}"
          f"{'var [us/pt]':>13}{'pathwise [s]':>14}{'jitter':>9}")
    for n in (int(v) for v in args.sizes.split(",")):
        d = rng.standard_normal((n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        obs = surface_observations(0.8 * d, d if args.normals else None, noise=1e-4)
        t0 = time.perf_counter()
        post = Posterior(kernel, mean, obs)
        t1 = time.perf_counter()
        post.mean(probes)
        t2 = time.perf_counter()
        m = min(len(probes), 200)
        post.variance(probes[:m])
        t3 = time.perf_counter()
        sample = post.pathwise(RandomFeatures.sample(kernel, 256, rng),
                               rng.standard_normal(256), rng)
        t4 = time.perf_counter()
        sample(probes)
        t5 = time.perf_counter()
        post._blocks(obs.x, obs.u)          # building K alone, to split the first column
        t_k = time.perf_counter() - t5
        print(f"{len(obs):>8}{t1 - t0:>16.3f}{t_k:>13.3f}{(t2 - t1) / len(probes) * 1e6:>14.2f}"
              f"{(t3 - t2) / m * 1e6:>13.1f}{t4 - t3:>14.3f}{post.jitter:>9.0e}")
    if args.device_sizes:
        device_cost([int(v) for v in args.device_sizes.split(",")], args.rays)
    if args.render_sizes:
        render_cost([int(v) for v in args.render_sizes.split(",")], 32, 4, 3)
    return 0


if __name__ == "__main__":
    sys.exit(main())
