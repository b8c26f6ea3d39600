"""Uncertainty quantification by double Monte Carlo (supplemental Section 4).

N weight-space realizations, K samples per pixel each. Per pixel and channel, with y_i the
mean of realization i and u_i = s_i^2 / K the within-realization variance of that mean
(s_i^2: the film's unbiased sample variance of i's K samples):

  mean            ybar = sum y_i / N
  Eq. 44 (plain)  sum (y_i - ybar)^2 / N: its expectation is
                  (N-1)/N (Var_Phi[M] + E[s^2] / K), biased by the Monte Carlo noise
  unbiased        V = sum (y_i - ybar)^2 / (N-1) - sum u_i / N. By the law of total variance
                  Var(y) = Var_Phi[M] + E[s^2 / K], and E[s_i^2 | Phi_i] = Var(sample | Phi_i),
                  so E[V] = Var_Phi[M] exactly, for any N >= 2 and K >= 2. V is NOT clamped:
                  clamping at 0 would bias it upwards where the true variance is small, so it
                  can be negative; only previews and the derived std clamp.
  standard error  of V: V is the mean of d_i = N/(N-1) (y_i - ybar)^2 - u_i, so its
                  variance is estimated by the sample variance of d / N (ybar treated as
                  known: the SE itself is off by O(1/N) relative, fine for N >~ 10).

Independence: realization i has its own geometry id and its own path-sampling seed.
Reusing one seed for every realization would share the Monte Carlo samples between
realizations and bias V low by Var_y[E_Phi(y | samples)].

UqSums holds the moments of a set of realizations as centred sums, merged with the
pairwise update of Chan et al. and Pebay (2008), so batches of realizations rendered
anywhere merge in any order to the same result (up to float64 rounding) and stay
accurate when the variance is tiny next to the mean.
"""
from __future__ import annotations

import copy
import json
from dataclasses import dataclass, fields

import numpy as np

from ..render.film import FilmImage

_MASK31 = (1 << 31) - 1
_MASK32 = (1 << 32) - 1


def _mix32(x: int) -> int:
    """A 32-bit integer hash (lowbias32, C. Wellons): a bijection of [0, 2^32)."""
    x &= _MASK32
    x ^= x >> 16
    x = (x * 0x7FEB352D) & _MASK32
    x ^= x >> 15
    x = (x * 0x846CA68B) & _MASK32
    x ^= x >> 16
    return x


def realization_ids(seed: int, first: int, count: int):
    """(geometry ids, path seeds) of realizations first .. first+count-1 of a run.

    id_i = (h(seed) + i * odd) mod 2^31 is a bijection of i mod 2^31, so ids within a run
    are distinct; path seeds are hashed again so that no two realizations of a run share
    Monte Carlo samples (the path seed is a bijection of i too).
    """
    pairs = list(iter_realizations(seed, first, count))
    return [p[0] for p in pairs], [p[1] for p in pairs]


def iter_realizations(seed: int, first: int, count: int):
    """(geometry id, path seed) of each realization, one at a time: a run of 10^9
    realizations is interrupted or time-limited long before its ids would fit in memory."""
    base, hashed = _mix32(seed ^ 0x5BD1E995), _mix32(seed)
    for i in range(first, first + count):
        yield (base + i * 0x2545F491) & _MASK31, _mix32((hashed + i * 0x9E3779B9) & _MASK32)


