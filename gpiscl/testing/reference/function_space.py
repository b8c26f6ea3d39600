"""numpy reference of the function-space sampler (fs_linalg.h, fs_sampling.h).

Same conventions as the device code (its header comments pin them): relative jitter
JITTER * K_ii on every observation, the truncated-normal start condition, the fixed step
of correlation c (the uniform baseline, and the length scale l_d of the adaptive rule),
and the adaptive step rule of fs_march.h (march_realization: applied to a given dense
realization, so that its misses can be counted). Used by the tests and tools; one ray at a
time with np.linalg.cholesky (and a dense joint sample along a ray as the ground truth).
root_point / root_search mirror the device's root search at a crossing (fs_root_point).
Not mirrored: the hit slope and memory models (tested on the device against Rice's
formula and dense joint samples, tests/test_fs_adaptive.py). normal_pdf is
the twin of fs_normal_pdf.h (the density of a hit's normal given the law the device drew it
from, tests/test_fs_nee.py).
"""
from __future__ import annotations

import math

import numpy as np

from ...host.gp.kernels import covariance_matrix
from ...host.layout import constants as C

JITTER = C.FS_JITTER
_SQRT2PI = math.sqrt(2.0 * math.pi)


# --- Gaussian conditioning --------------------------------------------------------------

def jittered(K):
    """K with the device's nugget: K_ii (1 + JITTER)."""
    K = np.array(K, dtype=np.float64)
    K[np.diag_indices_from(K)] *= 1.0 + JITTER
    return K


def conditional(K, mu, y, m):
    """Mean and covariance of rows m: given rows :m = y (jittered K, plain solves)."""
    K = jittered(K)
    Kcc, Kxc, Kxx = K[:m, :m], K[m:, :m], K[m:, m:]
    mean = mu[m:] + Kxc @ np.linalg.solve(Kcc, y - mu[:m]) if m else mu[m:].copy()
    cov = Kxx - Kxc @ np.linalg.solve(Kcc, Kxc.T) if m else Kxx
    return mean, cov


def observation_matrix(kernel, mean, x, u, deriv):
    """Joint covariance and prior means of value / directional-derivative observations."""
    x = np.asarray(x, float)
    u = np.where(np.asarray(deriv, bool)[:, None], np.asarray(u, float), np.nan)
    K = covariance_matrix(kernel, x, u1=u)
    v, g = mean.value_and_gradient(x)
    mu = np.where(deriv, np.sum(np.nan_to_num(u) * g, axis=-1), v)
    return K, mu


def stacked_observation_matrix(kernel, mean, X, deriv, d):
    """observation_matrix over a leading batch axis, with the device's jitter: K (b, n, n)
    and mu (b, n) of values (deriv False) and slopes along d (deriv True) at the points X
    (b, n, 3), from one kernel jet of every pair (tests/batched_march.py,
    tools/bench_function_space.py)."""
    d = np.asarray(d, float)
    deriv = np.asarray(deriv, bool)
    U = np.where(deriv[:, None], d, 0.0)
    j = kernel.jet(X[:, None, :, :] - X[:, :, None, :])
    ug1 = np.einsum("ik,bijk->bij", U, j.g)
    ug2 = np.einsum("jk,bijk->bij", U, j.g)
    dv = -np.einsum("ik,bijk->bij", U, j.G)
    vd = np.einsum("jk,bijk->bij", U, j.G)
    dd = -(j.alpha * ug1 * ug2 + np.einsum("ik,bijk,jk->bij", U, j.D, U))
    D1, D2 = deriv[:, None], deriv[None, :]
    K = np.where(D1, np.where(D2, dd, dv), np.where(D2, vd, j.k))
    n = len(deriv)
    K[:, np.arange(n), np.arange(n)] *= 1.0 + JITTER
    v, grad = mean.value_and_gradient(X)
    mu = np.where(deriv, np.sum(U * grad, axis=-1), v)
    return K, mu


