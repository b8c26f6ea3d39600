"""Function-space GPIS throughput on the OpenCL device against batched numpy.

    python tools/bench_function_space.py [--repeats 5] [--batch 4096] [--no-render]

1. Conditioned segments/s: one segment = N values along a ray sampled jointly, conditioned
   on a value and a slope at the ray origin (the renewal_plus memory at a vertex): build
   the (N + 2)^2 covariance, Cholesky, whiten, sample. numpy does the same systems batched
   (covariances vectorised over the batch, np.linalg.cholesky on the stack).
2. Free-flight samples/s: fs_free_flight (fs_march.h, adaptive step, window N; the wrapper is
   tools/bench_free_flight.py's) over long
   rays that rarely hit (mean 3 sigma); renewal_plus and global (cap 64) memory; evals/s
   counts the step rule's moment evaluations. The numpy column is the batched segment
   pipeline's rate times N (for scale).
3. Paths/s of a small full render (tests/test_fs_render.py's rough ball, 32x32, 16 spp)
   per memory model, and weight space for scale; then renewal_plus with sigma(x), l(x)
   fields, analytic and sampled on grids (the cost of the fields and of the grid reads).
Numbers are medians over --repeats runs after a warm-up (PoCL compiles per work-group
size on first use); the machines are shared, so compare ratios.
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

from gpiscl.host.render.device import Device  # noqa: E402
from gpiscl.host.gp import Constant
from gpiscl.host.gp import Sphere
from gpiscl.host.gp import SquaredExponential
from gpiscl.host.layout import gp_records  # noqa: E402
from gpiscl.testing.reference import function_space as FS  # noqa: E402
from gpiscl.host.layout import function_space_records as FL  # noqa: E402
from gpiscl.host.render.program_sources import fs_sampler_options, fs_sampler_source  # noqa: E402
from gpiscl.host.layout.records import GPIS_MEMORIES  # noqa: E402
from bench_free_flight import WRAPPER as FLIGHT  # noqa: E402  (tools/ is the script's path)

WRAPPERS = r"""
__kernel void segment(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                      int n, double dt, uint seed, __global double* scratch,
                      __global double* out)
{
    int s = get_global_id(0);
    FsScratch S = fs_scratch(scratch, s);
    FsRng rng = {seed, (uint)s, 0u, 0u, 0u};
    double u = 1.0 - fs_uniform2(rng, 0u, FS_U_GRID).x;
    double3 o = (double3)(0.001 * s, 0.0, 0.0), d = (double3)(0.0, 0.0, 1.0);
    S.rows[0] = fs_obs(o, d, FS_OBS_VALUE, 0.0);
    S.rows[1] = fs_obs(o, d, FS_OBS_DERIV, 0.5);
    for (int i = 0; i < n; ++i) S.rows[2 + i] = fs_obs(o + (i + u) * dt * d, d, FS_OBS_VALUE, 0.0);
    int st = fs_factor(kp[0], mean, mc, S, 0, n + 2);
    fs_whiten_row(S.L, S.e, 0, 0.0, S.mu[0]);
    fs_whiten_row(S.L, S.e, 1, 0.5, S.mu[1]);
    double acc = 0.0;
    for (int i = 0; i < n; ++i)
        acc += fs_sample_row(S.L, S.e, 2 + i, S.mu[2 + i], fs_normal(rng, 0u, i));
    out[s] = st ? NAN : acc;
}

