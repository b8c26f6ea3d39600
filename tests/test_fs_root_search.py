"""The root search at a crossing (fs_march.h, "Hit"; fs_root_point): the device's point
choice is the numpy twin's, its worst case is bisection's plus FS_ROOT_SLACK points on any
bracket, it takes about half of bisection's points on smooth paths, with it (at the
default refine 0, where the root width alone decides) the first hit and the slope drawn
there follow one dense joint sample along the ray, and on the device's own flights every
point is the twin's function of values drawn before it and every value is whitened
N(0, 1) by numpy's exact conditional (breaking checks: a choice that peeks at the value it
is about to draw fails test05; dropping the ITP projection fails test02)."""
import math

import numpy as np
import pyopencl as cl
import pytest

from gpiscl.host.gp import Constant, SquaredExponential
from gpiscl.testing.reference import function_space as FS
from gpiscl.host.layout import function_space_records as FL
from gpiscl.host.layout import gp_records
from gpiscl.host.render.program_sources import fs_sampler_options
from gpiscl.testing.stats import z_threshold
from gpiscl.testing.flights import flights
from gpiscl.testing.stats import ks_two_sample
from gpiscl.testing.wrappers import sampler_program

WRAPPER = r"""
/* per item: the point for bracket q[0..3] = (ta, tb, fa, fb), width q[4], index q[5],
 * and the budget of that bracket (its own kmax) */
__kernel void root_point(__global const double* q, __global double* out)
{
    int i = get_global_id(0);
    __global const double* b = q + 6 * i;
    int kmax = fs_root_budget(b[1] - b[0], b[4]);
    out[2 * i] = fs_root_point(b[0], b[1], b[2], b[3], b[4], (int)b[5], kmax);
    out[2 * i + 1] = kmax;
}

/* one fresh flight per item along o + t (1, 0, 0) (memory none, window 16, refine 0):
 * out = (hit, roots, rows kept, t and value of each kept row, up to ROWS_OUT) */
__kernel void flight_rows(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                          double t1, uint seed, __global double* scratch, __global double* out)
{
    int i = get_global_id(0);
    FsParams prm = {16, GPIS_MEMORY_NONE, 1, 0, 0.0, FS_DEFAULT_TOL};
    FsRay r = {(double3)(0.0), (double3)(1.0, 0.0, 0.0), 0.0, t1};
    FsRng rng = {seed, (uint)i, 0u, 0u, 0u};
    FsVertex v = {0};
    FsScratch S = fs_scratch(scratch, i);
    FsResult res = fs_free_flight(kp[0], mean, mc, prm, r, v, 0, rng, S);
    __global double* o = out + (3 + 2 * ROWS_OUT) * i;
    int n = res.hit && !res.status ? res.new_end - FS_HIT_ROWS : 0;
    o[0] = res.status ? -1.0 : res.hit;
    o[1] = res.roots;
    o[2] = min(n, ROWS_OUT);
    for (int k = 0; k < min(n, ROWS_OUT); ++k) {
        o[3 + 2 * k] = S.rows[k].px;
        o[4 + 2 * k] = S.rows[k].value;
    }
}
"""
ROWS_OUT = 40


def _program(ctx):
    opts = fs_sampler_options(16, 64) + [f"-DROWS_OUT={ROWS_OUT}",
                                         f"-DFS_DEFAULT_TOL={FL.DEFAULT_MISS_TOLERANCE!r}"]
    return sampler_program(ctx, WRAPPER, opts)


def random_brackets(rng, n):
    """Brackets of every shape: widths 1e-3..3, ends far from 0 (ray parameters up to
    100), values from 1e-12 to 1e3 on either side, k up to the budget and beyond."""
    ta = rng.uniform(0.0, 100.0, n)
    w = 10.0 ** rng.uniform(-3.0, 0.5, n)
    fa = 10.0 ** rng.uniform(-12.0, 3.0, n) * (rng.random(n) > 0.05)   # some exactly 0
    fb = -(10.0 ** rng.uniform(-12.0, 3.0, n))
    width = 10.0 ** rng.uniform(-3.0, -1.0, n)
    k = rng.integers(0, 14, n)
    return np.stack([ta, ta + w, fa, fb, width, k], axis=1)


