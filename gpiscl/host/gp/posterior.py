"""Posterior GPIS on the host: a GP conditioned on observed values and gradients.

Observations are values f(x_j) = y_j (surface points: y = 0; inside/outside points: a
negative/positive value) and directional derivatives d_u f(x_j) = y_j (normals: the
gradient of a signed distance is the unit normal, so three axis derivatives per point),
each with its own noise variance. With K the joint covariance of the observations plus
their noise on the diagonal and r = y - (prior mean of the observations):

  exact (function space)  mean(x) = mu(x) + k_xo K^-1 r,
                          cov(x, x') = k(x, x') - k_xo K^-1 k_ox'
  pathwise (weight space) f_post(x) = f(x) + k_xo K^-1 (y - f(X) - eps), eps ~ N(0, noise),
                          for a prior realization f (Matheron's rule; Wilson et al. 2020):
                          a random-feature realization plus one kernel bump per
                          observation, exact in distribution when f is an exact prior draw.

Stable solve: one Cholesky factor of K (noise keeps it well conditioned; a jitter
relative to the diagonal is added, escalating, only if the factorization fails) and
blocked triangular solves, never an explicit inverse. Cost: O(n^3 / 3) once for n
observations (values and derivative components counted separately), then O(n) per
query point for the mean and O(n^2) for the variance; tools/bench_posterior.py measures it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .kernels import Kernel, NonStationary, covariance_matrix
from .means import Constant, Mean
from .spectral import RandomFeatures

_AXES = np.eye(3)


@dataclass
class Observations:
    """x (n, 3); u (n, 3): a direction per derivative observation, NaN rows for values;
    y (n,) observed values; noise (n,) variances."""

    x: np.ndarray
    u: np.ndarray
    y: np.ndarray
    noise: np.ndarray

    @classmethod
    def values(cls, x, y, noise=1e-6) -> "Observations":
        x = np.atleast_2d(np.asarray(x, float))
        n = len(x)
        return cls(x, np.full((n, 3), np.nan), np.broadcast_to(np.asarray(y, float), (n,)).copy(),
                   np.broadcast_to(np.asarray(noise, float), (n,)).copy())

    @classmethod
    def derivatives(cls, x, u, y, noise=1e-4) -> "Observations":
        x = np.atleast_2d(np.asarray(x, float))
        n = len(x)
        u = np.broadcast_to(np.asarray(u, float), (n, 3)).copy()
        return cls(x, u, np.broadcast_to(np.asarray(y, float), (n,)).copy(),
                   np.broadcast_to(np.asarray(noise, float), (n,)).copy())

    @classmethod
    def concat(cls, *parts: "Observations") -> "Observations":
        return cls(*(np.concatenate([getattr(p, f) for p in parts])
                     for f in ("x", "u", "y", "noise")))

    @property
    def is_value(self) -> np.ndarray:
        return np.any(np.isnan(self.u), axis=-1)

    def __len__(self) -> int:
        return len(self.x)


def surface_observations(points, normals=None, noise=1e-6, normal_noise=1e-3,
                         inside=None, outside=None, offset=0.1) -> Observations:
    """Zero values at surface points; with normals, grad f = n (three axis derivatives);
    inside / outside points observed at -offset / +offset."""
    parts = [Observations.values(points, 0.0, noise)]
    if normals is not None:
        p = np.asarray(points, float)
        nrm = np.asarray(normals, float)
        nrm = nrm / np.linalg.norm(nrm, axis=-1, keepdims=True)
        for i in range(3):
            parts.append(Observations.derivatives(p, _AXES[i], nrm[:, i], normal_noise))
    if inside is not None and len(inside):
        parts.append(Observations.values(inside, -offset, noise))
    if outside is not None and len(outside):
        parts.append(Observations.values(outside, offset, noise))
    return Observations.concat(*parts)


# --- linear algebra -------------------------------------------------------------------

def cholesky(K, max_tries: int = 7):
    """Lower Cholesky factor of K and the jitter added (relative to the mean diagonal)."""
    scale = float(np.mean(np.diag(K))) or 1.0
    jitter = 0.0
    for attempt in range(max_tries):
        try:
            A = K if jitter == 0.0 else K + jitter * scale * np.eye(len(K))
            return np.linalg.cholesky(A), jitter
        except np.linalg.LinAlgError:
            jitter = 1e-12 if jitter == 0.0 else jitter * 100.0
    raise np.linalg.LinAlgError(f"observation covariance is not positive definite even with "
                                f"jitter {jitter:g} x mean diagonal; add noise or remove "
                                f"duplicate observations")


def solve_triangular(L, B, transpose=False, block: int = 256):
    """L^-1 B (or L^-T B with transpose) for lower-triangular L, by blocks: small dense
    solves on the diagonal, matrix products elsewhere (numpy has no triangular solve)."""
    B = np.array(B, dtype=float, copy=True)
    vec = B.ndim == 1
    if vec:
        B = B[:, None]
    n = len(L)
    starts = list(range(0, n, block))
    if not transpose:
        for s in starts:
            e = min(s + block, n)
            B[s:e] = np.linalg.solve(L[s:e, s:e], B[s:e])
            if e < n:
                B[e:] -= L[e:, s:e] @ B[s:e]
    else:
        for s in reversed(starts):
            e = min(s + block, n)
            B[s:e] = np.linalg.solve(L[s:e, s:e].T, B[s:e])
            if s > 0:
                B[:s] -= L[s:e, :s].T @ B[s:e]
    return B[:, 0] if vec else B


# --- the posterior --------------------------------------------------------------------

def _prior_at(mean: Mean, obs: Observations) -> np.ndarray:
    """Prior mean of each observation: mu(x), or u . grad mu(x) for derivatives."""
    v, g = mean.value_and_gradient(obs.x)
    return np.where(obs.is_value, v, np.sum(np.nan_to_num(obs.u) * g, -1))


class Posterior:
    """GP(mean, kernel) conditioned on obs."""

    def __init__(self, kernel: Kernel, mean: Mean | None, obs: Observations):
        self.kernel, self.obs = kernel, obs
        self.mean_fn = mean if mean is not None else Constant(0.0)
        K = self._blocks(obs.x, obs.u)
        K[np.diag_indices_from(K)] += obs.noise
        self.L, self.jitter = cholesky(K)
        self.residual = obs.y - _prior_at(self.mean_fn, obs)
        self.alpha = self.solve(self.residual)

    def solve(self, b):
        """K^-1 b from the Cholesky factor."""
        return solve_triangular(self.L, solve_triangular(self.L, b), transpose=True)

    def _blocks(self, x, u=None) -> np.ndarray:
        """covariance_matrix(x, observations) by row blocks: its (rows, n, 3) temporaries
        would otherwise take gigabytes for 10^4 observations."""
        n = len(self.obs.x)
        rows = max(1, (1 << 21) // max(n, 1))
        out = np.empty((len(x), n))
        # values only (the common case of surface points): k(r) needs no derivative jet
        values_only = bool(np.all(self.obs.is_value)) and (u is None or np.all(np.isnan(u)))
        # a sigma(x) or l(x) field is no function of x - x' (kernels.NonStationary)
        values_only = values_only and not isinstance(self.kernel, NonStationary)
        for s in range(0, len(x), rows):
            if values_only:
                out[s:s + rows] = self.kernel.value(self.obs.x[None] - x[s:s + rows, None])
                continue
            uu = None if u is None else u[s:s + rows]
            out[s:s + rows] = covariance_matrix(self.kernel, x[s:s + rows], self.obs.x,
                                                u1=uu, u2=self.obs.u)
        return out

    def cross(self, x, u=None) -> np.ndarray:
        """cov(f(x) or d_u f(x), observations): (m, n)."""
        x = np.atleast_2d(np.asarray(x, float))
        uu = None if u is None else np.broadcast_to(np.asarray(u, float), x.shape)
        return self._blocks(x, uu)

    def mean(self, x) -> np.ndarray:
        x = np.atleast_2d(np.asarray(x, float))
        return self.mean_fn.value(x) + self.cross(x) @ self.alpha

    def mean_gradient(self, x) -> np.ndarray:
        x = np.atleast_2d(np.asarray(x, float))
        g = self.mean_fn.gradient(x)
        return g + np.stack([self.cross(x, _AXES[i]) @ self.alpha for i in range(3)], -1)

    def covariance(self, x1, x2=None) -> np.ndarray:
        x1 = np.atleast_2d(np.asarray(x1, float))
        x2 = x1 if x2 is None else np.atleast_2d(np.asarray(x2, float))
        V1 = solve_triangular(self.L, self.cross(x1).T)
        V2 = V1 if x2 is x1 else solve_triangular(self.L, self.cross(x2).T)
        return covariance_matrix(self.kernel, x1, x2) - V1.T @ V2

    def variance(self, x) -> np.ndarray:
        x = np.atleast_2d(np.asarray(x, float))
        V = solve_triangular(self.L, self.cross(x).T)
        prior = (self.kernel.variance_at(x) if isinstance(self.kernel, NonStationary)
                 else self.kernel.variance)
        return np.maximum(prior - np.sum(V * V, 0), 0.0)

    def occupancy(self, x) -> np.ndarray:
        """Posterior occupancy P(f(x) <= 0) = Phi(-mean / sd)."""
        from math import erfc, sqrt
        z = -self.mean(x) / np.sqrt(np.maximum(self.variance(x), 1e-300))
        return 0.5 * np.vectorize(erfc)(-z / sqrt(2.0))

    def sample(self, x, n: int, rng) -> np.ndarray:
        """n exact joint posterior samples (n, m) at points x (m, 3)."""
        C = self.covariance(x)
        lam, vec = np.linalg.eigh((C + C.T) / 2)
        root = vec * np.sqrt(np.clip(lam, 0.0, None))
        return self.mean(x) + rng.standard_normal((n, len(lam))) @ root.T

    def pathwise(self, features: RandomFeatures, weights, rng) -> "PathwiseSample":
        """Matheron's rule on the prior realization mean + features(weights)."""
        return PathwiseSample(self, features, np.asarray(weights, float), rng)