"""
KERNEL = SquaredExponential(sigma=1.0, length_scale=1.0)
MEAN = Sphere(center=(0.0, 0.0, 0.0), radius=0.5)


def field_variants() -> dict:
    """sigma(x) = sigma (1 + 0.3 x) and l(x) = l (0.75 + 0.25 y) over the ball's proxy
    [-1.1, 1.1]^3, analytic and as 12^3 grids of their samples (written to a temporary
    folder that lives as long as the process)."""
    import atexit
    import shutil
    import tempfile
    from gpiscl.host.gp.kernels import LinearField
    sig = {"type": "linear", "value": 1.0, "gradient": [0.3, 0.0, 0.0]}
    ls = {"type": "linear", "value": 0.75, "gradient": [0.0, 0.25, 0.0]}
    folder = Path(tempfile.mkdtemp())
    atexit.register(shutil.rmtree, folder, True)
    h, n = 0.2, 12
    idx = np.stack(np.meshgrid(*[np.arange(n)] * 3, indexing="ij"), -1)
    x = -1.1 + h * idx
    grids = {}
    for key, f in (("sigma_field", sig), ("length_scale_field", ls)):
        values = LinearField(f["value"], tuple(f["gradient"])).eval(x)[0]
        path = folder / f"{key}.npz"
        np.savez(path, values=values, origin=np.full(3, -1.1), voxel_size=np.float64(h))
        grids[key] = {"type": "grid", "file": str(path)}
    return {"analytic": {"sigma_field": sig, "length_scale_field": ls}, "grid": grids}


def median_time(fn, repeats):
    fn()   # warm-up: PoCL compiles per work-group size
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


# --- numpy: the same conditioned segments, batched -----------------------------------

def numpy_systems(n, batch, dt, rng):
    """Covariances (batch, n+2, n+2) with the device's jitter, prior means, and draws z."""
    s = np.arange(batch)
    u = 1.0 - rng.random(batch)
    X = np.zeros((batch, n + 2, 3))
    X[:, :, 0] = 0.001 * s[:, None]
    X[:, 2:, 2] = (np.arange(n)[None, :] + u[:, None]) * dt
    deriv = np.zeros(n + 2, bool)
    deriv[1] = True
    K, mu = FS.stacked_observation_matrix(KERNEL, MEAN, X, deriv, (0.0, 0.0, 1.0))
    return K, mu, rng.standard_normal((batch, n))