def test01_device_point_choice_is_the_twins(device):
    """fs_root_point and fs_root_budget against root_point / root_budget on 20,000
    random brackets: the same budget, points equal to rounding (1e-13 of the bracket)."""
    q = random_brackets(np.random.default_rng(3), 20000)
    out = np.empty((len(q), 2))
    qb = cl.Buffer(device.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=q)
    ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    _program(device.ctx)["root_point"](device.queue, (len(q),), None, qb, ob)
    cl.enqueue_copy(device.queue, out, ob)
    budget = np.array([FS.root_budget(b[1] - b[0], b[4]) for b in q])
    np.testing.assert_array_equal(out[:, 1], budget)
    twin = np.array([FS.root_point(*b[:5], int(b[5]), int(m)) for b, m in zip(q, budget)])
    assert np.all((twin > q[:, 0]) & (twin < q[:, 1]))
    np.testing.assert_allclose(out[:, 0], twin, rtol=0, atol=1e-13 * 100.0)


# functions on which a secant point is useless or misleading: a jump, flat tails, an
# end-heavy power and a value that is tiny at one end
HARD = {"jump": lambda t, r: 1.0 if t < r else -1.0,
        "flat": lambda t, r: math.tanh(200.0 * (r - t)),
        "power": lambda t, r: (r - t) ** 9 if t < r else -((t - r) ** (1.0 / 9.0)),
        "tiny end": lambda t, r: 1e-300 if t < r else -1e3}


@pytest.mark.parametrize("name", list(HARD))
def test02_never_more_points_than_bisection_plus_the_slack(name):
    """On any bracket the search ends within root_budget points (bisection's count plus
    ROOT_SLACK), with a bracket below the width around the sign change; 400 roots
    spread over (0, 1) for each hard function."""
    f = HARD[name]
    width = FS.ROOT_WIDTH
    worst = 0
    for r in np.linspace(0.0, 1.0, 402)[1:-1]:
        ta, tb, fa, fb, pts = FS.root_search(lambda t: f(t, r), 0.0, 1.0, f(0.0, r), f(1.0, r),
                                             width)
        assert tb - ta <= width and fa >= 0.0 > fb and ta <= r <= tb, (name, r, ta, tb)
        worst = max(worst, len(pts))
    assert worst <= FS.root_budget(1.0, width) == math.ceil(math.log2(1 / width)) + FS.ROOT_SLACK


def test03_smooth_paths_take_about_half_of_bisections_points():
    """The point of the search: on conditional draws (SE, l = 1, brackets of 0.45 l
    after a step of 0.45 l, mu = 0) the mean number of points per hit is below 3.5
    where bisection needs 6 (numpy twin; 200 hits, the mean's standard error ~0.06)."""
    rng = np.random.default_rng(8)
    kern, mean, d = SquaredExponential(sigma=1.0, length_scale=1.0), Constant(0.0), (1, 0, 0)
    counts = []
    while len(counts) < 200:
        ts, fs = [], []
        draw = FS.conditional_draws(kern, mean, (0, 0, 0), d, ts, fs, rng)
        f0 = draw(0.0)
        if f0 < 0.0:
            continue
        f1 = draw(0.45)
        if f1 >= 0.0:
            continue
        ta, tb, fa, fb, pts = FS.root_search(draw, 0.0, 0.45, f0, f1, FS.ROOT_WIDTH)
        counts.append(len(pts))
    print(f"points per hit {np.mean(counts):.2f} (bisection 6)")
    assert np.mean(counts) < 3.5


@pytest.mark.parametrize("mu", [0.0, 1.5])
def test04_first_hit_and_its_slope_match_a_dense_joint_sample(device, flight_prg, mu):
    """At the default refine (0: the root width alone stops the search, so every point is
    the new choice's), first hits along a fresh ray (SE l = 0.5, 6 long, global memory)
    and the slope drawn there against one dense joint sample (numpy Cholesky, 1201
    points, spacing l / 100; its slope is the first crossing cell's difference quotient):
    two-sample KS on the hit distance, and on the slope of the rays that hit, Bonferroni
    over both levels and statistics. This law hardly depends on the point choice (every
    choice ends in a bracket of 0.01 l_d): a choice that peeks at the value about to be
    drawn passes here, and so does a root width of 0.3 l_d (measured); test05 is the one
    that fails when the choice is broken."""
    n = 15000
    kern = SquaredExponential(sigma=1.0, length_scale=0.5)
    seed = int(10 * mu) + 21
    th, sh = FS.dense_first_hits(kern, Constant(mu), (0, 0, 0), (1, 0, 0), 0.0, 6.0, 1201, n,
                                 np.random.default_rng(seed), slopes=True)
    th = np.where(np.isfinite(th), th, -1.0)
    out = flights(device, flight_prg, kern, Constant(mu), n, memory="global", refine=FL.DEFAULT_REFINE,
                  seed=seed + 1)
    hit = out[:, 0] >= 0
    D, crit = ks_two_sample(out[:, 0], th, 4)
    Ds, crit_s = ks_two_sample(out[hit, 1], sh[np.isfinite(sh)], 4)
    print(f"mu {mu}: hit fraction {hit.mean():.4f} vs {np.mean(th >= 0):.4f}, KS t {D:.4f} "
          f"(critical {crit:.4f}), KS slope {Ds:.4f} (critical {crit_s:.4f}), mean slope "
          f"{out[hit, 1].mean():.4f} vs {sh[np.isfinite(sh)].mean():.4f}, samples per ray "
          f"{out[:, 6].mean():.2f}")
    assert D < crit
    assert Ds < crit_s


