"""fs_grid_field_reach (fs_sampling.h): how far along a segment a sigma grid is certified to
rise by less than one budget and fall by less than another, cell by cell along the segment.
fs_field_cap takes the function-space step's sigma cap from it, so it must be sound (the
field, evaluated densely on the host, stays within the budgets up to the returned point)
and never shorter than the bound over the segment's index box (fs_field_slope) that it
replaced."""
import numpy as np
import pyopencl as cl
import pytest

from gpiscl.host.gp.kernels import GridField, NonStationary, SquaredExponential
from gpiscl.host.gp.means import Sphere
from gpiscl.host.render.flight_samples import pack_model
from gpiscl.host.render.program_sources import fs_sampler_options
from gpiscl.testing.wrappers import buffer, sampler_program

WRAPPER = r"""
__kernel void field_reach(__global const GpKernel* kp, __global const MeanNode* mean,
                          __global const float* seg, __global const float* budget,
                          __global float* out)
{
    int i = get_global_id(0);
    GpKernel p = *kp;
    __global const MeanNode* g = mean + p.sigma_grid;
    float3 a = vload3(2 * i, seg), b = vload3(2 * i + 1, seg);
    out[3 * i] = fs_grid_field_reach(g, a, b, budget[2 * i], budget[2 * i + 1]);
    double2 r = fs_field_slope(GP_FIELD_GRID, p.sigma_p0, p.sigma_p1, g, convert_double3(a),
                               convert_double3(b));
    out[3 * i + 1] = (float)r.x;
    out[3 * i + 2] = (float)r.y;
}
"""

ORIGIN, VOXEL, SHAPE = np.array([-0.6, -0.5, -0.55]), 0.05, (24, 20, 22)


@pytest.fixture(scope="module")
def prg(device):
    return sampler_program(device.ctx, WRAPPER, fs_sampler_options(8, 8))


def field():
    """A bunny_grid-like sigma multiplier: 0.05 on one side of a plane, 1 on the other,
    a ramp of about two voxels between them, and smooth noise."""
    rng = np.random.default_rng(5)
    axes = [ORIGIN[k] + VOXEL * np.arange(SHAPE[k]) for k in range(3)]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    ramp = 1.0 / (1.0 + np.exp(-(x @ np.array([0.8, 0.36, -0.48])) / 0.04))
    v = 0.05 + 0.95 * ramp + 0.04 * rng.uniform(size=SHAPE)
    return GridField(v.astype(np.float32), tuple(ORIGIN), VOXEL)


