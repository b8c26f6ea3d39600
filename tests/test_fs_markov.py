"""The Markov (state-space) free flight of fs_markov.h for Matern 3/2 and 5/2: its
transition against the kernel's derivative covariances, state paths and bridge draws
against exact Gaussian laws, first passage against a dense joint sample and the general
sampler, Rice's crossing rate, white furnaces, and renders against the general sampler."""
import copy
import math
import re

from decimal import Decimal, getcontext
from pathlib import Path
import numpy as np
import pytest
from scipy import stats as sst

from gpiscl.host.gp import Constant, Matern32, Matern52
from gpiscl.testing.reference import function_space as FS
from gpiscl.host.gp.kernels import covariance_matrix
from markov_wrappers import bridge, flights, paths, rule_ratios, transition
from gpiscl.testing.stats import assert_agree, ks_two_sample, z_threshold
from gpiscl.testing.oracles import M32, M52
from crossing_oracle import expected_crossings

getcontext().prec = 40


class M:
    """A small dense matrix of 40-digit Decimals (the reference cancels ~h^(2p+1): float64
    cannot hold Q at 1e-3 l_d): product, transpose, inverse (Gauss-Jordan)."""

    def __init__(self, rows):
        self.a = [[Decimal(v) for v in r] for r in rows]

    def __getitem__(self, ij):
        return self.a[ij[0]][ij[1]]

    @property
    def n(self):
        return len(self.a)

    @property
    def T(self):
        return M([[self.a[j][i] for j in range(len(self.a))] for i in range(len(self.a[0]))])

    def __mul__(self, o):
        return M([[sum(self.a[i][k] * o.a[k][j] for k in range(len(o.a)))
                   for j in range(len(o.a[0]))] for i in range(len(self.a))])

    def __sub__(self, o):
        return M([[x - y for x, y in zip(r, q)] for r, q in zip(self.a, o.a)])

    def inv(self):
        n = self.n
        a = [r[:] + [Decimal(int(i == j)) for j in range(n)] for i, r in enumerate(self.a)]
        for c in range(n):
            p = max(range(c, n), key=lambda r: abs(a[r][c]))
            a[c], a[p] = a[p], a[c]
            piv = a[c][c]
            a[c] = [v / piv for v in a[c]]
            for r in range(n):
                if r != c and a[r][c] != 0:
                    f = a[r][c]
                    a[r] = [x - f * y for x, y in zip(a[r], a[c])]
        return M([r[n:] for r in a])
# sigma, l, aniso exact in float32 (GpKernel packs them so)
KERNELS = {"m32": Matern32(sigma=0.75, length_scale=0.5),
           "m52": Matern52(sigma=0.75, length_scale=0.5),
           "m52_aniso": Matern52(sigma=1.25, length_scale=2.0, aniso=(1.0, 0.5, 2.0))}
DIRS = {"m32": (1.0, 0.0, 0.0), "m52": (1.0, 0.0, 0.0),
        "m52_aniso": (0.6, 0.0, 0.8)}


def lam(kernel, d):
    c = math.sqrt(3.0 if kernel.kind == "matern32" else 5.0) / kernel.length_scale
    return c * math.sqrt(float(np.dot(np.asarray(kernel.aniso) * d, d)))


def k1_derivs(kernel, d, tau, order):
    """k1^(n)(tau), n = 0..order, of the kernel along unit d (tau >= 0), 40 digits: k1 =
    sigma^2 e^(-lambda tau) P(tau); each derivative maps P to P' - lambda P."""
    L, s2, tau = Decimal(lam(kernel, d)), Decimal(kernel.sigma) ** 2, Decimal(tau)
    P = [s2, s2 * L] + ([s2 * L * L / 3] if kernel.kind == "matern52" else [])
    out = []
    for _ in range(order + 1):
        out.append((-L * tau).exp() * sum(c * (tau ** k if k else 1) for k, c in enumerate(P)))
        dP = [(k + 1) * P[k + 1] for k in range(len(P) - 1)] + [Decimal(0)]
        P = [dP[k] - L * P[k] for k in range(len(P))]
    return out