def numpy_sample(K, mu, z):
    """Cholesky of the stack, whiten the two memory rows, sample the N targets."""
    L = np.linalg.cholesky(K)
    y = np.array([0.0, 0.5])
    e = np.linalg.solve(L[:, :2, :2], (y - mu[:, :2])[..., None])[..., 0]
    F = (mu[:, 2:] + np.einsum("bij,bj->bi", L[:, 2:, :2], e)
         + np.einsum("bij,bj->bi", L[:, 2:, 2:], z))
    return F.sum(axis=1)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--batch", type=int, default=4096)
    ap.add_argument("--no-render", action="store_true")
    args = ap.parse_args()
    dev = Device()
    print(f"device: {dev.name}")
    p = cl.Program(dev.ctx, fs_sampler_source(WRAPPERS + FLIGHT)).build(
        options=fs_sampler_options(128, 64) + [f"-DFS_DEFAULT_REFINE={FL.DEFAULT_REFINE}"])
    k = {kk.function_name: kk for kk in p.all_kernels()}
    nodes = gp_records.pack_mean(MEAN)
    mf = cl.mem_flags
    kp = cl.Buffer(dev.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR,
                   hostbuf=gp_records.pack_kernel(KERNEL))
    mb = cl.Buffer(dev.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=nodes)
    stride = FL.scratch_doubles(FL.max_rows(128, 64))
    dt = FS.step_size(KERNEL, (0, 0, 1), 0.9)
    rng = np.random.default_rng(1)
    q = dev.queue

    print("\nconditioned segments (value + slope memory, N targets)")
    print("(numpy: covariances + Cholesky + sampling; chol-only: without building the")
    print(" covariances, i.e. np.linalg.cholesky on the stack plus the solves and draws)")
    print(f"{'N':>5}{'batch':>8}{'device seg/s':>15}{'numpy seg/s':>15}{'ratio':>8}"
          f"{'chol-only/s':>16}{'ratio':>8}{'device samples/s':>19}")
    numpy_rate = {}
    for n in (8, 16, 32, 128):
        # whole work-groups of 16 (the launch's local size), at least one
        batch = max(16, (args.batch if n <= 32 else args.batch // 16) // 16 * 16)
        scratch = cl.Buffer(dev.ctx, mf.READ_WRITE, 8 * stride * batch)
        out = cl.Buffer(dev.ctx, mf.WRITE_ONLY, 8 * batch)

        def run_dev():
            k["segment"](q, (batch,), (16,), kp, mb, np.int32(len(nodes)), np.int32(n),
                         np.float64(dt), np.uint32(3), scratch, out)
            q.finish()
        t_dev = median_time(run_dev, args.repeats)
        res = np.empty(batch)
        cl.enqueue_copy(q, res, out)
        assert np.isfinite(res).all(), "a device solve failed"
        t_build = median_time(lambda: numpy_systems(n, batch, dt, rng), args.repeats)
        systems = numpy_systems(n, batch, dt, rng)
        t_chol = median_time(lambda: numpy_sample(*systems), args.repeats)
        t_np = t_build + t_chol
        numpy_rate[n] = batch / t_np
        print(f"{n:>5}{batch:>8}{batch / t_dev:>15.4g}{batch / t_np:>15.4g}"
              f"{t_np / t_dev:>8.2f}{batch / t_chol:>16.4g}{t_chol / t_dev:>8.2f}"
              f"{n * batch / t_dev:>19.4g}")

    print("\nfree flight (fresh rays, 60 length scales, mean 3 sigma: few hits)")
    print(f"{'N':>5}{'memory':>14}{'rays':>7}{'samples/s':>13}{'evals/s':>13}"
          f"{'numpy samples/s':>17}{'ratio':>8}")
    for n in (8, 16):
        for memory in ("renewal_plus", "global"):
            rays = args.batch // 4 if n <= 32 else args.batch // 16
            scratch = cl.Buffer(dev.ctx, mf.READ_WRITE, 8 * stride * rays)
            out = cl.Buffer(dev.ctx, mf.WRITE_ONLY, 40 * rays)
            far = Constant(3.0)
            far_nodes = gp_records.pack_mean(far)
            fb = cl.Buffer(dev.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=far_nodes)

            def run_flight():
                k["flight"](q, (rays,), (16,), kp, fb, np.int32(len(far_nodes)), np.int32(n),
                            np.int32(GPIS_MEMORIES[memory]), np.int32(64), np.float64(60.0),
                            np.float64(0.0), np.float64(FL.DEFAULT_MISS_TOLERANCE),
                            np.uint32(5), scratch, out)
                q.finish()
            t = median_time(run_flight, args.repeats)
            res = np.empty((rays, 5))
            cl.enqueue_copy(q, res, out)
            assert (res[:, 0] >= 0).all(), "a free flight failed"
            samples, segs = res[:, 0].sum(), res[:, 1].sum()
            np_rate = numpy_rate[n] * n
            print(f"{n:>5}{memory:>14}{rays:>7}{samples / t:>13.4g}{segs / t:>13.4g}"
                  f"{np_rate:>17.4g}{samples / t / np_rate:>8.2f}")

    if args.no_render:
        return
    from gpiscl.testing.scenes import SUN_AND_SKY, function_space_sampler, gpis_scene
    from gpiscl import render_result
    print("\nfull render, 32x32 x 16 spp, rough GPIS ball (diffuse 0.9, sun + sky)")
    print(f"{'sampler':>24}{'paths/s':>12}{'rays/path':>11}")
    samplers = [("weight_space M=256", {"type": "weight_space", "features": 256}, None)]
    samplers += [(f"function_space {m}", function_space_sampler(m, memory_cap=64), None)
                 for m in ("none", "renewal", "renewal_plus", "global")]
    # renewal_plus with sigma(x) and l(x): analytic fields, and the same sampled on grids
    samplers += [(f"rp {kind} fields", function_space_sampler("renewal_plus"), fields)
                 for kind, fields in field_variants().items()]
    for name, sampler, fields in samplers:
        scene = gpis_scene(sampler, "diffuse", 0.9, SUN_AND_SKY, 16, seed=7, max_depth=64,
                           rr_start=8)
        scene["camera"]["resolution"] = [32, 32]
        if fields:
            scene["shapes"][0]["kernel"].update(fields)
        stats = []
        render_result(scene, device=dev)   # warm-up
        for _ in range(max(1, args.repeats // 2)):
            stats.append(render_result(scene, device=dev).stats)
        rate = statistics.median(s.paths / s.seconds for s in stats)
        print(f"{name:>24}{rate:>12.4g}{stats[0].rays / stats[0].paths:>11.2f}")


if __name__ == "__main__":
    main()