class PathwiseSample:
    """A posterior realization: prior random-feature realization plus n kernel bumps,
    f_post(x) = f(x) + k_xo v,  v = K^-1 (y - f(X) - eps). Evaluating it costs O(M + n)."""

    def __init__(self, post: Posterior, features: RandomFeatures, weights, rng):
        self.post, self.features, self.weights = post, features, weights
        obs = post.obs
        v, g = self._prior(obs.x)
        f_obs = np.where(obs.is_value, v, np.sum(np.nan_to_num(obs.u) * g, -1))
        eps = rng.standard_normal(len(obs)) * np.sqrt(obs.noise)
        self.v = post.solve(obs.y - f_obs - eps)

    def _prior(self, x):
        v, g = self.features.evaluate(self.weights, x)
        mv, mg = self.post.mean_fn.value_and_gradient(x)
        return v + mv, g + mg

    def __call__(self, x) -> np.ndarray:
        x = np.atleast_2d(np.asarray(x, float))
        return self._prior(x)[0] + self.post.cross(x) @ self.v

    def gradient(self, x) -> np.ndarray:
        x = np.atleast_2d(np.asarray(x, float))
        g = self._prior(x)[1]
        return g + np.stack([self.post.cross(x, _AXES[i]) @ self.v for i in range(3)], -1)