def cross_cov(kernel, d, tau):
    """C_ij = cov(Y^(i)(0), Y^(j)(tau)) = (-1)^i k1^(i+j)(tau) (n x n, 40 digits)."""
    n = 2 if kernel.kind == "matern32" else 3
    k = k1_derivs(kernel, d, tau, 2 * n - 2)
    return M([[(-1) ** i * k[i + j] for j in range(n)] for i in range(n)])


def exact_transition(kernel, d, h):
    """A = C' P^-1, Q = P - C' P^-1 C from the stationary joint law of two states."""
    P, C = cross_cov(kernel, d, 0), cross_cov(kernel, d, h)
    A = C.T * P.inv()
    return A, P - A * C


def scaled_error(dev, ref, n):
    """max |dev - ref| / sqrt(|ref_ii ref_jj|) over the n x n block"""
    return max(abs(Decimal(dev[i, j]) - ref[i, j]) / abs(ref[i, i] * ref[j, j]).sqrt()
               for i in range(n) for j in range(n))


@pytest.mark.parametrize("name", list(KERNELS))
def test01_transition_is_the_kernels_joint_law(device, name):
    """The 1-D reference k1 is the kernel as implemented along d (value, slope, curvature
    covariances to 1e-12); A(h) and Q(h) on the device match the conditional law of the
    state at lag h given the state at 0, built from k1's derivatives in 40-digit
    arithmetic, to 1e-10 in the scaled norm |e_ij| / sqrt(ref_ii ref_jj) (A scaled by
    lambda^(i - j)), from 1e-3 l_d (where P_inf - A P_inf A' cancels) to 4 l_d."""
    kern, d = KERNELS[name], np.asarray(DIRS[name])
    n = 2 if kern.kind == "matern32" else 3
    L = lam(kern, d)
    for tau in (0.05, 0.4, 1.3):
        k = [float(v) for v in k1_derivs(kern, d, tau, 2)]
        x = tau * d
        assert abs(kern.value(x[None])[0] - k[0]) < 1e-12
        assert abs(kern.cov_vd(np.zeros(3), x[None], d)[0] - k[1]) < 1e-12
        assert abs(kern.cov_dd(np.zeros(3), d, x[None], d)[0] + k[2]) < 1e-12
    # fs_march.h's length scale l_d (the lag of correlation e^-1/2) as fs_markov.h's
    # FS_MK_ELL32/52 give it: lambda l_d
    text = (Path(__file__).resolve().parent.parent / "gpiscl" / "kernels_cl" / "lib"
            / "fs_markov.h").read_text()
    ell = float(re.search(r"#define FS_MK_ELL%s ([0-9.]+)" % kern.kind[-2:], text).group(1))
    assert abs(kern.value((ell / L * d)[None])[0] / kern.sigma ** 2 - math.exp(-0.5)) < 1e-14
    for lh in (1e-3, 1e-2, 0.3, 1.0, 4.0):
        h = lh / L
        A, Q = transition(device, kern, h, d)
        Ar, Qr = exact_transition(kern, d, h)
        D = np.array([L ** i for i in range(n)])
        a_err = max(abs(A[i, j] * D[j] / D[i] - float(Ar[i, j]) * D[j] / D[i])
                    for i in range(n) for j in range(n))
        q_err = float(scaled_error(Q, Qr, n))
        assert a_err < 1e-10 and q_err < 1e-10, (name, lh, a_err, q_err)


def joint_value_slope_cov(kernel, d, us):
    """Covariance of (f(u_k), f'(u_k))_k along d from the kernel's covariance_matrix."""
    X = np.repeat(np.asarray(us)[:, None] * d, 2, axis=0)
    U = np.tile(np.vstack([np.full(3, np.nan), d]), (len(us), 1))
    return covariance_matrix(kernel, X, None, U, None)


