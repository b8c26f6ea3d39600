"""The authors' knob as a procedural mean (gp/knob.py): its restated formulas, its grid."""
import numpy as np
import pytest

from gpiscl.host.gp.knob import BOUNDS, FUNCTIONS, knob_grid


def test_inner_sphere_and_shell_partition_the_knob():
    rng = np.random.default_rng(0)
    p = rng.uniform(-1.2, 1.2, (20000, 3))
    assert np.allclose(FUNCTIONS["knob_inner"](p), np.linalg.norm(p, axis=1) - 0.6)
    inside = FUNCTIONS["knob"](p) < 0
    # knob = min(shell, inner ball) up to the torus groove that cuts both
    either = (FUNCTIONS["knob_outer"](p) < 0) | (FUNCTIONS["knob_inner"](p) < 0)
    assert np.mean(inside != either) < 0.01
    assert np.all(~(FUNCTIONS["knob_outer"](p) < 0) | (FUNCTIONS["knob_inner"](p) >= -1e-6))


@pytest.mark.parametrize("name", sorted(FUNCTIONS))
def test_zero_set_lies_inside_the_bake_bounds(name):
    lo, hi = BOUNDS[name]
    g = np.linspace(-1.6, 1.6, 97)
    p = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1)
    inside = p[FUNCTIONS[name](p) < 0]
    assert len(inside) > 0
    voxel = g[1] - g[0]
    assert np.all(inside.min(0) >= lo - voxel) and np.all(inside.max(0) <= hi + voxel)
    # the base reaches the floor: the knob stands on y = -0.8 before its +0.8 lift
    if name != "knob_inner":
        assert inside[:, 1].min() == pytest.approx(-0.8, abs=2 * voxel)


def test_grid_interpolates_the_function():
    grid = knob_grid("knob", 96)
    lo, hi = BOUNDS["knob"]
    rng = np.random.default_rng(1)
    p = rng.uniform(lo, hi, (5000, 3))
    exact = FUNCTIONS["knob"](p)
    value, _ = grid.value_and_gradient(p)
    # trilinear interpolation is a convex combination of corners at most h sqrt(3) away, so
    # for a function of slope <= S (the grid's bound) |error| <= S h sqrt(3) everywhere
    h = grid.voxel_size
    assert np.max(np.abs(value - exact)) <= grid.lipschitz * h * np.sqrt(3)
    # where the distance is smooth the error is second order: <= 3 h^2 |f''|_max / 8 per
    # axis sum, |f''| <= 1 / r for surfaces of curvature radius r; the smallest feature is
    # the groove torus (minor radius 0.05 * 0.8), so a typical point is far below this
    assert np.median(np.abs(value - exact)) < 3 * h * h / (8 * 0.04)