@dataclass
class UqSums:
    """Centred per-pixel sums over realizations; arrays are (H, W, 3) float64.

    n      realizations                 m2..m4  sum (y - mean)^k
    mean   mean of the realization means c1, c2  sum (y - mean)^k u
    u, uu  sum u, sum u^2 (u: within-realization variance of a realization's mean)
    """

    n: int
    mean: np.ndarray
    m2: np.ndarray
    m3: np.ndarray
    m4: np.ndarray
    c1: np.ndarray
    c2: np.ndarray
    u: np.ndarray
    uu: np.ndarray

    @classmethod
    def empty(cls, shape) -> "UqSums":
        z = lambda: np.zeros(shape, np.float64)
        return cls(0, z(), z(), z(), z(), z(), z(), z(), z())

    @classmethod
    def from_realization(cls, y, u) -> "UqSums":
        """One realization: its per-pixel mean y and the variance u of that mean."""
        y = np.asarray(y, np.float64)
        u = np.asarray(u, np.float64)
        z = np.zeros_like(y)
        return cls(1, y.copy(), z, z.copy(), z.copy(), z.copy(), z.copy(), u.copy(), u * u)

    @classmethod
    def from_film(cls, image: FilmImage) -> "UqSums":
        """From a realization's film, in double (the film's float32 stderr is not used)."""
        k = image.count[..., None]
        if np.any(k < 2):
            raise ValueError("every pixel needs >= 2 samples for a within-realization variance")
        y = image.sum / k
        # rounding only can make this negative; the exact value is a sum of squares
        s2 = np.maximum(image.sum_sq - k * y * y, 0.0) / (k - 1)
        return cls.from_realization(y, s2 / k)

    def merge(self, other: "UqSums") -> "UqSums":
        """The sums of both sets of realizations (a new object; neither input changes)."""
        if other.n == 0:
            return copy.deepcopy(self)
        if self.n == 0:
            return copy.deepcopy(other)
        if self.mean.shape != other.mean.shape:
            raise ValueError(f"cannot merge images of shapes {self.mean.shape} and "
                             f"{other.mean.shape}")
        a, b = self, other
        na, nb = float(a.n), float(b.n)
        n = na + nb
        delta = b.mean - a.mean
        da, db = -nb * delta / n, na * delta / n        # old means minus the new mean
        m2 = a.m2 + b.m2 + delta**2 * na * nb / n
        m3 = (a.m3 + b.m3 + delta**3 * na * nb * (na - nb) / n**2
              + 3.0 * delta * (na * b.m2 - nb * a.m2) / n)
        m4 = (a.m4 + b.m4 + delta**4 * na * nb * (na * na - na * nb + nb * nb) / n**3
              + 6.0 * delta**2 * (na * na * b.m2 + nb * nb * a.m2) / n**2
              + 4.0 * delta * (na * b.m3 - nb * a.m3) / n)
        c1 = a.c1 + da * a.u + b.c1 + db * b.u
        c2 = (a.c2 + 2.0 * da * a.c1 + da**2 * a.u) + (b.c2 + 2.0 * db * b.c1 + db**2 * b.u)
        # the mean as a weighted sum of both, symmetric in a and b
        mean = (na * a.mean + nb * b.mean) / n
        return UqSums(a.n + b.n, mean, m2, m3, m4, c1, c2, a.u + b.u, a.uu + b.uu)

    __add__ = merge

    # --- estimates ------------------------------------------------------------------

    def _need(self, k: int):
        if self.n < k:
            raise ValueError(f"needs at least {k} realizations (have {self.n})")

    @property
    def mean_stderr(self) -> np.ndarray:
        """Standard error of the mean image (realization and Monte Carlo noise together)."""
        self._need(2)
        return np.sqrt(self.m2 / (self.n - 1) / self.n)

    @property
    def variance_eq44(self) -> np.ndarray:
        """Eq. 44: the plain variance of the realization means (biased for finite K)."""
        self._need(1)
        return self.m2 / self.n

    @property
    def variance(self) -> np.ndarray:
        """Unbiased between-realization variance (law of total variance); not clamped."""
        self._need(2)
        return self.m2 / (self.n - 1) - self.u / self.n

    @property
    def within_variance(self) -> np.ndarray:
        """Mean within-realization variance of a realization's mean, E[s^2] / K."""
        self._need(1)
        return self.u / self.n

    @property
    def variance_stderr(self) -> np.ndarray:
        """Standard error of `variance` (delta method over the terms d_i)."""
        self._need(2)
        n = float(self.n)
        c = n / (n - 1.0)
        sum_d = c * self.m2 - self.u
        sum_d2 = c * c * self.m4 - 2.0 * c * self.c2 + self.uu
        var_d = np.maximum(sum_d2 - sum_d**2 / n, 0.0) / (n - 1.0)
        return np.sqrt(var_d / n)

    @property
    def std(self) -> np.ndarray:
        """sqrt(max(variance, 0)): for viewing; clamping makes it biased."""
        return np.sqrt(np.maximum(self.variance, 0.0))

    # --- partial results on disk, for batches rendered elsewhere ---------------------

    def save(self, path, meta: dict | None = None) -> None:
        """meta: where the sums come from (render_realizations' UqRun.meta), kept as JSON
        so that --merge can check the batches belong together."""
        extra = {} if meta is None else {"meta": np.array(json.dumps(meta))}
        np.savez_compressed(path, **{f.name: np.asarray(getattr(self, f.name))
                                     for f in fields(self)}, **extra)

    @classmethod
    def load(cls, path) -> "UqSums":
        with np.load(path) as z:
            kw = {f.name: z[f.name] for f in fields(cls)}
        kw["n"] = int(kw["n"])
        return cls(**kw)