@pytest.mark.parametrize("name", list(KERNELS))
def test02_state_paths_have_the_dense_joint_law(device, name):
    """Stationary state paths at unequal lags (steps 0.004 l to 1.5 l) whitened by the
    dense joint covariance of values and slopes (numpy Cholesky of the kernel's
    covariance_matrix) are standard normal: the squared norm is chi-square with 2 x 8
    degrees of freedom (one-sample KS) and each whitened component has mean 0 and
    variance 1 (z-tests, Bonferroni)."""
    kern, d = KERNELS[name], np.asarray(DIRS[name])
    l_d = 1.0 / lam(kern, d)
    us = l_d * np.array([0.0, 0.004, 0.3, 0.35, 1.0, 2.5, 2.6, 4.1])
    n = 40000
    X = paths(device, kern, us, n, seed=3, direction=d)[:, :, :2].reshape(n, -1)
    W = np.linalg.solve(np.linalg.cholesky(joint_value_slope_cov(kern, d, us)), X.T).T
    k = W.shape[1]
    D = sst.kstest((W ** 2).sum(axis=1), sst.chi2(k).cdf).statistic
    crit = math.sqrt(-math.log(1e-3 / 6 / 2) / 2) / math.sqrt(n)
    z = z_threshold(2 * k * 3)
    se_var = math.sqrt(2.0 / n)
    print(f"{name}: KS {D:.4f} (critical {crit:.4f}), max |mean| z "
          f"{np.abs(W.mean(0)).max() * math.sqrt(n):.2f}, max |var - 1| z "
          f"{np.abs(W.var(0) - 1).max() / se_var:.2f}")
    assert D < crit
    assert np.abs(W.mean(0)).max() * math.sqrt(n) < z
    assert np.abs(W.var(0) - 1).max() < z * se_var


def exact_bridge(kern, d, h1, h2, xa, xb, y0):
    """The state at h1 given xa at 0 and xb at h1 + h2 (mean, covariance), and the slope's
    mean and sd given also Y = y0 there, from the joint law of three states (40 digits)."""
    n = len(xa)
    P, C1, C2, C12 = (cross_cov(kern, d, t) for t in (0, h1, h2, h1 + h2))
    z = Decimal(0)
    S_me = [[z] * (2 * n) for _ in range(n)]
    S_ee = [[z] * (2 * n) for _ in range(2 * n)]
    for i in range(n):
        for j in range(n):
            S_me[i][j] = C1[j, i]          # cov(x_m, x_a) = C(h1)'
            S_me[i][n + j] = C2[i, j]      # cov(x_m, x_b) = C(h2)
            S_ee[i][j] = S_ee[n + i][n + j] = P[i, j]
            S_ee[i][n + j] = C12[i, j]
            S_ee[n + i][j] = C12[j, i]
    S_me, S_ee = M(S_me), M(S_ee)
    K = S_me * S_ee.inv()
    mean = K * M([[Decimal(v)] for v in list(xa) + list(xb)])
    mean = [mean[i, 0] for i in range(n)]
    cov = P - K * S_me.T
    slope_mean = mean[1] + cov[1, 0] / cov[0, 0] * (Decimal(y0) - mean[0])
    slope_var = cov[1, 1] - cov[1, 0] ** 2 / cov[0, 0]
    return (np.array([float(v) for v in mean]),
            np.array([[float(cov[i, j]) for j in range(n)] for i in range(n)]),
            float(slope_mean), float(slope_var.sqrt()))