def segments(n, rng):
    """n segments starting inside the sample box, 0.02 to 0.5 units long, ending inside it."""
    lo, hi = ORIGIN + 1e-3, ORIGIN + VOXEL * (np.array(SHAPE) - 1) - 1e-3
    a = rng.uniform(lo, hi, (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    b = a + d * rng.uniform(0.02, 0.5, (n, 1))
    keep = np.all((b > lo) & (b < hi), axis=1)
    return a[keep], b[keep]


def device_reach(device, prg, gf, a, b, budget):
    packed = pack_model(NonStationary(SquaredExponential(sigma=0.1, length_scale=0.2),
                                      sigma_field=gf), Sphere(radius=0.3))
    seg = np.stack([a, b], 1).astype(np.float32)
    out = np.empty((len(a), 3), np.float32)
    ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    prg["field_reach"](device.queue, (len(a),), None, buffer(device, packed.kernel),
                       buffer(device, packed.nodes), buffer(device, seg),
                       buffer(device, budget.astype(np.float32)), ob)
    cl.enqueue_copy(device.queue, out, ob)
    return out


def test_the_field_moves_no_faster_than_its_budgets_spread_over_the_reach(device, prg):
    """3000 segments, rise budget the field's value at the start and fall budget half of it
    (fs_field_cap's): along [a, a + f (b - a)] the field, at 2000 points, rises and falls by
    at most the budgets times the fraction of the reach covered (to float rounding): the
    largest rate times the reach stays within the budget, so a rise cannot gather at the
    reach's end (a walk that added up each cell's rise instead fails it)."""
    gf, rng = field(), np.random.default_rng(11)
    a, b = segments(3000, rng)
    a, b = a.astype(np.float32).astype(float), b.astype(np.float32).astype(float)
    va = gf.eval(a)[0]
    budget = np.stack([va, 0.5 * va], 1)
    f = device_reach(device, prg, gf, a, b, budget)[:, 0]
    assert np.all((f >= 0.0) & (f <= 1.0))
    assert 0.2 < np.mean(f < 1.0) < 0.9          # both kinds of segment are tested
    s = np.linspace(0.0, 1.0, 2000)
    for i in range(len(a)):
        v = gf.eval(a[i] + (f[i] * s)[:, None] * (b[i] - a[i]))[0]
        assert np.all(v - va[i] <= budget[i, 0] * s * (1 + 1e-4) + 1e-6), i
        assert np.all(va[i] - v <= budget[i, 1] * s * (1 + 1e-4) + 1e-6), i


def test_the_reach_is_never_shorter_than_the_box_bound(device, prg):
    """Against fs_field_slope's rates over the segment's index box (fs_field_cap's bound
    before): the walk reaches at least as far on every segment whose box it could scan,
    unless it stopped at a kink (a cell face, FS_FIELD_KINK), and more than 1.2x as far
    on many where the box's bound stops short of the end."""
    gf, rng = field(), np.random.default_rng(12)
    a, b = segments(3000, rng)
    va = gf.eval(a.astype(np.float32).astype(float))[0]
    budget = np.stack([va, 0.5 * va], 1)
    out = device_reach(device, prg, gf, a, b, budget)
    f, fall, rise = out[:, 0], out[:, 1].astype(float), out[:, 2].astype(float)
    scanned = np.isfinite(fall)
    with np.errstate(divide="ignore"):
        box = np.minimum(np.minimum(budget[:, 1] / fall, budget[:, 0] / rise), 1.0)
    assert scanned.sum() > 1000
    u = (a + f[:, None] * (b - a) - ORIGIN) / VOXEL      # where the walk stopped, in cells
    at_face = np.any(np.abs(u - np.round(u)) < 1e-3, axis=1)
    assert np.all((f >= box * (1 - 1e-5) - 1e-6) | at_face)
    assert 0.02 < np.mean((f < box * (1 - 1e-5) - 1e-6)[scanned]) < 0.5    # kinks stop some
    short = scanned & (box < 1.0)
    assert np.mean(f[short] > 1.2 * box[short]) > 0.3      # 0.41 on this noisy field


def test_a_segment_leaving_the_sample_box_is_left_to_the_box_bound(device, prg):
    """Budgets the field cannot spend: the walk reaches the sample box's face (first
    segment) or cannot start (second), and leaves the segment to the box bound."""
    a = np.array([[0.0, 0.0, 0.0], [-0.7, 0.0, 0.0]])
    b = np.array([[0.0, 0.0, 0.9], [0.0, 0.0, 0.0]])
    f = device_reach(device, prg, field(), a, b, np.full((2, 2), 1e6))[:, 0]
    assert np.all(f == -1.0)


def test_a_try_ends_at_a_kink_of_the_field(device, prg):
    """sigma rising at 4.95 a unit to x = 3 and flat after (0.05 voxels): a segment from
    x = 2.96 to 3.5 with fs_field_cap's budgets (sigma at its start, 0.81) would reach
    0.30 of the way at that rate, but the slope's jump at x = 3 (4.95 x 0.54 = 2.7, above
    FS_FIELD_KINK x 0.81) ends it at that face, 0.074 of the way. Along the flat part
    alone nothing stops it."""
    vs = 0.05
    x = np.arange(0.0, 6.0 + vs / 2, vs)
    v = 0.01 + 0.99 * np.clip((x - 2.8) / 0.2, 0.0, 1.0)
    gf = GridField(np.repeat(np.repeat(v[:, None, None], 3, 1), 3, 2).astype(np.float32),
                   (0.0, -vs, -vs), vs)
    a = np.array([[2.96, 0.01, 0.0], [3.1, 0.01, 0.0]])
    b = np.array([[3.5, 0.01, 0.0], [3.9, 0.01, 0.0]])
    va = gf.eval(a)[0]
    f = device_reach(device, prg, gf, a, b, np.stack([va, 0.5 * va], 1))[:, 0]
    assert abs(f[0] - 0.04 / 0.54) < 1e-4
    assert f[1] == 1.0
