"""numpy reference of the function-space sampler (fs_linalg.h, fs_sampling.h).

Same conventions as the device code (its header comment pins them): relative jitter
JITTER * K_ii on every observation, the truncated-normal start condition, the step rule
corr = c, segments of N samples at t_s + (i + u) dt with the last squeezed onto t1,
bisection refinement of the crossing bracket, and the memory models none / renewal /
renewal_plus / global. Used by the tests and tools/bench_function_space.py; one ray at a
time with np.linalg.cholesky (and a dense joint sample along a ray as the ground truth).
Not mirrored: the device's global model draws all three gradient components at a hit
(the normal here conditions on f(x_h) = 0 and the secant slope); the two laws agree
(tests/test_fs_free_flight.py), only the global ring needs genuine draws.
"""
from __future__ import annotations

import math

import numpy as np

from .kernels import covariance_matrix

JITTER = 1e-10
MEMORIES = ("none", "renewal", "renewal_plus", "global")
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


# --- step rule and segment grid ---------------------------------------------------------

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


def segment_grid(t_start, t1, dtc, n_max, u):
    """Sample parameters of one segment (u in (0, 1]) and whether it is the last."""
    rem = t1 - t_start
    if (n_max - 1 + u) * dtc < rem:
        return t_start + (np.arange(n_max) + u) * dtc, False
    n = int(min(max(math.ceil(rem / dtc + 1.0 - u), 1), n_max))
    ts = t_start + (np.arange(n) + u) * (rem / (n - 1 + u))
    ts[-1] = t1
    return ts, True


# --- one ray ----------------------------------------------------------------------------

def free_flight(kernel, mean, o, d, t0, t1, rng, samples=32, memory="global",
                step_corr=0.9, refine=6, cap=64):
    """First crossing along a fresh ray (start condition f(t0) >= 0), or None.

    Returns (t_hit or None, gradient at the hit or None, number of segments)."""
    o, d = np.asarray(o, float), np.asarray(d, float)
    dn = d / np.linalg.norm(d)
    sd0 = math.sqrt(kernel.variance)
    v0 = truncnorm_sample(float(mean.value(o + t0 * d)), sd0, [rng.random()])[0]
    X, U, D, Y = [o + t0 * d], [dn], [False], [v0]     # conditioning rows
    t, t_prev, f_prev, outside = t0, t0, v0, True
    dtc = step_size(kernel, d, step_corr)
    for seg in range(1, 100000):
        if t >= t1:
            return None, None, seg - 1
        ts, last = segment_grid(t, t1, dtc, samples, 1.0 - rng.random())
        x = list(X) + [o + ti * d for ti in ts]
        u = list(U) + [dn] * len(ts)
        der = list(D) + [False] * len(ts)
        K, mu = observation_matrix(kernel, mean, x, u, der)
        m = len(X)
        mc, cov = conditional(K, mu, np.array(Y), m)
        F = mc + np.linalg.cholesky(cov) @ rng.standard_normal(len(ts))
        hit = None
        for i in range(len(ts)):
            if outside and F[i] < 0.0:
                hit = i
                break
            outside = F[i] >= 0.0
        if hit is not None:
            ta, fa = (t_prev, f_prev) if hit == 0 else (ts[hit - 1], F[hit - 1])
            tb, fb = ts[hit], F[hit]
            ox, ou, od = x[:m + hit + 1], u[:m + hit + 1], der[:m + hit + 1]
            oy = list(Y) + list(F[:hit + 1])
            for _ in range(refine):
                tm = 0.5 * (ta + tb)
                K, mu = observation_matrix(kernel, mean, ox + [o + tm * d], ou + [dn],
                                           od + [False])
                cm, cv = conditional(K, mu, np.array(oy), len(oy))
                fm = cm[0] + math.sqrt(max(cv[0, 0], 0.0)) * rng.standard_normal()
                ox, ou, od, oy = ox + [o + tm * d], ou + [dn], od + [False], oy + [fm]
                ta, fa, tb, fb = (tm, fm, tb, fb) if fm >= 0.0 else (ta, fa, tm, fm)
            th = ta + (tb - ta) * fa / (fa - fb)
            slope = (fb - fa) / ((tb - ta) * np.linalg.norm(d))
            xh = o + th * d
            T, B = _frame(dn)
            K, mu = observation_matrix(kernel, mean, ox + [xh] * 4, ou + [dn, dn, T, B],
                                       od + [False, True, True, True])
            cm, cv = conditional(K, mu, np.array(oy + [0.0, slope]), len(oy) + 2)
            q = cm + np.linalg.cholesky(cv) @ rng.standard_normal(2)
            return th, T * q[0] + B * q[1] + dn * slope, seg
        if last:
            return None, None, seg
        t = t_prev = ts[-1]
        f_prev, xe = F[-1], o + ts[-1] * d
        if memory == "global":
            X, U, D, Y = (x[-cap:], u[-cap:], der[-cap:], (list(Y) + list(F))[-cap:])
        elif memory == "renewal_plus":
            K, mu = observation_matrix(kernel, mean, x + [xe], u + [dn], der + [True])
            cm, cv = conditional(K, mu, np.array(list(Y) + list(F)), len(x))
            s = cm[0] + math.sqrt(max(cv[0, 0], 0.0)) * rng.standard_normal()
            X, U, D, Y = [xe, xe], [dn, dn], [False, True], [f_prev, s]
        else:
            if memory == "none":
                f_prev = truncnorm_sample(float(mean.value(xe)), sd0, [rng.random()])[0]
                outside = True
            X, U, D, Y = [xe], [dn], [False], [f_prev]
    raise RuntimeError("segment cap")


def _frame(n):
    sign = math.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    c = n[0] * n[1] * a
    return (np.array([1.0 + sign * n[0] * n[0] * a, sign * c, -sign * n[0]]),
            np.array([c, sign + n[1] * n[1] * a, -n[1]]))


def dense_first_hits(kernel, mean, o, d, t0, t1, n_points, n_samples, rng, chunk=4096):
    """Ground truth: first f >= 0 -> f < 0 crossing of dense joint samples at n_points
    equally spaced parameters, given f(t0) >= 0 (rejection: exactly the start condition),
    linear interpolation within the cell; inf where there is none."""
    o, d = np.asarray(o, float), np.asarray(d, float)
    ts = np.linspace(t0, t1, n_points)
    x = o + ts[:, None] * d
    K = jittered(covariance_matrix(kernel, x))
    L = np.linalg.cholesky(K).astype(np.float32)
    mu = mean.value(x)[:, None]
    out = []
    while sum(len(h) for h in out) < n_samples:
        F = mu + L @ rng.standard_normal((n_points, chunk), dtype=np.float32)
        F = F[:, F[0] >= 0.0]
        neg = F < 0.0
        first = np.where(neg.any(axis=0), neg.argmax(axis=0), -1)
        cols = np.arange(F.shape[1])
        j = np.maximum(first, 1)
        fa, fb = F[j - 1, cols], F[j, cols]
        th = ts[j - 1] + (ts[1] - ts[0]) * fa / (fa - fb)
        out.append(np.where(first > 0, th, np.inf))
    return np.concatenate(out)[:n_samples]


def downcrossing_rate(kernel, level, d):
    """Rice: expected f >= level -> f < level crossings per unit ray parameter."""
    var = kernel.variance
    d = np.asarray(d, float)
    lam2 = float(kernel.cov_dd(np.zeros(3), d, np.zeros(3), d))
    return math.exp(-level * level / (2.0 * var)) * math.sqrt(lam2 / var) / (2.0 * math.pi)