@pytest.mark.parametrize("name", list(KERNELS))
@pytest.mark.parametrize("widths", [(0.3, 0.5), (0.004, 0.006)])
def test03_bridge_draws_follow_the_exact_conditional(device, name, widths):
    """Midpoint states drawn given both end states (a wide and a root-width bracket, in
    l_d) whitened by the exact conditional (40-digit joint law of three states) are
    chi-square (KS) with unbiased components; the slope's conditional mean and sd given
    Y = y0 at the point, used for the hit's slope, agree to 1e-7 relative."""
    kern, d = KERNELS[name], np.asarray(DIRS[name])
    l_d = 1.0 / lam(kern, d)
    n_state = 2 if kern.kind == "matern32" else 3
    h1, h2 = widths[0] * l_d, widths[1] * l_d
    s = kern.sigma
    xa = (0.4 * s, -0.9 * s / l_d, 0.3 * s / l_d ** 2)[:n_state]
    xb = (-0.2 * s, -1.1 * s / l_d, -0.5 * s / l_d ** 2)[:n_state]
    if widths[0] < 0.1:   # a root-width bracket: ends near a smooth path's values
        xb = (xa[0] + xa[1] * (h1 + h2), xa[1] - 0.01 * s / l_d,
              xa[2] if n_state == 3 else 0.0)[:n_state]
    y0 = 0.5 * (xa[0] + xb[0])
    n = 40000
    X, (dev_m, dev_sd) = bridge(device, kern, h1, h2, xa, xb, y0, n, seed=5, direction=d)
    mean, cov, sm, ssd = exact_bridge(kern, d, h1, h2, xa, xb, y0)
    W = np.linalg.solve(np.linalg.cholesky(cov), (X[:, :n_state] - mean).T).T
    D = sst.kstest((W ** 2).sum(axis=1), sst.chi2(n_state).cdf).statistic
    crit = math.sqrt(-math.log(1e-3 / 12 / 2) / 2) / math.sqrt(n)
    z = z_threshold(12 * n_state)
    print(f"{name} {widths}: KS {D:.4f} (critical {crit:.4f}); slope mean {dev_m:.6g} vs "
          f"{sm:.6g}, sd {dev_sd:.6g} vs {ssd:.6g}")
    assert D < crit
    assert np.abs(W.mean(0)).max() * math.sqrt(n) < z
    assert abs(dev_m - sm) < 1e-7 * (abs(sm) + ssd) and abs(dev_sd - ssd) < 1e-7 * ssd


def test03b_rule_ratio_makes_the_exact_rates_decisions(device):
    """fs_mk_rule_ratio (the rate bracketed by normal-tail bounds, erfc only where the
    threshold falls inside the bracket) puts every ratio on the same side of the step
    rule's threshold (accept <= 1; the step predictor reads the ratio, within the
    bracket's 15%, for the step sequence only) as scale * fs_return_rate, over random
    moments spanning deep tails, a < -8 (fs_return_rate's asymptotic), both sides and
    degenerate ones, at random scales and at scales (up to 1e8) that put the exact ratio
    within 1e-6..3e-2 relative of it; and it settles most of them without the exact rate
    (the bracket is used)."""
    rng = np.random.default_rng(11)
    n = 200000
    s = 10.0 ** rng.uniform(-4, 1, n)
    g = 10.0 ** rng.uniform(-3, 2, n)
    mom = np.column_stack([s * rng.uniform(-1, 9, n), g * rng.normal(0, 12, n), s,
                           s * rng.uniform(-1, 1, n) * 0.99, g])
    mom[:100, 2] = 0.0          # degenerate: rate 0
    side = rng.integers(0, 2, n)
    out = rule_ratios(device, mom, side, 10.0 ** rng.uniform(-2, 8))
    # scales the rule can meet (0.75 l_d / tol, tol >= 1e-8: rates below ~1e-8 are
    # float denormals in both, decided by neither's rounding)
    rate = rule_ratios(device, mom, side, 1.0)[:, 1]
    ok = (rate > 1e-8) & (rate < 1e2)
    th = 1.0
    rel = rng.choice([-1.0, 1.0], n) * 10.0 ** rng.uniform(-6, -1.5, n)
    near = rule_ratios(device, mom[ok], side[ok], (th * (1.0 + rel) / np.where(ok, rate, 1.0))[ok])
    for o in (out, near):
        assert np.array_equal(o[:, 0] <= 1.0, o[:, 1] <= 1.0)
    settled = np.mean(out[:, 0] != out[:, 1])
    print(f"settled by the bracket: {settled:.1%} (near a threshold: "
          f"{np.mean(near[:, 0] != near[:, 1]):.1%})")
    assert settled > 0.5