# --- truncated normal -------------------------------------------------------------------

def mills_ratio(a):
    """Q(a) / phi(a), vectorised; a continued fraction beyond 5 where Q underflows."""
    a = np.asarray(a, dtype=np.float64)
    small = np.minimum(a, 5.0)
    erfc = np.vectorize(math.erfc, otypes=[np.float64])
    direct = 0.5 * erfc(small / math.sqrt(2.0)) * _SQRT2PI * np.exp(0.5 * small * small)
    big = np.maximum(a, 5.0)
    r = big.copy()
    for k in range(200, 0, -1):
        r = big + k / r
    return np.where(a < 5.0, direct, 1.0 / r)


def truncnorm_moments(mu, s):
    """Mean and variance of N(mu, s^2) conditioned on x >= 0."""
    a = -mu / s
    lam = 1.0 / float(mills_ratio(a))
    return mu + s * lam, s * s * (1.0 + a * lam - lam * lam)


def truncnorm_survival(x, mu, s):
    """P(X > x) for X ~ N(mu, s^2) | X >= 0 and x >= 0, without underflow."""
    a, z = -mu / s, (np.asarray(x, np.float64) - mu) / s
    return np.exp(-0.5 * (z - a) * (z + a)) * mills_ratio(z) / mills_ratio(a)


def truncnorm_sample(mu, s, u):
    """Inverse-CDF draw for uniforms u (vectorised; a > 30 uses the asymptotic tail)."""
    a = -mu / s
    out = []
    for ui in np.ravel(u):
        if a > 30.0:
            z = math.sqrt(a * a - 2.0 * math.log1p(-ui))   # Rayleigh: ~1/a^2 off, host only
        elif a < 0.0:
            z = -_qinv(_q(-a) + ui * _q(a))
        else:
            z = _qinv(_q(a) * (1.0 - ui))
        out.append(max(mu + s * max(z, a), 0.0))
    return np.array(out)


def _q(x):
    return 0.5 * math.erfc(x / math.sqrt(2.0))


def _qinv(q):
    q = min(max(q, 1e-300), 1.0 - 2.2e-16)
    p = min(q, 1.0 - q)
    t = math.sqrt(-2.0 * math.log(p))
    x = t - (2.515517 + t * (0.802853 + t * 0.010328)) / (
        1.0 + t * (1.432788 + t * (0.189269 + t * 0.001308)))
    x = -x if q > 0.5 else x
    for _ in range(3):
        u = (_q(x) - q) * _SQRT2PI * math.exp(0.5 * x * x)
        x += u / (1.0 - 0.5 * x * u)
    return x


# --- fixed step -------------------------------------------------------------------------

def correlation(kernel, d, t):
    return float(kernel.value(t * np.asarray(d, float)) / kernel.value(np.zeros(3)))


def step_size(kernel, d, c):
    """The lag dt with corr(f(x), f(x + dt d)) = c."""
    d = np.asarray(d, float)
    dad = float(np.sum(np.asarray(kernel.aniso, float) * d * d))
    if kernel.kind == "squared_exponential":
        return kernel.length_scale * math.sqrt(-2.0 * math.log(c) / dad)
    if kernel.kind == "rational_quadratic":
        a = kernel.alpha
        return kernel.length_scale * math.sqrt(2.0 * a * (c ** (-1.0 / a) - 1.0) / dad)
    lam = float(kernel.cov_dd(np.zeros(3), d, np.zeros(3), d)) / kernel.variance
    lo, hi = 0.0, math.sqrt(2.0 * (1.0 - c) / lam)
    for _ in range(40):
        if correlation(kernel, d, hi) <= c:
            break
        lo, hi = hi, 2.0 * hi
    else:
        return math.sqrt(2.0 * (1.0 - c) / lam)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if correlation(kernel, d, mid) > c else (lo, mid)
    return 0.5 * (lo + hi)