def test05_each_point_is_chosen_from_values_drawn_before_it(device):
    """The exactness argument, checked on the device's own flights (SE l = 0.5, mean 0.5,
    memory none, 4000 rays): every root-search point equals the twin's root_point of the
    bracket and values drawn before it (so the choice never sees the value it is about to
    draw), and every value the search drew, whitened by numpy's exact conditional given
    the rows kept before it, is N(0, 1) (mean, variance and KS, Bonferroni over 3). With
    both, the values are the GP's at the chosen points, whatever the choice."""
    n, l = 4000, 0.5
    kern = SquaredExponential(sigma=1.0, length_scale=l)
    mean = Constant(0.5)
    nodes = gp_records.pack_mean(mean)
    mf = cl.mem_flags
    kp = cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR,
                   hostbuf=gp_records.pack_kernel(kern))
    mb = cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=nodes)
    scratch = cl.Buffer(device.ctx, mf.READ_WRITE, 8 * FL.scratch_doubles(FL.max_rows(16, 64)) * n)
    out = np.empty((n, 3 + 2 * ROWS_OUT))
    ob = cl.Buffer(device.ctx, mf.WRITE_ONLY, out.nbytes)
    _program(device.ctx)["flight_rows"](device.queue, (n,), None, kp, mb, np.int32(len(nodes)),
                                     np.float64(6.0), np.uint32(17), scratch, ob)
    cl.enqueue_copy(device.queue, out, ob)
    assert np.all(out[:, 0] >= 0)
    width = FS.ROOT_WIDTH * l
    z, points, checked = [], 0, 0
    for row in out[out[:, 0] == 1]:
        roots, m = int(row[1]), int(row[2])
        t, f = row[3:3 + 2 * m:2], row[4:4 + 2 * m:2]
        j = m - roots                       # the first search row; the bracket before it
        assert j >= 2 and f[j - 2] >= 0.0 > f[j - 1]   # roots 0: a step below the width
        ta, tb, fa, fb = t[j - 2], t[j - 1], f[j - 2], f[j - 1]
        kmax = FS.root_budget(tb - ta, width)
        for k in range(roots):
            expect = FS.root_point(ta, tb, fa, fb, width, k, kmax)
            assert abs(t[j + k] - expect) <= 1e-12 * (1.0 + abs(expect)), (k, t[j + k], expect)
            ta, fa, tb, fb = (t[j + k], f[j + k], tb, fb) if f[j + k] >= 0 else \
                (ta, fa, t[j + k], f[j + k])
        assert tb - ta <= width
        points += roots
        if checked < 1500:                  # whitening: numpy solves, a subset suffices
            checked += 1
            x = t[:, None] * np.array([1.0, 0.0, 0.0])
            K, mu = FS.observation_matrix(kern, mean, x, np.zeros_like(x), [False] * m)
            for k in range(roots):
                c = j + k
                cm, cv = FS.conditional(K[:c + 1, :c + 1], mu[:c + 1], f[:c], c)
                z.append((f[c] - cm[0]) / math.sqrt(cv[0, 0]))
    z = np.array(z)
    D = np.max(np.abs(np.arange(1, len(z) + 1) / len(z)
                      - 0.5 * (1 + np.vectorize(math.erf)(np.sort(z) / math.sqrt(2)))))
    crit = math.sqrt(-math.log(1e-3 / 3 / 2) / 2) / math.sqrt(len(z))
    zt = z_threshold(3)
    print(f"{points} points checked against the twin ({points / (out[:, 0] == 1).sum():.2f} "
          f"per hit); {len(z)} whitened: mean {z.mean():+.4f}, var {z.var():.4f}, KS {D:.4f} "
          f"(critical {crit:.4f})")
    assert abs(z.mean()) < zt / math.sqrt(len(z))
    assert abs(z.var() - 1.0) < zt * math.sqrt(2.0 / len(z))
    assert D < crit