# rule evaluations + steps (GP samples) per 40 l ray, m32 / m52, mean 0. With the one-node
# rule the fixed growth (2, 1.5, 1.1 after ratios below 0.05, 0.3, 1; halving after a
# rejection) took 820 / 269 (1.95 / 1.49 evaluations a sample) and the predictor 602 / 213
# (1.39 / 1.07). The two-node rule evaluates both nodes on every accepted try (>= 2 a step):
# the predictor takes 1026 / 361 (2.38 / 2.02); the bounds are those plus ~7%, so a predictor
# that overshoots as the fixed growth did (~2 tries a step: >= 3 evaluations) fails them.
WORK_BOUND = {"m32": (1100.0, 2.55), "m52": (385.0, 2.15)}


@pytest.mark.parametrize("name", ["m32", "m52"])
def test03c_step_predictor_cuts_the_rule_evaluations(device, name):
    """fs_mk_predict aims each try at a ratio of 2^FS_MK_TARGET from the last try's X and
    the state's value and slope, where the fixed growth factors overshot after every
    halving (about two tries a step). Counts, not times: rays of 40 l through Matern
    (l = 1, mean 0) continued through every hit with renewal_plus, evaluations per sample
    and evaluations plus samples per ray below WORK_BOUND. The laws do not depend on it: a step is accepted only at ratio <= 1
    (test05 and the others check the laws with the predictor in place)."""
    kern = {"m32": Matern32(1.0, 1.0), "m52": Matern52(1.0, 1.0)}[name]
    out = flights(device, kern, Constant(0.0), 512, markov=True, memory="renewal_plus",
                  refine=0, t1=40.0, seed=5, restarts=1 << 20)
    assert np.all(out[:, 5] == 0)
    samples, evals = out[:, 6].mean(), out[:, 7].mean()
    print(f"{name}: per ray {samples:.1f} samples, {evals:.1f} evaluations "
          f"({evals / samples:.2f} a sample), {out[:, 4].mean():.2f} hits")
    work, per_sample = WORK_BOUND[name]
    assert evals + samples < work and evals / samples < per_sample


@pytest.mark.parametrize("name", ["m32", "m52"])
def test04_first_passage_matches_dense_and_general_samplers(device, name):
    """First hits of fresh rays (mean 0.5 sigma, length 8 l): Markov against one dense
    joint sample (numpy Cholesky, spacing l / 100) and against the general conditional
    sampler (fs_march.h) with the same kernel and tolerance: two-sample KS, Bonferroni."""
    kern = {"m32": Matern32(1.0, 0.5), "m52": Matern52(1.0, 0.5)}[name]
    mean, n, L = Constant(0.5), 12000, 4.0
    dense = FS.dense_first_hits(kern, mean, (0, 0, 0), (1, 0, 0), 0.0, L, 801, n,
                                np.random.default_rng(7))
    dense = np.where(np.isfinite(dense), dense, -1.0)
    mk = flights(device, kern, mean, n, markov=True, t1=L, seed=8)
    gen = flights(device, kern, mean, n, markov=False, t1=L, seed=9)
    assert np.all(mk[:, 5] == 0) and np.all(gen[:, 5] == 0)
    Dd, crit = ks_two_sample(mk[:, 0], dense, 4)
    Dg, _ = ks_two_sample(mk[:, 0], gen[:, 0], 4)
    print(f"{name}: hit fraction Markov {np.mean(mk[:, 0] >= 0):.4f}, dense "
          f"{np.mean(dense >= 0):.4f}, general {np.mean(gen[:, 0] >= 0):.4f}; KS to dense "
          f"{Dd:.4f}, to general {Dg:.4f} (critical {crit:.4f}); samples per flight "
          f"Markov {mk[:, 6].mean():.2f}, general {gen[:, 6].mean():.2f}")
    assert Dd < crit and Dg < crit


LEVELS = (0.0, 1.0, 2.0)


