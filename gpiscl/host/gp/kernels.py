"""Stationary covariance kernels on R^3 with closed-form derivative covariances, and
(NonStationary, at the end) their spatially varying sigma(x), l(x) forms.

Conventions (pinned here, in gp_kernel.h and in the docs):
  r = b - a for k(a, b);  A = diag(aniso);  s = r^T A r.
  squared_exponential  k = sigma^2 exp(-s / (2 l^2))   (Rasmussen & Williams, the authors'
                       code; the supplemental's Eq. 16 drops the 2, which is a typo)
  rational_quadratic   k = sigma^2 (1 + s / (2 a l^2))^(-a)   -> SE as a -> infinity
  periodic             k = sigma^2 exp(-(2/l^2) sum_i sin^2(pi w sqrt(A_ii) r_i)),
                       a product of 1-D periodic kernels, one per axis. The supplemental's
                       exp(-2 sin^2(pi w |r|) / l^2) of the Euclidean distance is not
                       positive semidefinite in 3-D (200 random points in a cube give an
                       eigenvalue near -14): it is valid only on collinear points, e.g.
                       values along one ray, and fails once gradients or other rays are
                       conditioned on. The product form is PD, has an exact discrete
                       spectrum (spectral.py), has no sqrt(s) (the reference's NaN at s = 0)
                       and agrees with the Euclidean form to second order at r = 0, so the
                       gradient variances are the same: 4 pi^2 w^2 sigma^2 A / l^2.
  locally_periodic     periodic(l, w) * exp(-s / (2 l_se^2)), one sigma^2.
  thin_plate           k = sigma^2 (2 rho^3 - 3 R rho^2 + R^3), rho = sqrt(s) <= R, and 0
                       beyond R. (R - rho)^2 (2 rho + R) has a double root at R, so the zero
                       extension is C^1; second derivatives jump there. Not PD in 3-D in
                       general: 300 points filling a ball of diameter R (in the metric of
                       A) gave negative eigenvalues; balls of diameter <= 0.8 R passed.
                       Keep R at least twice the domain diameter. At rho = 0 the
                       derivative covariances use their exact limits (no sqrt(0) NaN).
  matern32             k = sigma^2 (1 + c rho) e^{-c rho},  c = sqrt(3)/l, rho = sqrt(s):
                       2 k'(s) = -sigma^2 c^2 e^{-c rho}, 4 k''(s) = sigma^2 c^3 e^{-c rho} / rho.
                       The 1/rho multiplies (u.Ar)(v.Ar) = O(rho^2): the limit at rho = 0 is
                       0 (the Hessian of k is continuous, its 4th derivatives are not: the
                       realizations are once differentiable). -k''(0) = 3 sigma^2 A / l^2.
  matern52             k = sigma^2 (1 + c rho + c^2 rho^2 / 3) e^{-c rho},  c = sqrt(5)/l:
                       2 k'(s) = -sigma^2 c^2 (1 + c rho) e^{-c rho} / 3,
                       4 k''(s) = sigma^2 c^4 e^{-c rho} / 3 (smooth at 0);
                       -k''(0) = 5 sigma^2 A / (3 l^2).

Every kernel returns the local jet of k as a function of r:
  k(r),  grad k(r) = G,  Hess k(r) = alpha g g^T + diag(D)
from which all covariances of values and directional derivatives follow:
  cov(f(a), f(b)) = k                  cov(d_u f(a), f(b)) = -u.G
  cov(f(a), d_v f(b)) = v.G            cov(d_u f(a), d_v f(b)) = -(alpha (u.g)(v.g) + u.D.v)
For kernels of s alone, G = 2 k'(s) A r, g = A r, alpha = 4 k''(s), D = 2 k'(s) diag(A).
For the product kernels, k = sigma^2 exp(-h(r)) with a separable h, so
G = -k grad h, g = grad h, alpha = k, D = -k diag(Hess h).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np


class Jet(NamedTuple):
    k: np.ndarray       # (...)
    G: np.ndarray       # (..., 3) gradient of k with respect to r
    alpha: np.ndarray   # (...)    Hess k = alpha g g^T + diag(D)
    g: np.ndarray       # (..., 3)
    D: np.ndarray       # (..., 3)


def _vec(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


class Kernel:
    """Shared covariance logic; subclasses provide jet(r) and value(r)."""

    kind = ""
    _positive = ("sigma", "length_scale", "alpha", "w", "se_length_scale", "radius")

    def __post_init__(self):
        for name in self._positive:
            if hasattr(self, name) and not float(getattr(self, name)) > 0.0:
                raise ValueError(f"{self.kind}: {name} must be positive, got "
                                 f"{getattr(self, name)}")
        aniso = np.asarray(self.aniso, dtype=np.float64)
        if aniso.shape != (3,) or not np.all(aniso > 0.0):
            raise ValueError(f"{self.kind}: aniso must be three positive numbers, got "
                             f"{self.aniso}")

    @property
    def variance(self) -> float:
        """k(0), the marginal variance (sigma^2 R^3 for thin-plate)."""
        return float(self.value(np.zeros(3)))

    @property
    def _a(self) -> np.ndarray:
        return _vec(self.aniso)

    def jet(self, r) -> Jet:
        raise NotImplementedError

    def value(self, r) -> np.ndarray:
        return self.jet(r).k

    def cov(self, a, b):
        """cov(f(a), f(b))."""
        return self.value(_vec(b) - _vec(a))

    def cov_dv(self, a, u, b):
        """cov(d_u f(a), f(b))."""
        j = self.jet(_vec(b) - _vec(a))
        return -np.sum(_vec(u) * j.G, axis=-1)

    def cov_vd(self, a, b, v):
        """cov(f(a), d_v f(b))."""
        j = self.jet(_vec(b) - _vec(a))
        return np.sum(_vec(v) * j.G, axis=-1)

    def cov_dd(self, a, u, b, v):
        """cov(d_u f(a), d_v f(b))."""
        j = self.jet(_vec(b) - _vec(a))
        u, v = _vec(u), _vec(v)
        return -(j.alpha * np.sum(u * j.g, -1) * np.sum(v * j.g, -1)
                 + np.sum(u * j.D * v, -1))

    def gradient_variance(self) -> np.ndarray:
        """Var(d_i f) per axis: the diagonal of -Hess k(0)."""
        return -self.jet(np.zeros(3)).D


class _RadialKernel(Kernel):
    """Kernels of s = r^T A r alone: subclasses give (k, 2 k'(s), 4 k''(s))."""

    def _radial(self, s):
        raise NotImplementedError

    def value(self, r):
        r = _vec(r)
        return self._radial(np.sum(self._a * r * r, axis=-1))[0]

    def jet(self, r):
        r = _vec(r)
        a = self._a
        ar = a * r
        k, dk2, ddk4 = self._radial(np.sum(ar * r, axis=-1))
        return Jet(k, dk2[..., None] * ar, ddk4, ar, dk2[..., None] * a)


class _LogSeparableKernel(Kernel):
    """k = sigma^2 exp(-h(r)), h a sum of per-axis terms: subclasses give h, grad h, diag Hess h."""

    def _h(self, r):
        raise NotImplementedError

    def jet(self, r):
        h, dh, hh = self._h(_vec(r))
        k = float(self.sigma) ** 2 * np.exp(-h)
        return Jet(k, -k[..., None] * dh, k, dh, -k[..., None] * hh)

    def _periodic_h(self, r, length_scale, w):
        c = np.pi * w * np.sqrt(self._a)
        cr = c * r
        # sin^2 rather than (1 - cos)/2: no cancellation at small lags
        h = (2.0 / length_scale**2) * np.sum(np.sin(cr) ** 2, axis=-1)
        dh = (2.0 / length_scale**2) * c * np.sin(2.0 * cr)
        hh = (4.0 / length_scale**2) * c * c * np.cos(2.0 * cr)
        return h, dh, hh


@dataclass(frozen=True)
class SquaredExponential(_RadialKernel):
    sigma: float = 1.0
    length_scale: float = 1.0
    aniso: tuple = (1.0, 1.0, 1.0)
    kind = "squared_exponential"

    def _radial(self, s):
        l2 = self.length_scale**2
        k = float(self.sigma) ** 2 * np.exp(-s / (2.0 * l2))
        return k, -k / l2, k / (l2 * l2)


@dataclass(frozen=True)
class RationalQuadratic(_RadialKernel):
    sigma: float = 1.0
    length_scale: float = 1.0
    alpha: float = 1.0
    aniso: tuple = (1.0, 1.0, 1.0)
    kind = "rational_quadratic"

    def _radial(self, s):
        l2, al = self.length_scale**2, self.alpha
        x = s / (2.0 * al * l2)
        # log1p keeps the a -> infinity limit (SE) accurate
        k = float(self.sigma) ** 2 * np.exp(-al * np.log1p(x))
        base = 1.0 + x
        return k, -k / (l2 * base), k * (al + 1.0) / (al * l2 * l2 * base * base)


@dataclass(frozen=True)
class ThinPlate(_RadialKernel):
    sigma: float = 1.0
    radius: float = 1.0
    aniso: tuple = (1.0, 1.0, 1.0)
    kind = "thin_plate"

    def _radial(self, s):
        R, v = self.radius, float(self.sigma) ** 2
        rho = np.sqrt(s)
        inside = rho < R
        # factored form of 2 rho^3 - 3 R rho^2 + R^3: no cancellation near rho = R
        k = np.where(inside, v * (R - rho) ** 2 * (2.0 * rho + R), 0.0)
        dk2 = np.where(inside, 6.0 * v * (rho - R), 0.0)
        # 4 k'' = 6 sigma^2 / rho multiplies (u.Ar)(v.Ar) = O(rho^2): the exact limit at
        # rho = 0 is 0, where the reference's sqrt(s) gave NaN
        safe = np.where(rho > 0.0, rho, 1.0)
        ddk4 = np.where(inside & (rho > 0.0), 6.0 * v / safe, 0.0)
        return k, dk2, ddk4


@dataclass(frozen=True)
class Matern32(_RadialKernel):
    sigma: float = 1.0
    length_scale: float = 1.0
    aniso: tuple = (1.0, 1.0, 1.0)
    kind = "matern32"
    nu = 1.5

    def _radial(self, s):
        v, c = float(self.sigma) ** 2, np.sqrt(3.0) / self.length_scale
        rho = np.sqrt(s)
        e = np.exp(-c * rho)
        safe = np.where(rho > 0.0, rho, 1.0)
        ddk4 = np.where(rho > 0.0, v * c**3 * e / safe, 0.0)
        return v * (1.0 + c * rho) * e, -v * c * c * e, ddk4


@dataclass(frozen=True)
class Matern52(_RadialKernel):
    sigma: float = 1.0
    length_scale: float = 1.0
    aniso: tuple = (1.0, 1.0, 1.0)
    kind = "matern52"
    nu = 2.5

    def _radial(self, s):
        v, c = float(self.sigma) ** 2, np.sqrt(5.0) / self.length_scale
        rho = np.sqrt(s)
        cr = c * rho
        e = np.exp(-cr)
        return (v * (1.0 + cr + cr * cr / 3.0) * e, -v * c * c * (1.0 + cr) * e / 3.0,
                v * c**4 * e / 3.0)


@dataclass(frozen=True)
class Periodic(_LogSeparableKernel):
    sigma: float = 1.0
    length_scale: float = 1.0
    w: float = 2.0 * np.pi      # frequency: period 1 / (w sqrt(A_ii)) along axis i
    aniso: tuple = (1.0, 1.0, 1.0)
    kind = "periodic"

    def _h(self, r):
        return self._periodic_h(r, self.length_scale, self.w)


@dataclass(frozen=True)
class LocallyPeriodic(_LogSeparableKernel):
    sigma: float = 1.0
    length_scale: float = 1.0       # of the periodic factor
    w: float = 2.0 * np.pi
    se_length_scale: float = 1.0    # of the squared-exponential envelope
    aniso: tuple = (1.0, 1.0, 1.0)
    kind = "locally_periodic"

    def _h(self, r):
        h, dh, hh = self._periodic_h(r, self.length_scale, self.w)
        a, L2 = self._a, self.se_length_scale**2
        ar = a * r
        return h + np.sum(ar * r, -1) / (2.0 * L2), dh + ar / L2, hh + a / L2


def _observation_rows(x1, x2, u1, u2):
    """Points and derivative directions of two observation sets: (x1, u1, d1, x2, u2, d2),
    d marking derivative rows (u given and not NaN), u zero on value rows; x2 = None means
    the first set again."""
    x1 = _vec(x1)
    x2 = x1 if x2 is None else _vec(x2)
    if x2 is x1 and u2 is None:
        u2 = u1

    def split(x, u):
        if u is None:
            return np.zeros_like(x), np.zeros(len(x), bool)
        u = _vec(u)
        d = ~np.any(np.isnan(u), axis=-1)
        return np.where(d[:, None], u, 0.0), d

    u1, d1 = split(x1, u1)
    u2, d2 = split(x2, u2)
    return x1, u1, d1, x2, u2, d2


def covariance_matrix(kernel: Kernel, x1, x2=None, u1=None, u2=None):
    """Joint covariance of observations at points x (n, 3).

    u (n, 3) holds a direction per observation for directional derivatives; a row of
    NaN, or u = None, marks a value observation.
    """
    if isinstance(kernel, NonStationary):
        return kernel.covariance_matrix(x1, x2, u1, u2)
    x1, u1, d1, x2, u2, d2 = _observation_rows(x1, x2, u1, u2)
    j = kernel.jet(x2[None, :, :] - x1[:, None, :])
    ug1 = np.einsum("ik,ijk->ij", u1, j.g)
    ug2 = np.einsum("jk,ijk->ij", u2, j.g)
    vv = j.k
    dv = -np.einsum("ik,ijk->ij", u1, j.G)
    vd = np.einsum("jk,ijk->ij", u2, j.G)
    dd = -(j.alpha * ug1 * ug2 + np.einsum("ik,ijk,jk->ij", u1, j.D, u2))
    D1, D2 = d1[:, None], d2[None, :]
    return np.where(D1, np.where(D2, dd, dv), np.where(D2, vd, vv))


# --- spatially varying sigma(x) and l(x) ------------------------------------------------
#
# Fields are dimensionless positive multipliers: sigma(x) = sigma m_s(x), l(x) = l m_l(x)
# (the reference's `nonstationary` / `proc_nonstationary` semantics: the base kernel's own
# sigma and l still apply), so a field identically 1 is the stationary kernel. Only the
# value and gradient of a field enter: the derivative covariances need grad_a grad_b^T of
# k, in which a field at a and the same field at b never meet in one second derivative.
#
# Variance field (any base kernel k0; PSD because it is a congruence D K0 D):
#   k(a, b) = m(a) m(b) k0(a, b), and by the product rule
#   cov(d_u f(a), f(b))      = m(b) [(u.grad m(a)) k0 + m(a) cov0(d_u f(a), f(b))]
#   cov(d_u f(a), d_v f(b))  = (u.grad m(a))(v.grad m(b)) k0
#                              + (u.grad m(a)) m(b) cov0(f(a), d_v f(b))
#                              + m(a) (v.grad m(b)) cov0(d_u f(a), f(b)) + m(a) m(b) cov0(d_u, d_v)
# The reference froze sigma(x) and l(x) in its derivative covariances (REFERENCE-ALGORITHMS
# 2.3): those are then not the covariances of the derivatives of its f, so slopes and
# normals drawn with them follow another law than the surface's. Here every term is kept.
#
# Length-scale field: Paciorek & Schervish with Sigma(x) = l(x)^2 A^-1 (d = 3):
#   k0(a, b) = (|Sigma_a| |Sigma_b|)^(1/4) |(Sigma_a + Sigma_b)/2|^(-1/2) kappa(r^T Sbar^-1 r)
#            = (2 l_a l_b / S)^(3/2) kappa_L(s),   S = l_a^2 + l_b^2,  L^2 = S / 2,
# kappa_L the stationary radial kernel at length scale L:
#   SE  k0 = sigma^2 (2 l_a l_b / S)^(3/2) exp(-s / S)
#   RQ  k0 = sigma^2 (2 l_a l_b / S)^(3/2) (1 + s / (a S))^(-a)
# With l constant, S = 2 l^2 and the prefactor is 1: sigma^2 exp(-s / (2 l^2)), our SE.
# PD for every radial kernel that is PD in all dimensions (SE, and RQ as a scale mixture
# of SE); thin-plate and the product kernels have no such form and take no l(x).
# Derivatives through F = ln k0 = const + 3/2 ln l_a + 3/2 ln l_b + G(s, S),
#   G = psi(s, S) - 3/2 ln S, psi = ln kappa_L: with beta = 1/a (0 for SE), D = S + beta s,
#   psi_s = -1/D, psi_ss = beta/D^2, psi_sS = 1/D^2, psi_S = s/(S D),
#   psi_SS = -s (D + S)/(D^2 S^2);
#   grad_a s = -2Ar, grad_b s = 2Ar, grad_a grad_b^T s = -2A, grad_a S = 2 l_a grad l_a;
#   grad_a F = 3/2 grad l_a / l_a - 2 G_s Ar + G_S grad_a S   (b: +2 G_s Ar, grad_b S)
#   u^T (grad_a grad_b^T F) v = -2 G_s u.Av + 2 (v.Ar)(-2 G_ss u.Ar + G_sS u.grad_a S)
#                               + (v.grad_b S)(-2 G_sS u.Ar + G_SS u.grad_a S)
#   cov(d_u f(a), f(b)) = k0 u.grad_a F,  cov(d_u f(a), d_v f(b)) = k0 [(u.grad_a F)(v.grad_b F)
#                                                                       + u^T H v]

@dataclass(frozen=True)
class LinearField:
    """m(x) = value + gradient . (x - origin); the scene check keeps it positive over the
    proxy, where rays sample it."""
    value: float = 1.0
    gradient: tuple = (0.0, 0.0, 0.0)
    origin: tuple = (0.0, 0.0, 0.0)
    kind = "linear"

    def eval(self, x):
        x = _vec(x)
        g = _vec(self.gradient)
        return self.value + np.sum((x - _vec(self.origin)) * g, -1), np.broadcast_to(g, x.shape)


@dataclass(frozen=True)
class RadialField:
    """A smooth blend from `inner` (|x - center| < radius) to `outer`, across a shell of
    about `width`: m = inner + (outer - inner) (1 + tanh(t)) / 2, t = (q - R^2) / (2 R width),
    q = |x - c|^2. t ~ (|x - c| - R) / width near the sphere; a function of q rather than
    of |x - c| keeps m smooth at the centre."""
    center: tuple = (0.0, 0.0, 0.0)
    radius: float = 1.0
    width: float = 0.1
    inner: float = 1.0
    outer: float = 1.0
    kind = "radial"

    def __post_init__(self):
        for name in ("radius", "width", "inner", "outer"):
            if not float(getattr(self, name)) > 0.0:
                raise ValueError(f"radial field: {name} must be positive")

    def eval(self, x):
        q = _vec(x) - _vec(self.center)
        R, w = self.radius, self.width
        th = np.tanh((np.sum(q * q, -1) - R * R) / (2.0 * R * w))
        h = 0.5 * (self.outer - self.inner)
        return self.inner + h * (1.0 + th), (h * (1.0 - th * th) / (R * w))[..., None] * q

    def minimum(self):
        return float(min(self.inner, self.outer))



@dataclass(frozen=True, eq=False)
class GridField:
    """Trilinear in samples values[i, j, k] > 0 at origin + voxel_size (i, j, k) (every
    n >= 2), the border value held outside the sample box, as fs_sampling.h
    fs_grid_field: inside, the gradient of the same interpolant (one-sided at cell
    faces: the cell is floor(u), the last one at the far faces); outside, 0 along each
    clamped axis. m is continuous and its gradient jumps across cell faces, which keeps
    every covariance built from (m, grad m) valid: k(a, b) = m(a) m(b) k0(a, b) and the
    Paciorek-Schervish form are covariances for any positive m; the derivative rows are
    those of the interpolant wherever it is differentiable."""
    values: np.ndarray
    origin: tuple
    voxel_size: float
    kind = "grid"

    def eval(self, x):
        x = _vec(x)
        values = np.asarray(self.values)   # gathered corners go to float64 (GridMean's)
        hi = np.asarray(values.shape, float) - 1.0
        u = (x - _vec(self.origin)) / self.voxel_size
        c = np.clip(u, 0.0, hi)
        cell = np.minimum(np.floor(c), hi - 1.0)
        t = c - cell
        i, j, k = (cell[..., a].astype(np.intp) for a in range(3))
        m, g = 0.0, np.zeros(x.shape)
        for a in (0, 1):
            for b in (0, 1):
                for e in (0, 1):
                    w = [t[..., 0] if a else 1 - t[..., 0], t[..., 1] if b else 1 - t[..., 1],
                         t[..., 2] if e else 1 - t[..., 2]]
                    v = values[i + a, j + b, k + e].astype(np.float64)
                    m = m + w[0] * w[1] * w[2] * v
                    for ax, sign in enumerate((a, b, e)):
                        others = [w[q] for q in range(3) if q != ax]
                        g[..., ax] += (1.0 if sign else -1.0) * others[0] * others[1] * v
        g = np.where(u != c, 0.0, g) / self.voxel_size
        return m, g

    def minimum(self):
        """A lower bound anywhere: trilinear values are convex combinations of samples."""
        return float(np.min(self.values))

    def maximum(self):
        return float(np.max(self.values))



FIELDS = {cls.kind: cls for cls in (LinearField, RadialField, GridField)}


@dataclass(frozen=True)
class NonStationary(Kernel):
    """A stationary base kernel with a variance field and/or (SE, RQ) a length-scale
    field; see the derivation above. step_length_scale: the smallest l(x) where rays
    sample (set by the scene compiler from the proxy); the step rule uses it."""
    base: Kernel = None
    sigma_field: object = None
    length_scale_field: object = None
    step_length_scale: float | None = None

    def __post_init__(self):
        if not isinstance(self.base, Kernel) or isinstance(self.base, NonStationary):
            raise ValueError("non-stationary kernel: base must be a stationary kernel")
        if (self.length_scale_field is not None
                and not isinstance(self.base, (SquaredExponential, RationalQuadratic))):
            raise ValueError(f"{self.base.kind}: a length_scale field needs a radial kernel "
                             "that is positive definite in every dimension (SE, RQ)")

    def __getattr__(self, name):   # kind, sigma, length_scale, aniso, ... of the base
        if name.startswith("__") or name == "base":
            raise AttributeError(name)
        return getattr(self.base, name)

    def value(self, r):
        raise TypeError("a non-stationary kernel is not a function of r = b - a: use cov")

    def jet(self, r):
        raise TypeError("a non-stationary kernel has no jet in r: use cov, cov_dv, ...")

    def variance_at(self, x):
        return self.cov(x, x)

    def _l(self, x):
        m, g = self.length_scale_field.eval(x)
        return self.base.length_scale * m, self.base.length_scale * g

    def _base_terms(self, a, u, b, v):
        """k0, cov0(d_u f(a), f(b)), cov0(f(a), d_v f(b)), cov0(d_u f(a), d_v f(b))."""
        base = self.base
        if self.length_scale_field is None:
            return (base.cov(a, b), base.cov_dv(a, u, b), base.cov_vd(a, b, v),
                    base.cov_dd(a, u, b, v))
        A = base._a
        r = b - a
        Ar = A * r
        s = np.sum(Ar * r, -1)
        la, gla = self._l(a)
        lb, glb = self._l(b)
        S = la * la + lb * lb
        sig2 = float(base.sigma) ** 2
        if isinstance(base, RationalQuadratic):
            al = base.alpha
            beta, psi = 1.0 / al, -al * np.log1p(s / (al * S))
        else:
            beta, psi = 0.0, -s / S
        k0 = sig2 * (2.0 * la * lb / S) ** 1.5 * np.exp(psi)
        D = S + beta * s
        G_s, G_ss, G_sS = -1.0 / D, beta / D**2, 1.0 / D**2
        G_S = s / (S * D) - 1.5 / S
        G_SS = -s * (D + S) / (D**2 * S**2) + 1.5 / S**2
        gSa, gSb = 2.0 * la[..., None] * gla, 2.0 * lb[..., None] * glb
        Fa = 1.5 * gla / la[..., None] - 2.0 * G_s[..., None] * Ar + G_S[..., None] * gSa
        Fb = 1.5 * glb / lb[..., None] + 2.0 * G_s[..., None] * Ar + G_S[..., None] * gSb
        uFa, vFb = np.sum(u * Fa, -1), np.sum(v * Fb, -1)
        uAr, vAr = np.sum(u * Ar, -1), np.sum(v * Ar, -1)
        uS, vS = np.sum(u * gSa, -1), np.sum(v * gSb, -1)
        uHv = (-2.0 * G_s * np.sum(u * A * v, -1) + 2.0 * vAr * (-2.0 * G_ss * uAr + G_sS * uS)
               + vS * (-2.0 * G_sS * uAr + G_SS * uS))
        return k0, k0 * uFa, k0 * vFb, k0 * (uFa * vFb + uHv)

    def _terms(self, a, u, b, v):
        a, b = np.broadcast_arrays(_vec(a), _vec(b))
        u = np.broadcast_to(_vec(u), a.shape)
        v = np.broadcast_to(_vec(v), a.shape)
        k0, dv0, vd0, dd0 = self._base_terms(a, u, b, v)
        if self.sigma_field is None:
            return k0, dv0, vd0, dd0
        ma, ga = self.sigma_field.eval(a)
        mb, gb = self.sigma_field.eval(b)
        ua, vb = np.sum(u * ga, -1), np.sum(v * gb, -1)
        return (ma * mb * k0, mb * (ua * k0 + ma * dv0), ma * (vb * k0 + mb * vd0),
                ua * vb * k0 + ua * mb * vd0 + ma * vb * dv0 + ma * mb * dd0)

    def cov(self, a, b):
        return self._terms(a, np.zeros(3), b, np.zeros(3))[0]

    def cov_dv(self, a, u, b):
        return self._terms(a, u, b, np.zeros(3))[1]

    def cov_vd(self, a, b, v):
        return self._terms(a, np.zeros(3), b, v)[2]

    def cov_dd(self, a, u, b, v):
        return self._terms(a, u, b, v)[3]

    def covariance_matrix(self, x1, x2=None, u1=None, u2=None):
        x1, u1, d1, x2, u2, d2 = _observation_rows(x1, x2, u1, u2)
        vv, dv, vd, dd = self._terms(x1[:, None, :], u1[:, None, :], x2[None, :, :],
                                     u2[None, :, :])
        D1, D2 = d1[:, None], d2[None, :]
        return np.where(D1, np.where(D2, dd, dv), np.where(D2, vd, vv))