# --- the adaptive march (fs_march.h) ----------------------------------------------------

H_MAX, H_MIN, ELL_CORR, WINDOW = C.FS_H_MAX, C.FS_H_MIN, C.FS_ELL_CORR, C.FS_WINDOW
RULE_SAMPLES = C.FS_RULE_SAMPLES   # the step rule conditions on the last 4-8 samples
# the step rule's quadrature on [0, 1]: the free nodes of a three-point Gauss-Radau rule
# with its fixed node at the step's start, the one nearer the end first (a try may stop
# there: a rate grows toward the end, where f is least pinned)
RULE = C.FS_RULE
# the root search (fs_root_point)
ROOT_WIDTH, ROOT_OFFSET, ROOT_SLACK = C.FS_ROOT_WIDTH, C.FS_ROOT_OFFSET, C.FS_ROOT_SLACK
root_budget = C.root_budget


def return_rate(m, m1, s, r, g, outside):
    """Rice's rate of crossings back across 0 from the side `outside` says (up-crossings
    when outside) of a Gaussian process with, at one point, E f = m, E f' = m1,
    sd f = s, cov(f, f') = r s and sd(f' | f) = g (fs_return_rate)."""
    if not outside:
        m, m1 = -m, -m1
    if not (s > 0.0 and g > 0.0):
        return 0.0
    a = (m1 - r / s * m) / g
    e = (math.exp(-0.5 * a * a) / _SQRT2PI / (a * a) * (1 - 3 / (a * a)) if a < -8.0
         else math.exp(-0.5 * a * a) / _SQRT2PI + a * _q(-a))   # Phi(a) = Q(-a): no cancellation for a < 0, as fs_return_rate
    return math.exp(-0.5 * (m / s) ** 2) / _SQRT2PI / s * g * e


def _moments(kernel, mean, x_rows, y_rows, x, d):
    """(m, m1, s, r, g) of f and its slope along d at x given values y at x_rows."""
    n = len(x_rows)
    K, mu = observation_matrix(kernel, mean, list(x_rows) + [x, x], [d] * (n + 2),
                               [False] * (n + 1) + [True])
    L = np.linalg.cholesky(jittered(K))
    e = np.linalg.solve(L[:n, :n], np.asarray(y_rows) - mu[:n])
    return (mu[n] + L[n, :n] @ e, mu[n + 1] + L[n + 1, :n] @ e, L[n, n], L[n + 1, n],
            L[n + 1, n + 1])


def march_steps(kernel, o, d, ts, F, tol):
    """The step rule of fs_march.h applied to one realization F sampled densely at the
    equally spaced ts along the unit ray o + t d (F[0] >= 0), as a generator: the march
    reads F where it samples (steps rounded down to the grid, at least one cell), yields
    (rows' points, rows' values, node) where the rule needs its moments given its last
    RULE_SAMPLES samples (the device's memory rows are absent here: the ray starts fresh
    at F[0]) and is sent (m, m1, s, r, g) back; it goes on through every crossing.
    Returns the sampled grid indices and the missed down-crossings: those of the dense
    path inside a step whose ends do not show them (the event the tolerance bounds), and
    the rate evaluations it made. march_realization answers one realization's questions;
    tests/batched_march.py answers many realizations' at once."""
    o, d = np.asarray(o, float), np.asarray(d, float)
    dt = ts[1] - ts[0]
    ell = step_size(kernel, d, ELL_CORR)
    down = (F[:-1] >= 0.0) & (F[1:] < 0.0)          # dense down-crossings per cell
    idx, i, h, grow, missed, first, evals = [0], 0, 0.5 * ell, 1.0, 0, 0, 0
    while i < len(ts) - 1:
        if len(idx) - first > 2 * RULE_SAMPLES:     # fs_rule_build: the last 4 again
            first = len(idx) - RULE_SAMPLES
        rows = idx[first:]
        xr, yr = o + ts[rows, None] * d, F[rows]
        outside = F[i] >= 0.0
        h = min(grow * h, H_MAX * ell)
        while True:
            k = max(1, min(int(h / dt), len(ts) - 1 - i))
            hs = k * dt
            ratio = 0.0
            for u, w in RULE:          # a try stops at the first node that rejects it
                moments = yield xr, yr, o + (ts[i] + u * hs) * d
                ratio += w * return_rate(*moments, outside) * ell / tol
                evals += 1
                if ratio > 1.0:
                    break
            if ratio <= 1.0 or h <= H_MIN * ell or k == 1:
                grow = 2.0 if ratio < 0.05 else (1.5 if ratio < 0.3 else 1.1)
                break
            h = 0.5 * hs
        missed += int(down[i:i + k].sum()) - int(F[i] >= 0.0 > F[i + k])
        i += k
        idx.append(i)
    return np.array(idx), missed, evals