@pytest.mark.parametrize("name", ["m32", "m52"])
def test05_rice_crossing_rate_with_renewal_plus(device, long_run, name):
    """Rays continued through every hit under renewal_plus count down-crossings of 0 over
    L; the mean agrees with the exact expectation (Rice's rate plus the start condition,
    oracles.expected_crossings) at mu / sigma = 0, 1, 2 (z-test, Bonferroni).
    renewal_plus is the exact state for 3/2; for 5/2 f'' is redrawn from its stationary
    law given (f, f'), which is its Palm law at a crossing, so the chain of crossing states
    stays stationary and the expected count is still exact. At mu = 0 the slopes at
    crossings after the first follow Rice's Palm law, E[-s] = sqrt(pi / 2), E[s^2] = 2
    (lambda2 = 1), on rays long enough (400 l_d) for the start's transient to vanish."""
    kern = {"m32": M32, "m52": M52}[name]
    n, L = (20000, 100.0) if long_run else (3000, 40.0)
    z = z_threshold(2 * len(LEVELS) + 4)
    for mu in LEVELS:
        out = flights(device, kern, Constant(mu), n, markov=True, memory="renewal_plus",
                      t1=L, seed=17, restarts=100000)
        assert np.all(out[:, 5] == 0)
        cnt = out[:, 4]
        expect = expected_crossings(name, mu, L)
        se = cnt.std(ddof=1) / math.sqrt(n)
        print(f"{name} mu {mu}: {cnt.mean():.4f} +- {se:.4f} vs {expect:.4f} "
              f"({cnt.mean() / expect - 1:+.3%}); samples per length "
              f"{out[:, 6].sum() / (n * L):.2f}, evaluations {out[:, 7].sum() / (n * L):.2f}")
        assert abs(cnt.mean() - expect) < z * se
    # the slope law far from the start (its transient: E[-s] -2.3% at L = 25, -0.6% at
    # 100, +0.06 +- 0.14% at 400, measured; the general sampler's is the same)
    n, L = (10000, 400.0) if long_run else (1500, 400.0)
    out = flights(device, kern, Constant(0.0), n, markov=True, memory="renewal_plus", t1=L,
                  seed=19, restarts=100000)
    M = (out[:, 4] - 1).clip(0)
    for j, sign, ex in ((8, -1.0, math.sqrt(math.pi / 2)), (9, 1.0, 2.0)):
        S = sign * out[:, j]
        est = S.sum() / M.sum()
        se_r = (S - est * M).std(ddof=1) / (math.sqrt(n) * M.mean())
        print(f"  slope moment {j - 7}: {est:.4f} +- {se_r:.4f} (expect {ex:.4f})")
        assert abs(est - ex) < z * se_r


# The renders: test_fs_render's rough ball with a Matern kernel
def matern_scene(kernel, memory, bsdf, spp, seed=3, lights=None):
    from gpiscl.testing.scenes import function_space_sampler, gpis_scene
    scene = gpis_scene(function_space_sampler(memory), bsdf, 1.0 if bsdf == "mirror" else 0.9,
                       lights or [{"type": "environment", "radiance": 1.0}], spp, seed=seed)
    scene["shapes"][0]["kernel"] = {"type": kernel, "sigma": 0.3, "length_scale": 0.25}
    return scene


def render_compiled(device, scene, general):
    """Render `scene`; general = 1 keeps every function-space object on the general
    sampler (GpisObject.general, set on the compiled objects only)."""
    from gpiscl.host.compile.scene import compile_scene
    from gpiscl.host.layout import records as layouts
    from gpiscl.host.render.integrator import WavefrontIntegrator
    from gpiscl.host.scene.loading import load_scene
    data = load_scene(copy.deepcopy(scene)).data
    compiled = compile_scene(data)
    objs = compiled.gpis.objects
    objs["general"][objs["sampler"] == layouts.GPIS_SAMPLERS["function_space"]] = general
    res = WavefrontIntegrator(device, compiled, data["render"], None).render(
        data["render"]["spp"])
    st = res.stats
    assert st.nan_paths == 0 and st.gpis_failed == 0 and st.killed_paths == 0, st.summary()
    return res


