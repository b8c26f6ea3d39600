"""Spectral samplers in 3-D: frequencies omega with E[cos(omega . r)] = k(r) / sigma^2.

By Bochner's theorem a stationary kernel is sigma^2 times the characteristic function of a
symmetric probability measure; random Fourier features
  f(x) = sigma sqrt(2/M) sum_i w_i cos(omega_i . x + b_i),  w_i ~ N(0,1), b_i ~ U[0, 2 pi)
then have covariance k exactly in expectation. Each sampler below is derived from the
kernel as implemented in kernels.py (r = b - a, A = diag(aniso), s = r^T A r):

squared_exponential  exp(-s / (2 l^2)) is the characteristic function of N(0, A / l^2):
                     omega = sqrt(A) z / l, z ~ N(0, I3). (The supplemental's Algorithm 1 is
                     a 2-D sampler with a typo; the reference's 3-D one ignores aniso in the
                     radius.)
rational_quadratic   (1 + s / (2 a l^2))^-a = E_tau[exp(-tau s / 2)] for tau ~ Gamma(shape
                     a, rate a l^2) (the Gamma Laplace transform at s/2), so omega =
                     sqrt(tau) sqrt(A) z. tau concentrates at 1/l^2 as a grows: the SE
                     limit. (The reference's 3-D version uses z / sqrt(tau): wrong.)
periodic             per axis, exp(-(2/l^2) sin^2(pi w c t)) = exp(-z (1 - cos(2 pi w c t)))
                     with z = 1/l^2, c = sqrt(A_ii); by e^{z cos t} = sum_n I_n(z) e^{int}
                     it equals sum_{n in Z} p_n cos(2 pi w c n t), p_n = e^-z I_|n|(z), which
                     sum to 1. So omega_i = 2 pi w c_i n_i with independent n_i ~ p. This is
                     exact because our 3-D periodic kernel is the product over axes; the
                     Euclidean form has no spectral measure in 3-D at all (not PD).
locally_periodic     the product of two kernels has the convolution of their measures as
                     its spectral measure: omega = omega_periodic + omega_SE, independent.
                     (E[cos((o1 + o2).r)] = E[cos o1.r] E[cos o2.r] for symmetric measures.)
matern32, matern52   Matern nu = p + 1/2 (3/2, 5/2). With x = sqrt(2 nu s) / l,
                     k / sigma^2 = 2^(1-nu) x^nu K_nu(x) / Gamma(nu), and for G ~ Gamma(nu, 1)
                     E[exp(-c / G)] = 2 c^(nu/2) K_nu(2 sqrt c) / Gamma(nu); at c = x^2 / 4 =
                     nu s / (2 l^2) the two agree, so exp(-s tau / 2) with tau = nu / (l^2 G)
                     mixes to the kernel: omega = sqrt(nu / G) sqrt(A) z / l, a multivariate
                     Student-t with 2 nu degrees of freedom (density ~ (2 nu / l^2 + |w|^2)
                     ^-(nu + 3/2) for A = I). E[omega omega^T] = A nu / ((nu - 1) l^2): 3 A / l^2
                     and 5 A / (3 l^2), i.e. -k''(0) / sigma^2. The 4th moment
                     (E[1/G^2] = 1/((nu-1)(nu-2))) is infinite for 3/2, finite for 5/2.
thin_plate           not sampled: raises ValueError (use function space).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .kernels import Kernel


@lru_cache(maxsize=64)
def periodic_order_weights(length_scale: float) -> np.ndarray:
    """P(|n| = m), m = 0.., for the 1-D periodic kernel's discrete spectrum.

    p_n = e^-z I_n(z), z = 1/l^2, are the Fourier coefficients of exp(z (cos t - 1)); the
    trapezoid rule on M points returns them aliased by p_{n + jM}, which is below double
    rounding once M exceeds four times the support. Beyond m_max = 9 sqrt(z) + 30 the
    Gaussian-like tail exp(-m^2 / (2z)) is below 1e-17.
    """
    z = 1.0 / length_scale**2
    m_max = int(np.ceil(9.0 * np.sqrt(z) + 30.0))
    M = 1 << int(np.ceil(np.log2(4 * m_max)))
    t = 2.0 * np.pi * np.arange(M) / M
    p = np.fft.rfft(np.exp(z * (np.cos(t) - 1.0))).real[: m_max + 1] / M
    p = np.clip(p, 0.0, None)
    q = np.concatenate([p[:1], 2.0 * p[1:]])       # fold n and -n
    return q / q.sum()


def _periodic_orders(length_scale, size, rng):
    q = periodic_order_weights(float(length_scale))
    m = rng.choice(len(q), size=size, p=q)
    return m * rng.choice(np.array([-1.0, 1.0]), size=size)


def sample_frequencies(kernel: Kernel, n: int, rng: np.random.Generator) -> np.ndarray:
    """n frequencies (n, 3) from the normalised spectral measure of kernel."""
    kind = kernel.kind
    sqrt_a = np.sqrt(np.asarray(kernel.aniso, dtype=np.float64))
    if kind == "squared_exponential":
        return rng.standard_normal((n, 3)) * sqrt_a / kernel.length_scale
    if kind == "rational_quadratic":
        al = kernel.alpha
        tau = rng.gamma(shape=al, scale=1.0 / (al * kernel.length_scale**2), size=n)
        return np.sqrt(tau)[:, None] * rng.standard_normal((n, 3)) * sqrt_a
    if kind in ("matern32", "matern52"):
        nu = kernel.nu
        g = rng.gamma(shape=nu, scale=1.0, size=n)
        return (np.sqrt(nu / g) / kernel.length_scale)[:, None] * rng.standard_normal((n, 3)) \
            * sqrt_a
    if kind in ("periodic", "locally_periodic"):
        omega = 2.0 * np.pi * kernel.w * sqrt_a * _periodic_orders(kernel.length_scale,
                                                                   (n, 3), rng)
        if kind == "locally_periodic":
            omega = omega + rng.standard_normal((n, 3)) * sqrt_a / kernel.se_length_scale
        return omega
    if kind == "thin_plate":
        raise ValueError("thin_plate has no spectral density; use function space")
    raise ValueError(f"no spectral sampler for kernel '{kind}'")


@dataclass(frozen=True, eq=False)
class RandomFeatures:
    """A weight-space basis; evaluate() is the numpy reference for device realizations."""

    omega: np.ndarray   # (M, 3)
    phase: np.ndarray   # (M,)
    sigma: float

    @classmethod
    def sample(cls, kernel: Kernel, m: int, rng: np.random.Generator) -> "RandomFeatures":
        omega = sample_frequencies(kernel, m, rng)
        return cls(omega, rng.uniform(0.0, 2.0 * np.pi, m), float(kernel.sigma))

    def evaluate(self, weights, x):
        """Zero-mean realization value (...) and gradient (..., 3) at points x (..., 3)."""
        x = np.asarray(x, dtype=np.float64)
        arg = x @ self.omega.T + self.phase
        c = self.sigma * np.sqrt(2.0 / len(self.phase))
        value = c * np.cos(arg) @ weights
        grad = -c * (np.sin(arg) * weights) @ self.omega
        return value, grad


# --- tables uploaded with a GPIS object -------------------------------------------------

def periodic_order_cdf(length_scale: float) -> np.ndarray:
    """cdf[m] = P(|n| <= m) (float32) of one axis's periodic order, last entry exactly 1.

    P(|n| = m) is periodic_order_weights (e^-z I_m(z), n and -n folded, z = 1/l^2). The
    device draws u in [0, 1) on a 2^-24 grid and takes the first m with u < cdf[m]; the
    table is cut where the remaining mass is below 2^-26, which that grid cannot resolve,
    and its last entry is set to 1 so every u finds an entry.
    """
    cdf = np.cumsum(periodic_order_weights(float(length_scale)))
    n = int(np.searchsorted(cdf, 1.0 - 2.0**-26)) + 1
    out = cdf[:n].astype(np.float32)
    out[-1] = 1.0
    return out


def order_table(kernel) -> np.ndarray:
    """The order table of a kernel: its periodic CDF, or [1] (never read) otherwise."""
    if kernel.kind in ("periodic", "locally_periodic"):
        return periodic_order_cdf(kernel.length_scale)
    return np.ones(1, np.float32)


def pack_order_tables(kernels):
    """One float32 buffer of all objects' tables, with per-object (first, count).

    Object j passes `table + first[j]` and `count[j]` as order_cdf / order_count.
    """
    tables = [order_table(k) for k in kernels]
    count = np.array([len(t) for t in tables], np.int32)
    first = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int32)
    table = np.concatenate(tables) if tables else np.ones(1, np.float32)
    return table.astype(np.float32), first, count
