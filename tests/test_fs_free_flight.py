"""Function-space free flight on the device (fs_sampling.h through the `flight` wrapper of
test_fs_sampling): memory models on a fresh ray, convergence to a dense joint sample as
the step shrinks, Rice's crossing rate along long rays that continue through each hit."""
import math

import numpy as np

from gpiscl.host.gp import Constant, Plane, SquaredExponential
from gpiscl.testing.reference import function_space as FS
from gpiscl.testing.stats import z_threshold
from gpiscl.testing.flights import flights
from gpiscl.testing.stats import ks_two_sample

SE = SquaredExponential(sigma=1.0, length_scale=0.5)
# mean 3 - x along the ray (0,0,0) + t (1,0,0): the surface sits near t = 3
RAMP = Plane(point=(3.0, 0.0, 0.0), normal=(-1.0, 0.0, 0.0))
MEMORIES = ("none", "renewal", "renewal_plus", "global")


def test01_a_fresh_ray_is_the_same_under_every_memory_model(device, flight_prg):
    """Memory only acts at a vertex: a fresh ray draws identical hits under every model
    (shared random numbers; inside a ray every model conditions on the same window).
    none/renewal/renewal_plus share the normal too (isotropic closed form); global draws
    the tangential components given every row, which must give the same law."""
    runs = {m: flights(device, flight_prg, SE, RAMP, 6000, memory=m, t1=6.0, seed=5)
            for m in MEMORIES}
    ref = runs["none"]
    assert np.mean(ref[:, 0] >= 0) > 0.5
    for m, out in runs.items():
        np.testing.assert_array_equal(out[:, 0], ref[:, 0], err_msg=m)
        np.testing.assert_array_equal(out[:, 1], ref[:, 1], err_msg=m)   # the slope law
        if m != "global":
            np.testing.assert_array_equal(out[:, 1:4], ref[:, 1:4], err_msg=m)
    hit = ref[:, 0] >= 0
    for j in (2, 3):
        D, crit = ks_two_sample(runs["global"][hit, j], ref[hit, j], 2)
        assert D < crit, (j, D, crit)


def test02_first_hits_converge_to_a_dense_joint_sample(device, flight_prg):
    """Global memory against one dense joint Gaussian sample along the ray (numpy
    Cholesky, 601 points): the two-sample KS distance passes at the default adaptive
    step and is larger for a coarse uniform step (correlation 0.5 between neighbours)."""
    n = 20_000
    dense = FS.dense_first_hits(SE, RAMP, (0, 0, 0), (1, 0, 0), 0.0, 6.0, 601, n,
                                np.random.default_rng(11))
    dense = np.where(np.isfinite(dense), dense, -1.0)
    D = {}
    for c in (0.5, 0.0):
        out = flights(device, flight_prg, SE, RAMP, n, memory="global", cap=64, c=c, seed=12)
        D[c], crit = ks_two_sample(out[:, 0], dense, 2)
    print(f"KS distance to the dense sample: uniform c=0.5 {D[0.5]:.4f}, adaptive "
          f"{D[0.0]:.4f} (critical {crit:.4f})")
    assert D[0.0] < crit
    assert D[0.5] > D[0.0]


def test03_rice_crossing_rate_along_continued_rays(device, flight_prg):
    """Mean 0, SE: a ray that goes straight on through every hit (a continuation from the
    vertex record, global memory) counts level-0 down-crossings: Rice's L / (2 pi l) per
    ray plus 1/4 from starting with f(0) >= 0 (f -> -f symmetry), at the default miss
    tolerance (its bias bound, 2 pi tol relative, is far below this test's resolution).
    test_fs_adaptive.py checks other levels and kernels."""
    L, n = 60.0, 1500
    kern = SquaredExponential(sigma=1.0, length_scale=1.0)
    out = flights(device, flight_prg, kern, Constant(0.0), n, memory="global", cap=64, t1=L,
                  seed=21, restarts=200)
    counts = out[:, 4]
    expect = FS.downcrossing_rate(kern, 0.0, (1, 0, 0)) * L + 0.25
    se = counts.std(ddof=1) / math.sqrt(n)
    print(f"crossings per ray {counts.mean():.3f} +- {se:.3f}, expected {expect:.3f}")
    assert abs(counts.mean() - expect) < z_threshold(1) * se
