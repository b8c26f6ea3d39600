"""Cost of a posterior GPIS solve as the number of observations grows.

    python tools/bench_posterior.py [--sizes 100,1000,10000] [--normals]

Per size n (surface points on a sphere; --normals adds three derivative observations
per point, so 4n in all): seconds to build K, factor it (Cholesky) and solve for the
weights (and how much of that is building K), then per-point costs of the posterior mean
and variance, and the setup of one pathwise (Matheron) realization (one more solve).
Memory: two n x n float64 matrices (K and its factor), 1.6 GB at n = 10^4.
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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="100,1000,10000")
    ap.add_argument("--normals", action="store_true")
    ap.add_argument("--probes", type=int, default=2000)
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
