"""Mean functions: signed distances, positive outside, each with an analytic gradient.

All evaluate vectorised over points x of shape (..., 3) and return (value (...),
gradient (..., 3)). Primitives follow iq's distance functions. Where a distance is not
differentiable (a sphere's centre, a capsule's axis, a torus's core circle or axis) the
gradient is 0, a valid subgradient; the mean never supplies normals there in practice.

Smooth CSG uses iq's polynomial smooth minimum with blend width k (k <= 0: sharp):
  h = clamp(1/2 + (b - a) / (2k), 0, 1),  smin = h a + (1 - h) b - k h (1 - h)
d smin / dh vanishes wherever h is not clamped, so grad smin = h grad a + (1 - h) grad b
exactly. smax(a, b) = -smin(-a, -b); difference(a, b) = smax(a, -b).
Smooth results are distance bounds, not exact distances (as in iq's formulas).

Transform(child, object_to_world) evaluates s * child(T^-1 x). For a rigid or uniformly
scaled T this is the exact world distance. For a general affine T the distance is not
preserved; s = smallest singular value of T's linear part makes the result a lower bound
(|grad| <= 1, safe for sphere tracing, same zero set and sign), and the true distance lies
between it and sigma_max / sigma_min times it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np


def _vec(x) -> np.ndarray:
    return np.asarray(x, dtype=np.float64)


def _norm_and_dir(v):
    n = np.linalg.norm(v, axis=-1)
    safe = np.where(n > 0.0, n, 1.0)
    return n, np.where((n > 0.0)[..., None], v / safe[..., None], 0.0)


class Mean:
    def value_and_gradient(self, x):
        raise NotImplementedError

    def value(self, x):
        return self.value_and_gradient(x)[0]

    def gradient(self, x):
        return self.value_and_gradient(x)[1]


@dataclass(frozen=True)
class Constant(Mean):
    offset: float = 0.0

    def value_and_gradient(self, x):
        x = _vec(x)
        return np.full(x.shape[:-1], float(self.offset)), np.zeros_like(x)


@dataclass(frozen=True)
class Plane(Mean):
    """max(scale * n . (x - point), min_value); n is normalised (the reference's 'linear')."""
    point: tuple = (0.0, 0.0, 0.0)
    normal: tuple = (1.0, 0.0, 0.0)
    scale: float = 1.0
    min_value: float = -np.inf

    def __post_init__(self):
        if not np.linalg.norm(self.normal) > 0.0:
            raise ValueError("plane: the normal must be a non-zero vector")

    def value_and_gradient(self, x):
        x = _vec(x)
        n = _vec(self.normal) / np.linalg.norm(self.normal)
        v = self.scale * np.sum(n * (x - _vec(self.point)), axis=-1)
        clamped = v < self.min_value
        g = np.where(clamped[..., None], 0.0, self.scale * n * np.ones_like(x))
        return np.maximum(v, self.min_value), g


@dataclass(frozen=True)
class Sphere(Mean):
    center: tuple = (0.0, 0.0, 0.0)
    radius: float = 1.0

    def value_and_gradient(self, x):
        n, d = _norm_and_dir(_vec(x) - _vec(self.center))
        return n - self.radius, d


def _box(p, half):
    """iq's sdBox with its gradient, box centred at the origin."""
    q = np.abs(p) - half
    outside = np.maximum(q, 0.0)
    out_len, out_dir = _norm_and_dir(outside)
    qmax = np.max(q, axis=-1)
    # numpy's argmax takes the first maximum: gp_mean.h breaks ties in the same order
    axis = np.argmax(q, axis=-1)
    inside_dir = np.eye(3)[axis]
    sign = np.copysign(1.0, p)
    is_out = (qmax > 0.0)[..., None]
    return out_len + np.minimum(qmax, 0.0), sign * np.where(is_out, out_dir, inside_dir)


@dataclass(frozen=True)
class Box(Mean):
    half_extents: tuple = (1.0, 1.0, 1.0)
    center: tuple = (0.0, 0.0, 0.0)

    def value_and_gradient(self, x):
        return _box(_vec(x) - _vec(self.center), _vec(self.half_extents))


@dataclass(frozen=True)
class RoundedBox(Mean):
    """A box of the given outer half extents with edges rounded by radius."""
    half_extents: tuple = (1.0, 1.0, 1.0)
    radius: float = 0.1
    center: tuple = (0.0, 0.0, 0.0)

    def __post_init__(self):
        if not 0.0 <= self.radius <= min(self.half_extents):
            raise ValueError(f"rounded_box: radius {self.radius} must lie in "
                             f"[0, smallest half extent {min(self.half_extents)}]")

    def value_and_gradient(self, x):
        v, g = _box(_vec(x) - _vec(self.center), _vec(self.half_extents) - self.radius)
        return v - self.radius, g


@dataclass(frozen=True)
class Torus(Mean):
    """Ring of radius `major` in the xz-plane around the y axis, tube radius `minor`."""
    major: float = 1.0
    minor: float = 0.25
    center: tuple = (0.0, 0.0, 0.0)

    def value_and_gradient(self, x):
        p = _vec(x) - _vec(self.center)
        rho, radial = _norm_and_dir(p[..., [0, 2]])
        q = np.stack([rho - self.major, p[..., 1]], axis=-1)
        qn, qd = _norm_and_dir(q)
        g = np.stack([qd[..., 0] * radial[..., 0], qd[..., 1], qd[..., 0] * radial[..., 1]], -1)
        return qn - self.minor, g


@dataclass(frozen=True)
class Capsule(Mean):
    a: tuple = (0.0, -0.5, 0.0)
    b: tuple = (0.0, 0.5, 0.0)
    radius: float = 0.25

    def value_and_gradient(self, x):
        a, ba = _vec(self.a), _vec(self.b) - _vec(self.a)
        pa = _vec(x) - a
        bb = np.dot(ba, ba)     # a == b degenerates to a sphere
        h = np.clip(np.sum(pa * ba, axis=-1) / (bb if bb > 0 else 1.0), 0.0, 1.0)
        # the closest-point parameter h is stationary, so it carries no gradient term
        n, d = _norm_and_dir(pa - h[..., None] * ba)
        return n - self.radius, d


def smooth_min(a, ga, b, gb, k):
    """Polynomial smooth minimum of two (value, gradient) pairs; k <= 0 is min."""
    if k <= 0.0:
        pick = (a <= b)
        return np.where(pick, a, b), np.where(pick[..., None], ga, gb)
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return h * a + (1.0 - h) * b - k * h * (1.0 - h), h[..., None] * ga + (1.0 - h[..., None]) * gb


def smooth_max(a, ga, b, gb, k):
    v, g = smooth_min(-a, -ga, -b, -gb, k)
    return -v, -g


@dataclass(frozen=True)
class Union(Mean):
    left: Mean
    right: Mean
    k: float = 0.0      # blend width; 0 is the sharp min

    def value_and_gradient(self, x):
        return smooth_min(*self.left.value_and_gradient(x), *self.right.value_and_gradient(x),
                          self.k)


@dataclass(frozen=True)
class Intersection(Mean):
    left: Mean
    right: Mean
    k: float = 0.0

    def value_and_gradient(self, x):
        return smooth_max(*self.left.value_and_gradient(x), *self.right.value_and_gradient(x),
                          self.k)


@dataclass(frozen=True)
class Difference(Mean):
    """left minus right."""
    left: Mean
    right: Mean
    k: float = 0.0

    def value_and_gradient(self, x):
        vb, gb = self.right.value_and_gradient(x)
        return smooth_max(*self.left.value_and_gradient(x), -vb, -gb, self.k)


def SmoothUnion(left, right, k):
    return Union(left, right, k)


def SmoothIntersection(left, right, k):
    return Intersection(left, right, k)


def SmoothDifference(left, right, k):
    return Difference(left, right, k)


def _affine(m) -> np.ndarray:
    m = _vec(m)
    if m.shape == (4, 4):
        m = m[:3]
    if m.shape != (3, 4):
        raise ValueError(f"an affine transform is a 3x4 or 4x4 matrix, got shape {m.shape}")
    return m


@dataclass(frozen=True, eq=False)
class Transform(Mean):
    """child placed by object_to_world (3x4 or 4x4: world = L local + t)."""
    child: Mean
    object_to_world: np.ndarray = field(default_factory=lambda: np.eye(3, 4))

    @property
    def world_to_object(self) -> np.ndarray:
        m = _affine(self.object_to_world)
        inv = np.linalg.inv(m[:, :3])
        return np.concatenate([inv, -(inv @ m[:, 3])[:, None]], axis=1)

    @property
    def distance_scale(self) -> float:
        """Smallest singular value of the linear part (1 for rigid transforms)."""
        return float(np.linalg.svd(_affine(self.object_to_world)[:, :3], compute_uv=False)[-1])

    def value_and_gradient(self, x):
        w2o, s = self.world_to_object, self.distance_scale
        y = _vec(x) @ w2o[:, :3].T + w2o[:, 3]
        v, g = self.child.value_and_gradient(y)
        return s * v, s * (g @ w2o[:, :3])


@dataclass(frozen=True, eq=False)
class GridMean(Mean):
    """Interpolant of samples values[i, j, k] at origin + voxel_size (i, j, k):
    interpolation "linear" (trilinear) or "cubic" (the interpolating tricubic B-spline
    with natural end conditions, cubic_coefficients: C2, so a mirror shows no cell facets,
    and O(h^4) accurate on smooth data; it may overshoot the samples between them).

    values has shape (nx, ny, nz), x index first, each >= 2. The gradient is that of the
    same interpolant (one-sided at cell faces: the cell is floor(u) clamped to the last
    one, as on the device), so value and gradient are consistent. Outside the sample box B,
    with c the closest point of B, d = |x - c| and g = g(c), the mean continues as
        sqrt(g^2 + d^2) where g >= 0,    g + d where g < 0,
    continuous (both are d at g = 0) and increasing away from B. For a signed distance g
    that is positive on B's faces (a mesh with a margin) sqrt(g^2 + d^2) is a lower bound of
    the true distance (Pythagoras: B is convex) and keeps |gradient| <= max(1, the face
    slope), where g + d would reach sqrt(1 + slope^2) (up to sqrt(2)). The gradient there
    combines the interpolant's along the unclamped axes with the unit vector (x - c) / d.
    `lipschitz` is the maximum of |gradient| over all space (ws_intersect.h relies on it
    bounding it). Note that the trilinear interpolant of a distance is steeper than 1
    next to the distance's creases (medial axis): one-sided differences from a cell corner
    add up to ~1.37 near a sphere's centre, at any resolution.
    """
    values: np.ndarray
    origin: tuple = (0.0, 0.0, 0.0)
    voxel_size: float = 1.0
    interpolation: str = "linear"

    def __post_init__(self):
        if self.interpolation not in ("linear", "cubic"):
            raise ValueError(f"grid interpolation must be 'linear' or 'cubic' (got "
                             f"{self.interpolation!r})")
        v = np.asarray(self.values)
        if v.ndim != 3 or min(v.shape) < 2:
            raise ValueError(f"grid values must be a 3-D array (nx, ny, nz) with every "
                             f"dimension >= 2 (got shape {v.shape})")
        # min and max see any NaN (it propagates) or infinity without a temporary per sample
        if not (np.isfinite(v.min()) and np.isfinite(v.max())):
            raise ValueError("grid values contain NaN or infinite samples")
        if not (np.isfinite(self.voxel_size) and self.voxel_size > 0.0):
            raise ValueError(f"grid voxel_size must be positive (got {self.voxel_size})")

    @property
    def shape(self) -> tuple:
        return tuple(np.shape(self.values))

    @cached_property
    def lipschitz(self) -> float:
        """A bound on |gradient| (world units) over all space; >= 1 (the outside term)."""
        if self.interpolation == "cubic":
            return cubic_slope_bound(self.coefficients, self.cell_bounds)
        return grid_slope_bound(np.asarray(self.values, np.float64), float(self.voxel_size))

    @cached_property
    def cell_bounds(self) -> np.ndarray:
        """cell_slope_bounds, computed once (the cubic form takes seconds at 128^3)."""
        return cell_slope_bounds(self)

    @cached_property
    def brick_bounds(self) -> dict:
        """brick edge -> brick_slope_bounds of this grid, filled as they are asked for."""
        return {}

    @cached_property
    def coefficients(self) -> np.ndarray:
        """The cubic B-spline coefficients, (nx + 2, ny + 2, nz + 2) (cubic only)."""
        return cubic_coefficients(np.asarray(self.values, np.float64))

    def value_and_gradient(self, x):
        x = _vec(x)
        # the samples as stored (a bake's are float32): only the gathered corners go to
        # float64, the same numbers without a double copy of the whole grid (the knob's
        # bakes, which the proxy-cut check evaluates, set compile's peak memory there)
        vals = np.asarray(self.values)
        h = float(self.voxel_size)
        hi = np.asarray(vals.shape, np.float64) - 1.0
        u = (x - _vec(self.origin)) / h
        c = np.clip(u, 0.0, hi)
        if self.interpolation == "cubic":
            value, grad = cubic_eval(self.coefficients, c)
            return _continue_outside(value, grad / h, u - c, h)
        cell = np.minimum(np.floor(c), hi - 1.0)
        t = c - cell
        i, j, k = (cell[..., a].astype(np.intp) for a in range(3))
        tx, ty, tz = t[..., 0], t[..., 1], t[..., 2]
        corner = {(a, b, e): vals[i + a, j + b, k + e].astype(np.float64) for a in (0, 1)
                  for b in (0, 1) for e in (0, 1)}

        def lerp(p, q, s):
            return p + (q - p) * s

        # bilinear over the two other axes of the differences along one axis
        def face(f):
            return lerp(lerp(f(0, 0), f(0, 1), tz), lerp(f(1, 0), f(1, 1), tz), ty)

        x0 = face(lambda b, e: corner[0, b, e])
        x1 = face(lambda b, e: corner[1, b, e])
        value = lerp(x0, x1, tx)
        gx = x1 - x0
        gy = lerp(lerp(corner[0, 1, 0] - corner[0, 0, 0], corner[0, 1, 1] - corner[0, 0, 1], tz),
                  lerp(corner[1, 1, 0] - corner[1, 0, 0], corner[1, 1, 1] - corner[1, 0, 1], tz),
                  tx)
        gz = lerp(lerp(corner[0, 0, 1] - corner[0, 0, 0], corner[0, 1, 1] - corner[0, 1, 0], ty),
                  lerp(corner[1, 0, 1] - corner[1, 0, 0], corner[1, 1, 1] - corner[1, 1, 0], ty),
                  tx)
        grad = np.stack([gx, gy, gz], axis=-1) / h
        return _continue_outside(value, grad, u - c, h)


def _continue_outside(value, grad, out, h):
    """The grid's value and gradient at x from those at the clamped point c (GridMean's
    docstring): out = (x - c) / h."""
    grad = np.where(out != 0.0, 0.0, grad)      # clamped axes: g(c(x)) is flat there
    d, direction = _norm_and_dir(out)
    d = h * d
    outside = d > 0.0
    negative = value < 0.0
    r = np.sqrt(value**2 + d**2)
    safe = np.where(outside, r, 1.0)[..., None]
    g_pos = (value[..., None] * grad + d[..., None] * direction) / safe
    v_out = np.where(negative, value + d, r)
    g_out = np.where(negative[..., None], grad + direction, g_pos)
    return (np.where(outside, v_out, value),
            np.where(outside[..., None], g_out, grad))


def _spline_system(n: int) -> np.ndarray:
    """The (n + 2)^2 matrix taking B-spline coefficients to the n samples (interpolation
    rows) and the two natural end conditions (zero second derivative at both ends)."""
    A = np.zeros((n + 2, n + 2))
    for i in range(n):
        A[i, i:i + 3] = (1.0 / 6.0, 4.0 / 6.0, 1.0 / 6.0)
    A[n, 0:3] = (1.0, -2.0, 1.0)
    A[n + 1, n - 1:n + 2] = (1.0, -2.0, 1.0)
    return A


def cubic_coefficients(values: np.ndarray) -> np.ndarray:
    """Coefficients c of the interpolating tricubic B-spline: sample (i, j, k) sits at
    coefficient index (i + 1, j + 1, k + 1), f(u) = sum c[a, b, e] B(u_x + 1 - a) ... with
    the uniform cubic B-spline B. Separable: one (n + 2)-square solve per axis."""
    c = np.asarray(values, np.float64)
    for axis in range(3):
        n = c.shape[axis]
        pad = [(0, 0)] * 3
        pad[axis] = (0, 2)                       # the end-condition rows' zero right sides
        rhs = np.moveaxis(np.pad(c, pad), axis, 0)
        sol = np.linalg.solve(_spline_system(n), rhs.reshape(n + 2, -1))
        c = np.moveaxis(sol.reshape(rhs.shape), 0, axis)
    return c


def _bspline_weights(t):
    """Weights of the four coefficients around a point at fraction t of its cell, and of
    their derivative (per unit of t)."""
    s = 1.0 - t
    w = np.stack([s**3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1, t**3]) / 6
    dw = np.stack([-s**2, 3 * t**2 - 4 * t, -3 * t**2 + 2 * t + 1, t**2]) / 2
    return w, dw


def cubic_eval(coef: np.ndarray, c: np.ndarray):
    """Value and gradient (index units) of the spline at clamped index coordinates c
    (..., 3), as gp_mean.h gp_grid_cubic: cell floor(c) clamped to the last one."""
    hi = np.asarray(coef.shape, np.float64) - 3.0        # the last sample's index
    cell = np.minimum(np.floor(c), hi - 1.0)
    t = c - cell
    base = cell.astype(np.intp)                         # coefficient index of tap 0
    wx, dx = _bspline_weights(t[..., 0])
    wy, dy = _bspline_weights(t[..., 1])
    wz, dz = _bspline_weights(t[..., 2])
    value = np.zeros(c.shape[:-1])
    grad = np.zeros(c.shape)
    for a in range(4):
        for b in range(4):
            for e in range(4):
                q = coef[base[..., 0] + a, base[..., 1] + b, base[..., 2] + e]
                value += wx[a] * wy[b] * wz[e] * q
                grad[..., 0] += dx[a] * wy[b] * wz[e] * q
                grad[..., 1] += wx[a] * dy[b] * wz[e] * q
                grad[..., 2] += wx[a] * wy[b] * dz[e] * q
    return value, grad


# A cell's piece of a uniform cubic B-spline in Bezier form: rows give the four Bezier
# control points from the cell's four B-spline taps; its derivative (a quadratic B-spline
# of the taps' differences) has three, from three differences.
_CUBIC_BEZIER = np.array([[1, 4, 1, 0], [0, 4, 2, 0], [0, 2, 4, 0], [0, 1, 4, 1]]) / 6.0
_QUAD_BEZIER = np.array([[1, 1, 0], [0, 2, 0], [0, 1, 1]]) / 2.0


def _bezier_pieces(a: np.ndarray, axis: int, rows: np.ndarray, cells: int) -> list:
    """For each row of `rows`, the combination of consecutive taps along axis for every
    cell (`cells` of them)."""
    taps = [np.take(a, np.arange(t, t + cells), axis=axis) for t in range(rows.shape[1])]
    return [sum(w * tap for w, tap in zip(row, taps) if w) for row in rows]


def cubic_cell_bounds(coef: np.ndarray, h: float) -> np.ndarray:
    """A bound on |grad| (world units) over each cell of the cubic spline, (n - 1)^3:
    per axis, the largest |Bezier control point| of the cell's derivative (the convex hull
    property: a Bezier piece stays within its control points), a quadratic Bezier form
    along the axis times cubic ones across; |grad| <= the norm of the three. Tighter than
    the coefficient differences themselves, which ring along a distance's ridges."""
    cells = [n - 3 for n in coef.shape]
    total = np.zeros(cells)
    for a in range(3):
        b, c = [x for x in range(3) if x != a]
        best = np.zeros(cells)
        for pa in _bezier_pieces(np.diff(coef, axis=a), a, _QUAD_BEZIER, cells[a]):
            for pb in _bezier_pieces(pa, b, _CUBIC_BEZIER, cells[b]):
                for pc in _bezier_pieces(pb, c, _CUBIC_BEZIER, cells[c]):
                    np.maximum(best, np.abs(pc), out=best)
        total += best * best
    return np.sqrt(total) / h


def cubic_slope_bound(coef: np.ndarray, cell_bounds: np.ndarray) -> float:
    """A bound on |grad| of the cubic GridMean (world units): the largest cell bound
    (cubic_cell_bounds). Outside: as grid_slope_bound, max(a, 1) where the face values are
    >= 0 (convex combinations of the three coefficient layers at the face, all >= 0),
    sqrt(a^2 + 1) otherwise."""
    a2 = float(np.max(cell_bounds)) ** 2
    faces_positive = all(float(np.min(np.take(coef, idx, axis=a))) >= 0.0
                         for a in range(3) for idx in (np.arange(3), np.arange(-3, 0)))
    return float(np.sqrt(max(a2, 1.0) if faces_positive else a2 + 1.0))


def cell_slope_bounds(grid: "GridMean") -> np.ndarray:
    """A bound on |gradient| (world units) inside each cell, (nx - 1, ny - 1, nz - 1):
    trilinear, the exact maximum (_corner_gradients2); cubic, cubic_cell_bounds."""
    h = float(grid.voxel_size)
    if grid.interpolation == "linear":
        return np.sqrt(_corner_gradients2(np.asarray(grid.values, np.float64))) / h
    return cubic_cell_bounds(grid.coefficients, h)


def brick_slope_bounds(grid: "GridMean", brick: int) -> np.ndarray:
    """The largest cell bound in each brick of brick^3 cells (the last bricks partial),
    kept in grid.brick_bounds[brick] (compile/sdf_bake.py caches them there: 1/64 of the
    cell bounds' bytes)."""
    memo = grid.brick_bounds
    if brick not in memo:
        memo[brick] = _brick_maxima(grid.cell_bounds, brick)
    return memo[brick]


def _brick_maxima(cells: np.ndarray, brick: int) -> np.ndarray:
    nb = [-(-n // brick) for n in cells.shape]
    pad = [(0, b * brick - n) for b, n in zip(nb, cells.shape)]
    cells = np.pad(cells, pad, constant_values=0.0)
    return cells.reshape(nb[0], brick, nb[1], brick, nb[2], brick).max(axis=(1, 3, 5))


def _corner_gradients2(values: np.ndarray) -> np.ndarray:
    """max over each cell's corners of |the interpolant's gradient there|^2 (voxel units),
    which is the max over the cell: each partial derivative is linear in every other
    coordinate, so |grad|^2 is convex in each coordinate separately and peaks at a corner.
    Works in 2-D (face cells) and 3-D."""
    nd = values.ndim
    diffs = [np.diff(values, axis=a) for a in range(nd)]
    best = None
    for corner in np.ndindex(*(2,) * nd):
        total = 0.0
        for a in range(nd):
            # the edge along axis a that starts at this corner of every cell
            sl = tuple(slice(None) if b == a else slice(corner[b], values.shape[b] - 1
                                                         + corner[b]) for b in range(nd))
            total = total + diffs[a][sl] ** 2
        best = total if best is None else np.maximum(best, total)
    return best


def grid_slope_bound(values: np.ndarray, h: float, inner2: float | None = None) -> float:
    """The maximum of |grad| of GridMean (world units). Inside: the exact maximum over
    each cell (_corner_gradients2). Outside, over a face cell whose bilinear gradient is at
    most a: |grad| <= max(a, 1) where its samples are >= 0 (then g >= 0 on it, and
    sqrt(g^2 + d^2) mixes slopes a and 1 in a weighted mean), sqrt(a^2 + 1) where any is
    negative (g + d: orthogonal parts add). Edges and corners of the box take their values
    and slopes from face cells, and slope 1 from d: the bound is never below 1.
    inner2: max(_corner_gradients2(values)) when already known (compile/sdf_bake.py takes
    it in slabs: docs/design/bakes.md, 'Slabs'); faces are in double."""
    if inner2 is None:
        inner2 = float(np.max(_corner_gradients2(np.asarray(values, np.float64))))
    bound2 = max(inner2 / h**2, 1.0)
    for axis in range(3):
        for end in (0, -1):
            f = np.asarray(np.take(values, end, axis=axis), np.float64)
            a2 = _corner_gradients2(f) / h**2
            corners = [f[i:f.shape[0] - 1 + i, j:f.shape[1] - 1 + j] for i in (0, 1)
                       for j in (0, 1)]
            negative = np.minimum.reduce(corners) < 0.0
            bound2 = max(bound2, float(np.max(np.where(negative, a2 + 1.0, a2))))
    return float(np.sqrt(bound2))

MEANS = {"constant": Constant, "plane": Plane, "linear": Plane, "sphere": Sphere,
         "box": Box, "rounded_box": RoundedBox, "torus": Torus, "capsule": Capsule,
         "union": Union, "intersection": Intersection, "difference": Difference,
         "transform": Transform, "grid": GridMean}
