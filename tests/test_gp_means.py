"""Mean functions: distances at known points, analytic gradients, CSG and transforms."""
import numpy as np
import pytest

from gpiscl.host.gp import (Box, Capsule, Constant, Difference, Intersection, Plane,
                            RoundedBox, Sphere, Torus, Transform, Union)
from gpiscl.host.gp.means import smooth_min


def _rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


ROT = _rotation([1, 2, 0.5], 0.7)
SHEAR = np.array([[1.2, 0.3, 0.0], [0.0, 0.8, 0.2], [0.1, 0.0, 1.5]])
SPHERE = Sphere(center=(0.2, -0.1, 0.3), radius=0.7)
BOX = Box(half_extents=(0.5, 0.3, 0.8), center=(0.1, 0.0, -0.2))

MEANS = {
    "constant": Constant(0.4),
    "plane": Plane(point=(0.1, 0.2, 0.3), normal=(1.0, 2.0, -1.0), scale=1.5),
    "plane_clamped": Plane(normal=(0.0, 1.0, 0.0), min_value=-0.3),
    "sphere": SPHERE,
    "box": BOX,
    "rounded_box": RoundedBox(half_extents=(0.6, 0.4, 0.5), radius=0.15),
    "torus": Torus(major=0.8, minor=0.2, center=(0.0, 0.1, 0.0)),
    "capsule": Capsule(a=(-0.3, -0.2, 0.1), b=(0.4, 0.5, -0.2), radius=0.25),
    "union": Union(SPHERE, BOX),
    "intersection": Intersection(SPHERE, BOX),
    "difference": Difference(BOX, SPHERE),
    "smooth_union": Union(SPHERE, BOX, k=0.3),
    "smooth_intersection": Intersection(SPHERE, BOX, k=0.3),
    "smooth_difference": Difference(BOX, SPHERE, k=0.3),
    "rigid": Transform(BOX, np.concatenate([ROT, [[0.3], [-0.2], [0.5]]], 1)),
    "affine": Transform(Union(SPHERE, BOX, k=0.2), np.concatenate([SHEAR, [[0.1], [0], [0]]], 1)),
}


@pytest.mark.parametrize("name", MEANS)
def test_gradient_matches_finite_differences(name):
    mean = MEANS[name]
    rng = np.random.default_rng(2)
    x = rng.uniform(-1.5, 1.5, (400, 3))
    eps = 1e-6
    fd = np.stack([(mean.value(x + eps * e) - mean.value(x - eps * e)) / (2 * eps)
                   for e in np.eye(3)], axis=-1)
    g = mean.gradient(x)
    # Rounding gives 1e-16 |f| / eps ~ 1e-9 and truncation eps^2 |f'''| ~ 1e-12. Distances are
    # only piecewise smooth: a difference straddling a crease (medial axis, CSG switch,
    # clamp) would be wrong, but 400 points meet a crease within eps with probability
    # ~400 * 2 eps * (crease area / volume) ~ 1e-3, and the seed is fixed.
    np.testing.assert_allclose(g, fd, atol=1e-8)


@pytest.mark.parametrize("name", ["sphere", "box", "rounded_box", "torus", "capsule", "rigid"])
def test_exact_distances_have_unit_gradient(name):
    x = np.random.default_rng(4).uniform(-1.5, 1.5, (400, 3))
    np.testing.assert_allclose(np.linalg.norm(MEANS[name].gradient(x), axis=1), 1.0, atol=1e-12)


