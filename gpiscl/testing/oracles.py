"""Oracles the device samplers are held to: Rice's formula with the exact start-condition
integral, dense joint samples of a stationary GP along a ray, and the dense GP posterior
built pair by pair."""
import math

import numpy as np
from scipy import special

from gpiscl.host.gp import Matern32, Matern52

# Matern at the l where lambda2 = -k''(0) = 1: 3/l^2 = 1 and 5/(3 l^2) = 1
M32 = Matern32(sigma=1.0, length_scale=math.sqrt(3.0))
M52 = Matern52(sigma=1.0, length_scale=math.sqrt(5.0 / 3.0))
_R3 = math.sqrt(3.0)
# covariance along a unit ray and its derivative (sigma = 1, lambda2 = 1 for all)
COV_1D = {"se": (lambda t: np.exp(-0.5 * t * t), lambda t: -t * np.exp(-0.5 * t * t)),
          "rq": (lambda t: 1.0 / (1.0 + 0.5 * t * t), lambda t: -t / (1.0 + 0.5 * t * t) ** 2),
          "m32": (lambda t: (1.0 + t) * np.exp(-t), lambda t: -t * np.exp(-t)),
          "m52": (lambda t: (1.0 + _R3 * t + t * t) * np.exp(-_R3 * t),
                  lambda t: -t * (1.0 + _R3 * t) * np.exp(-_R3 * t))}


def expected_crossings(kind, mu, L, nt=6000, nz=600, start=0.0):
    """E[down-crossings of 0 in (start, L]] of f ~ GP(mu, k) on a unit-speed ray given the
    start condition f(0) >= 0 (nt midpoints of that stretch: start = L / 2 with nt / 2
    takes the second half of (0, L]'s nodes): the integral over t of Rice's rate
    conditioned on it,
      nu(t) = p_f(t)(0) E[(-f'(t))+ 1{f(0) >= 0} | f(t) = 0] / P(f(0) >= 0),
    where given f(t) = 0, f(0) ~ N(mu (1 - k), 1 - k^2) and f'(t) | f(0) is Gaussian with
    cov(f(0), f'(t)) = k'(t) (cov(f(t), f'(t)) = 0). Tends to Rice's rate as k -> 0."""
    k, dk = COV_1D[kind]
    t = start + (np.arange(nt) + 0.5) * ((L - start) / nt)
    kt, dkt = k(t)[:, None], dk(t)[:, None]
    ma, va = mu * (1.0 - kt), 1.0 - kt * kt
    sa = np.sqrt(va)
    zlo = -ma / sa
    w = np.linspace(0.0, 1.0, nz)[None, :]
    z = zlo + (np.maximum(10.0, zlo + 10.0) - zlo) * w     # a = ma + sa z >= 0
    dz = (np.maximum(10.0, zlo + 10.0) - zlo) / (nz - 1)
    mc, vc = dkt / sa * z, 1.0 - dkt * dkt / va            # f'(t) | f(0), f(t) = 0
    sc = np.sqrt(np.maximum(vc, 1e-300))
    neg = sc * np.exp(-0.5 * (mc / sc) ** 2) / math.sqrt(2 * math.pi) \
        - mc * 0.5 * special.erfc(mc / sc / math.sqrt(2))   # E[(-c)+], c ~ N(mc, sc^2)
    g = np.exp(-0.5 * z * z) / math.sqrt(2 * math.pi) * neg
    inner = np.trapezoid(g, dx=dz, axis=1)
    p0 = 0.5 * special.erfc(-mu / math.sqrt(2))             # P(f(0) >= 0)
    nu = math.exp(-0.5 * mu * mu) / math.sqrt(2 * math.pi) * inner / p0
    return float(nu.sum() * ((L - start) / nt))


def dense_se_paths(n, mu, rng, spacing=0.01, L=20.0):
    """n realizations of SE (l = 1) + mu at the given spacing over [0, L] along a unit ray,
    each with f(0) >= 0 (the march's start condition): circulant embedding (exact for
    a period of 8192 spacings: at its half, 41 l, SE's correlation is e^-839)."""
    N, M = int(round(L / spacing)) + 1, 8192
    lag = np.minimum(np.arange(M), M - np.arange(M)) * spacing
    root = np.sqrt(np.clip(np.fft.fft(np.exp(-0.5 * lag * lag)).real, 0.0, None) / M)
    paths = []
    while len(paths) < n:
        z = rng.standard_normal((64, M)) + 1j * rng.standard_normal((64, M))
        f = np.fft.fft(root * z, axis=1)[:, :N]
        F = np.concatenate([f.real, f.imag]) + mu
        paths.extend(F[F[:, 0] >= 0.0])
    return np.arange(N) * spacing, np.array(paths[:n])


def dense_reference(kernel, mean, obs, probes):
    """Posterior mean and variance from an explicit K built pair by pair."""
    def cov(xa, ua, xb, ub):
        if ua is None and ub is None:
            return kernel.cov(xa, xb)
        if ub is None:
            return kernel.cov_dv(xa, ua, xb)
        if ua is None:
            return kernel.cov_vd(xa, xb, ub)
        return kernel.cov_dd(xa, ua, xb, ub)

    us = [None if np.isnan(u).any() else u for u in obs.u]
    n = len(obs)
    K = np.array([[cov(obs.x[i], us[i], obs.x[j], us[j]) for j in range(n)] for i in range(n)])
    K += np.diag(obs.noise)
    prior = np.array([mean.value(x[None])[0] if u is None else u @ mean.gradient(x[None])[0]
                      for x, u in zip(obs.x, us)])
    k = np.array([[cov(p, None, obs.x[j], us[j]) for j in range(n)] for p in probes])
    Kinv = np.linalg.inv(K)
    mu = mean.value(probes) + k @ Kinv @ (obs.y - prior)
    var = kernel.variance - np.einsum("ij,jk,ik->i", k, Kinv, k)
    return mu, var