def march_realization(kernel, mean, o, d, ts, F, tol):
    """march_steps for one realization, each rule evaluation's moments from _moments:
    (sampled grid indices, missed down-crossings, rate evaluations)."""
    d = np.asarray(d, float)
    steps = march_steps(kernel, o, d, ts, F, tol)
    try:
        xr, yr, node = next(steps)
        while True:
            xr, yr, node = steps.send(_moments(kernel, mean, xr, yr, node, d))
    except StopIteration as done:
        return done.value


def root_point(ta, tb, fa, fb, width, k, kmax):
    """The root search's point k in the bracket (ta, tb), f(ta) = fa >= 0 > fb = f(tb)
    (fs_root_point): regula falsi moved ROOT_OFFSET widths toward the midpoint, projected
    onto ITP's interval about the midpoint, from the values already drawn only."""
    w = tb - ta
    mid = ta + 0.5 * w
    xf = ta + w * (fa / (fa - fb))
    x = xf + math.copysign(min(ROOT_OFFSET * width, abs(mid - xf)), mid - xf)
    r = max(0.5 * width * (1.0 - 1e-12) * math.ldexp(1.0, kmax - k) - 0.5 * w, 0.0)
    return x if abs(x - mid) <= r else mid + math.copysign(r, x - mid)


def root_search(draw, ta, tb, fa, fb, width, refine=0):
    """fs_march.h's search for the crossing in (ta, tb]: draw(t) returns f(t) drawn given
    everything drawn before (the caller's conditioning); returns the final bracket
    (ta, tb, fa, fb) and the points drawn, in order."""
    kmax, k, points = root_budget(tb - ta, width), 0, []
    while k < refine or tb - ta > width:
        t = root_point(ta, tb, fa, fb, width, k, kmax)
        f = draw(t)
        points.append((t, f))
        ta, fa, tb, fb = (t, f, tb, fb) if f >= 0.0 else (ta, fa, t, f)
        k += 1
    return ta, tb, fa, fb, points


def conditional_draws(kernel, mean, o, d, ts, fs, rng):
    """draw(t) for root_search: f(o + t d) given the values fs at ts (both lists, which
    grow with every draw), from the exact jittered conditional (numpy Cholesky)."""
    o, d = np.asarray(o, float), np.asarray(d, float)

    def draw(t):
        x = [o + s * d for s in ts] + [o + t * d]
        K, mu = observation_matrix(kernel, mean, x, [d] * len(x), [False] * len(x))
        m, c = conditional(K, mu, np.asarray(fs), len(ts))
        f = float(m[0] + math.sqrt(max(c[0, 0], 0.0)) * rng.standard_normal())
        ts.append(t)
        fs.append(f)
        return f
    return draw


def _frame(n):
    sign = math.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    c = n[0] * n[1] * a
    return (np.array([1.0 + sign * n[0] * n[0] * a, sign * c, -sign * n[0]]),
            np.array([c, sign + n[1] * n[1] * a, -n[1]]))