def test_known_distances():
    s = Sphere(center=(1, 0, 0), radius=0.5)
    np.testing.assert_allclose(s.value([[1, 0, 0], [3, 0, 0], [1, 0.5, 0]]), [-0.5, 1.5, 0])
    np.testing.assert_allclose(s.gradient([3, 0, 0]), [1, 0, 0])
    b = Box(half_extents=(1, 2, 3))
    pts = [[0, 0, 0], [2, 0, 0], [2, 3, 0], [0, 0, -3.5], [0.5, 1.9, 0]]
    np.testing.assert_allclose(b.value(pts), [-1, 1, np.sqrt(2), 0.5, -0.1])
    np.testing.assert_allclose(b.gradient(pts[1:]), [[1, 0, 0], [np.sqrt(.5), np.sqrt(.5), 0],
                                                     [0, 0, -1], [0, 1, 0]])
    rb = RoundedBox(half_extents=(1, 1, 1), radius=0.25)
    np.testing.assert_allclose(rb.value([[2, 0, 0], [2, 2, 0]]),
                               [1, np.sqrt(2) * 1.25 - 0.25])
    t = Torus(major=2, minor=0.5)
    np.testing.assert_allclose(t.value([[2, 0, 0], [0, 0, 3], [0, 1, -2], [0, 0, 0]]),
                               [-0.5, 0.5, 0.5, 1.5])
    np.testing.assert_allclose(t.gradient([[0, 1, -2]]), [[0, 1, 0]])
    c = Capsule(a=(0, 0, 0), b=(0, 2, 0), radius=0.5)
    np.testing.assert_allclose(c.value([[1, 1, 0], [0, -1, 0], [0, 3, 0], [0, 1, 0]]),
                               [0.5, 0.5, 0.5, -0.5])
    p = Plane(point=(0, 1, 0), normal=(0, 2, 0), scale=2.0)
    np.testing.assert_allclose(p.value([[5, 3, 1]]), [4.0])


def test_singular_points_have_zero_gradient():
    assert np.all(Sphere().gradient([0, 0, 0]) == 0)
    assert np.all(Capsule().gradient([0, 0.1, 0]) == 0)
    assert np.all(np.isfinite(Torus().gradient([[0, 0.3, 0], [1, 0, 0]])))


def test_csg_values():
    a, b = Sphere(radius=1.0), Sphere(center=(1.5, 0, 0), radius=1.0)
    x = np.array([[0.75, 0, 0], [-0.5, 0, 0], [2.0, 0, 0], [5, 0, 0]])
    va, vb = a.value(x), b.value(x)
    np.testing.assert_allclose(Union(a, b).value(x), np.minimum(va, vb))
    np.testing.assert_allclose(Intersection(a, b).value(x), np.maximum(va, vb))
    np.testing.assert_allclose(Difference(a, b).value(x), np.maximum(va, -vb))
    # iq's smooth min: equal to min where |a - b| >= k, below it by k/4 where a = b
    k = 0.4
    np.testing.assert_allclose(Union(a, b, k).value(x[1:]), np.minimum(va, vb)[1:])
    assert Union(a, b, k).value(x[0]) == pytest.approx(va[0] - k / 4)
    assert Intersection(a, b, k).value(x[0]) == pytest.approx(va[0] + k / 4)
    assert np.all(Union(a, b, k).value(x) <= np.minimum(va, vb) + 1e-15)


def test_smooth_min_is_homogeneous():
    """Needed by the device packing, which scales blend widths by transform scales."""
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=50), rng.normal(size=50)
    ga, gb = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    v, g = smooth_min(a, ga, b, gb, 0.5)
    v2, g2 = smooth_min(3 * a, 3 * ga, 3 * b, 3 * gb, 1.5)
    np.testing.assert_allclose(v2, 3 * v)
    np.testing.assert_allclose(g2, 3 * g)


def test_rigid_transform_preserves_distance():
    m = np.concatenate([ROT, [[0.3], [-0.2], [0.5]]], 1)
    t = Transform(Sphere(radius=0.5), m)
    # a sphere moves to the translation: distance from there
    x = np.random.default_rng(1).normal(size=(20, 3))
    np.testing.assert_allclose(t.value(x), np.linalg.norm(x - m[:, 3], axis=1) - 0.5)
    assert t.distance_scale == pytest.approx(1.0)


def test_scaled_transform_is_exact_and_affine_is_a_lower_bound():
    s = Transform(Sphere(radius=1.0), np.diag([2.0, 2.0, 2.0, 1.0]))
    np.testing.assert_allclose(s.value([[5, 0, 0], [0, 0, 1]]), [3.0, -1.0])
    e = Transform(Sphere(radius=1.0), np.diag([3.0, 1.0, 1.0, 1.0]))  # ellipsoid 3x1x1
    x = np.random.default_rng(3).normal(size=(200, 3)) * 3
    v = e.value(x)
    # true distances to the ellipsoid are at least the lower bound, which is Lipschitz 1
    # and has the ellipsoid's sign
    inside = np.sum((x / [3, 1, 1]) ** 2, axis=1) < 1
    assert np.all((v < 0) == inside)
    assert np.all(np.linalg.norm(e.gradient(x), axis=1) <= 1 + 1e-12)
    assert np.all(np.abs(v) <= np.abs(e.child.value(x / [3, 1, 1]) * 3) + 1e-12)