@pytest.mark.parametrize("kernel", ["matern32", "matern52"])
@pytest.mark.parametrize("memory", ["none", "renewal", "renewal_plus"])
def test06_mirror_furnace(device, kernel, memory):
    """Albedo-1 mirror in a unit environment: exactly 1 per path with the Markov sampler,
    no killed or failed path; the ball is hit (more rays than paths)."""
    res = render_compiled(device, matern_scene(kernel, memory, "mirror", 8), 0)
    assert res.stats.rays > 1.5 * res.stats.paths
    np.testing.assert_allclose(res.image.mean, 1.0, rtol=1e-6)


@pytest.mark.parametrize("kernel, memory", [("matern32", "renewal_plus"),
                                            ("matern52", "renewal")])
def test07_markov_and_general_samplers_render_alike(device, kernel, memory):
    """The same diffuse scene (directional and environment light, NEE: shadow rays take
    the same sampler) with the Markov and the general sampler: different images (the
    switch acts) that agree per 4 x 4 block (z-test, Bonferroni) and in the mean."""
    lights = [{"type": "directional", "direction": [-0.3, -1, -0.4], "irradiance": 3.0},
              {"type": "environment", "radiance": 0.3}]
    scene = matern_scene(kernel, memory, "diffuse", 64, seed=7, lights=lights)
    a = render_compiled(device, scene, 0).image
    b = render_compiled(device, scene, 1).image
    assert not np.array_equal(a.mean, b.mean)
    assert_agree(a.mean, a.stderr, b.mean, b.stderr, block=4, what="Markov vs general")
    # the image mean's standard error: channels averaged first (grey scene: the three
    # channels of a pixel are one sample, so treating them as independent would shrink
    # it by sqrt(3); stderr.mean over channels is exact for identical channels and an
    # upper bound otherwise)
    diff = a.mean.mean() - b.mean.mean()
    se = math.sqrt((a.stderr.mean(axis=-1) ** 2).sum()
                   + (b.stderr.mean(axis=-1) ** 2).sum()) / a.mean[..., 0].size
    print(f"{kernel} {memory}: image mean Markov {a.mean.mean():.4f}, general "
          f"{b.mean.mean():.4f} ({diff / b.mean.mean():+.2%} +- {se / b.mean.mean():.2%})")
    assert abs(diff) < z_threshold(1) * se


@pytest.mark.parametrize("name", ["m32", "m52_aniso"])
def test08_hit_gradients_match_the_general_sampler(device, name):
    """The gradient at the first hit (constant mean 0.5 sigma, a ray oblique to the
    anisotropy axes): Markov (tangential parts in the A-orthonormal frame, independent of
    the ray) against the general sampler (isotropic: the same closed form; anisotropic:
    two rows conditioned on everything): each component and the along-ray slope,
    two-sample KS, Bonferroni over 4 x 2."""
    kern, d = KERNELS[name], np.asarray(DIRS[name])
    l_d = 1.0 / lam(kern, d)
    n, mean = 12000, Constant(0.5 * kern.sigma)
    mk = flights(device, kern, mean, n, markov=True, d=d, t1=8 * l_d, seed=61)
    gen = flights(device, kern, mean, n, markov=False, d=d, t1=8 * l_d, seed=62)
    assert np.all(mk[:, 5] == 0) and np.all(gen[:, 5] == 0)
    a, b = mk[mk[:, 0] >= 0, 1:4], gen[gen[:, 0] >= 0, 1:4]
    for j, (x, y) in enumerate(zip([*a.T, a @ d], [*b.T, b @ d])):
        D, crit = ks_two_sample(x, y, 8)
        print(f"{name} component {j}: KS {D:.4f} (critical {crit:.4f}), mean {x.mean():+.4f} "
              f"vs {y.mean():+.4f}, sd {x.std():.4f} vs {y.std():.4f}")
        assert D < crit