def dense_first_hits(kernel, mean, o, d, t0, t1, n_points, n_samples, rng, chunk=4096,
                     slopes=False):
    """Ground truth: first f >= 0 -> f < 0 crossing of dense joint samples at n_points
    equally spaced parameters, given f(t0) >= 0 (rejection: exactly the start condition),
    linear interpolation within the cell; inf where there is none. slopes=True also
    returns the slope per unit t there (the cell's difference quotient; nan if none)."""
    o, d = np.asarray(o, float), np.asarray(d, float)
    ts = np.linspace(t0, t1, n_points)
    x = o + ts[:, None] * d
    K = jittered(covariance_matrix(kernel, x))
    L = np.linalg.cholesky(K).astype(np.float32)
    mu = mean.value(x)[:, None]
    out, out_s = [], []
    dt = ts[1] - ts[0]
    while sum(len(h) for h in out) < n_samples:
        Z = rng.standard_normal((n_points, chunk), dtype=np.float32)
        # f(t0) = mu + L[0, 0] z_0 (L is lower triangular): the start condition decides
        # before the product, which then takes the accepted columns only (half at mu = 0)
        F = mu + L @ Z[:, mu[0] + L[0, 0] * Z[0] >= 0.0]
        neg = F < 0.0
        first = np.where(neg.any(axis=0), neg.argmax(axis=0), -1)
        cols = np.arange(F.shape[1])
        j = np.maximum(first, 1)
        fa, fb = F[j - 1, cols], F[j, cols]
        th = ts[j - 1] + dt * fa / (fa - fb)
        out.append(np.where(first > 0, th, np.inf))
        out_s.append(np.where(first > 0, (fb - fa) / dt, np.nan))
    if slopes:
        return np.concatenate(out)[:n_samples], np.concatenate(out_s)[:n_samples]
    return np.concatenate(out)[:n_samples]


def downcrossing_rate(kernel, level, d):
    """Rice: expected f >= level -> f < level crossings per unit ray parameter."""
    var = kernel.variance
    d = np.asarray(d, float)
    lam2 = float(kernel.cov_dd(np.zeros(3), d, np.zeros(3), d))
    return math.exp(-level * level / (2.0 * var)) * math.sqrt(lam2 / var) / (2.0 * math.pi)


# --- the normal's density at a hit (fs_normal_pdf.h) -------------------------------------

def _dot(u, v):
    """Dot products over the last axis, broadcasting the others."""
    return np.einsum("...k,...k->...", u, v)


def normal_pdf(n, d, law, jacobian=True):
    """numpy twin of fs_normal_pdf: the density per steradian of the unit normal n (..., 3)
    at a hit of a ray along unit d, for the law (m, a, b, s) of FsResult.law_* (arrays
    that broadcast against n): p = N2(q(n); m_q, S_q) s^2 / |n.d|^3, 0 where n.d >= 0.
    jacobian=False drops s^2 / |n.d|^3 (the tests' counterexample)."""
    m, a, b, s = law
    c = n @ d
    lam = s / c
    # q . a for q = lam (n - c d) - m as lam (n.a - c d.a) - m.a: no (..., 3) temporaries
    # per (law, point) pair (2.5-3x faster on test_fs_nee's grids; the same to 2e-12)
    z1 = lam * (_dot(n, a) - c * (a @ d)) - _dot(m, a)
    z2 = lam * (_dot(n, b) - c * (b @ d)) - _dot(m, b)
    inv_det = np.linalg.norm(np.cross(a, b), axis=-1)   # 1 / sqrt(det S_q)
    p = np.exp(-0.5 * (z1**2 + z2**2)) * inv_det / (2 * np.pi)
    if jacobian:
        p = p * s**2 / np.abs(c)**3
    return np.where(c < 0, p, 0.0)
