"""gp_mean.h's walks over a trilinear grid's cells along a segment (GpCellWalk).

gp_mean_monotone_reach, the monotone stretch that lets fs_mean_step lift the mean cap:
over the stretch it certifies, the mean's difference quotients along random segments
(trilinear grids, transformed) keep one sign with at least the required magnitude; the
stop past the zero set lands there; only one-trilinear-leaf programs qualify; and the
knob's shipped programs are certified on head-on stretches near their surface.

gp_mean_variation_reach, the mean cap's bound along the ray: the mean stays within its
budget of its start value over the reach (dense samples), the reach is never shorter than
the Lipschitz bound's, and it is longer for segments that run along the surface."""
import numpy as np
import pyopencl as cl
import pytest

from gpiscl import load_scene
from gpiscl.host.compile.gpis import build_mean
from gpiscl.host.gp.means import GridMean, Sphere, Transform, Union
from gpiscl.host.layout.constants import FS_MONO_R
from gpiscl.host.layout.gp_records import pack_mean
from gpiscl.host.render.program_sources import PYOPENCL_CL_DIR, join_sources
from gpiscl.testing.wrappers import GP_MEAN_WRAPPER, program

KERNELS = GP_MEAN_WRAPPER + r"""
__kernel void reach(__global const MeanNode* nodes, int count, __global const float* pq,
                    __global const float* m_p, float thr, float band, __global float* out)
{
    int i = get_global_id(0);
    float3 p = vload3(2 * i, pq), q = vload3(2 * i + 1, pq);
    out[i] = gp_mean_is_trilinear_grid(nodes, count)
        ? gp_mean_monotone_reach(nodes, p, q, normalize(q - p), thr, m_p[i], band) : -1.0f;
}

__kernel void variation(__global const MeanNode* nodes, __global const float* pq,
                        __global const float* budget, __global float* out)
{
    int i = get_global_id(0);
    out[i] = gp_mean_variation_reach(nodes, vload3(2 * i, pq), vload3(2 * i + 1, pq),
                                     budget[i]);
}
"""

ROT = np.array([[0.36, 0.48, -0.8], [-0.8, 0.6, 0.0], [0.48, 0.64, 0.6]])
AFFINE = np.concatenate([ROT @ np.diag([1.5, 0.75, 1.0]), [[0.1], [0.2], [0.0]]], 1)


@pytest.fixture(scope="module")
def prg(device):
    src = join_sources(
        (), ("ws_features.h", "ws_posterior.h", "ws_intersect.h")) + KERNELS
    return program(device.ctx, src, [f"-I{PYOPENCL_CL_DIR}", "-DWS_LANES=8"])


def device_reach(device, prg, mean, p, q, thr, band=np.inf):
    """The reach of each segment [p_i, q_i] (float32 end points, returned in float64)."""
    nodes = pack_mean(mean)
    pq = np.ascontiguousarray(np.stack([p, q], 1), np.float32)
    m_p = np.ascontiguousarray(mean.value(pq[:, 0].astype(np.float64)), np.float32)
    out = np.empty(len(p), np.float32)
    mf = cl.mem_flags

    def buf(a):
        return cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a)

    ob = cl.Buffer(device.ctx, mf.WRITE_ONLY, out.nbytes)
    prg["reach"](device.queue, (len(p),), None, buf(nodes), np.int32(len(nodes)), buf(pq),
                 buf(m_p), np.float32(thr), np.float32(min(band, 3e38)), ob)
    cl.enqueue_copy(device.queue, out, ob)
    pq = pq.astype(np.float64)
    return out.astype(np.float64), pq[:, 0], pq[:, 1]


def smooth_grid(interp="linear", seed=12):
    """Samples of a distance to a sphere plus noise: long monotone stretches, turns."""
    rng = np.random.default_rng(seed)
    shape, origin, h = (52, 48, 50), np.array([-1.3, -1.1, -1.2]), 0.05
    axes = [origin[a] + h * np.arange(shape[a]) for a in range(3)]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    v = np.linalg.norm(x - 0.2, axis=-1) - 0.8 + 0.002 * rng.normal(size=shape)
    return GridMean(v, tuple(origin), h, interp)


def quotients(mean, p, q, reach, points=257):
    """The mean's difference quotients per unit length along [p, p + reach (q - p)]."""
    t = np.linspace(0.0, 1.0, points)
    end = p + reach[:, None] * (q - p)
    x = p[:, None] + t[None, :, None] * (end - p)[:, None]
    v = mean.value(x.reshape(-1, 3)).reshape(len(p), -1)
    step = np.linalg.norm(end - p, axis=1)[:, None] * np.diff(t)
    return np.diff(v, axis=1) / np.where(step > 0, step, 1.0)


@pytest.mark.parametrize("name", ["grid", "affine"])
@pytest.mark.parametrize("thr", [0.05, 0.5])
def test_the_certified_stretch_is_monotone_and_steep(device, prg, name, thr):
    """Over [p, p + reach (q - p)] every difference quotient (an average of the slope) has
    the stretch's sign and magnitude >= thr (600 segments of lengths 0.02-1.5 inside,
    across and leaving the grid, 257 points each); the reach is not vacuous."""
    g = smooth_grid()
    mean = g if name == "grid" else Transform(g, AFFINE)
    rng = np.random.default_rng(int(thr * 100) + len(name))
    n = 600
    p = rng.uniform(-1.5, 1.5, (n, 3))
    q = p + rng.normal(size=(n, 3)) * 10.0 ** rng.uniform(-1.7, 0.2, (n, 1))
    reach, p, q = device_reach(device, prg, mean, p, q, thr)
    assert np.all((reach >= 0.0) & (reach <= 1.0))
    some = reach * np.linalg.norm(q - p, axis=1) > 1e-3
    quot = quotients(mean, p[some], q[some], reach[some])
    sign = np.sign(quot[:, :1])
    tol = 1e-3 * (1.0 + thr)
    assert np.all(sign * quot >= thr - tol), np.min(sign * quot - thr)
    print(f"{name} thr {thr}: {some.mean():.0%} of the segments reach > 1e-3, "
          f"{np.mean(reach == 1.0):.0%} whole")
    assert some.mean() > 0.1 and np.mean(reach == 1.0) > 0.05


def test_the_stop_past_the_zero_set_lands_there(device, prg):
    """With a band, a stretch that heads for the zero set stops once the mean's bound is
    past it by the band: where the stop shortened the reach, the mean there is past
    -band (descending from above) or +band (ascending from below)."""
    g = smooth_grid()
    rng = np.random.default_rng(3)
    n = 600
    centre = np.array([0.2, 0.2, 0.2])
    p = centre + rng.normal(size=(n, 3)) * 0.2
    p = centre + (p - centre) / np.linalg.norm(p - centre, axis=1, keepdims=True) \
        * rng.uniform(0.5, 1.1, (n, 1))
    q = p + (centre - p) * rng.uniform(0.3, 1.0, (n, 1)) * np.where(
        rng.random((n, 1)) < 0.5, 1.0, -1.0)
    band = 0.06
    free, p, q = device_reach(device, prg, g, p, q, 0.05)
    stop, _, _ = device_reach(device, prg, g, p, q, 0.05, band)
    assert np.all(stop <= free)
    cut = stop < free
    m_p = g.value(p[cut])
    m_end = g.value(p[cut] + stop[cut, None] * (q[cut] - p[cut]))
    assert cut.sum() > 50
    assert np.all(np.where(m_p > 0, m_end <= -band + 1e-4, m_end >= band - 1e-4))


def test_only_one_trilinear_leaf_qualifies(device, prg):
    g = smooth_grid()
    p, q = np.zeros((1, 3)), np.ones((1, 3))
    for mean in (GridMean(g.values, g.origin, g.voxel_size, "cubic"), Union(g, Sphere()),
                 Sphere()):
        assert device_reach(device, prg, mean, p, q, 0.1)[0][0] == -1.0
    assert device_reach(device, prg, Transform(g, AFFINE), p, q, 0.1)[0][0] >= 0.0


def test_the_knob_is_certified_on_head_on_stretches(device, prg):
    """The knob's shipped programs (two 128^3 bakes, SE l = 1.41, sigma = 0.01): stretches
    of 0.2 units (the uniform 0.99 step) ending on the surface and running along -grad m
    are certified to the surface with |slope| >= FS_MONO_R g (g = sigma / l, the prior
    slope's sd along any direction for SE, k = sigma^2 exp(-r^2 / 2 l^2)) wherever the
    mean is, give or take 10%."""
    scene = load_scene("scenes/knob.json")
    rng = np.random.default_rng(5)
    for shape in (s for s in scene.data["shapes"] if s["type"] == "gpis"):
        mean = build_mean(shape["mean"])
        kern = shape["kernel"]
        g = kern["sigma"] / kern["length_scale"]
        # points on the zero set: random points projected along the gradient
        x = rng.uniform(-1.2, 1.2, (4000, 3)) + [0.0, 0.8, 0.0]
        for _ in range(6):
            v, grad = mean.value_and_gradient(x)
            x = x - (v / np.maximum(np.sum(grad**2, 1), 1e-12))[:, None] * grad
        v, grad = mean.value_and_gradient(x)
        keep = (np.abs(v) < 1e-3) & (np.linalg.norm(grad, axis=1) > 0.5)
        x, grad = x[keep][:500], grad[keep][:500]
        d = grad / np.linalg.norm(grad, axis=1, keepdims=True)
        # from 0.2 outside to 0.05 inside: certified at least to the surface where the
        # mean is (densely sampled difference quotients); the outer shell is thin, so not
        # every such stretch is monotone
        thr = FS_MONO_R * g
        reach, p, q = device_reach(device, prg, mean, x + 0.2 * d, x - 0.05 * d, thr)
        certified = reach >= 0.2 / 0.25
        truth = np.all(quotients(mean, p, q, np.full(len(p), 0.2 / 0.25)) <= -thr, axis=1)
        print(f"{shape['mean']['child']['function']}: {len(x)} stretches, "
              f"{certified.mean():.1%} certified to the surface, {truth.mean():.1%} "
              f"monotone there, FS_MONO_R g = {thr:.4f}")
        assert len(x) > 100 and certified.mean() > 0.7
        assert certified.mean() >= 0.9 * truth.mean()


def device_variation(device, prg, mean, p, q, budget):
    """gp_mean_variation_reach of each segment [p_i, q_i] with budget_i; the reach and the
    float32 end points, in float64."""
    nodes = pack_mean(mean)
    pq = np.ascontiguousarray(np.stack([p, q], 1), np.float32)
    mf = cl.mem_flags

    def buf(a):
        return cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a)

    out = np.empty(len(p), np.float32)
    ob = cl.Buffer(device.ctx, mf.WRITE_ONLY, out.nbytes)
    prg["variation"](device.queue, (len(p),), None, buf(nodes), buf(pq),
                     buf(np.ascontiguousarray(budget, np.float32)), ob)
    cl.enqueue_copy(device.queue, out, ob)
    pq = pq.astype(np.float64)
    return out.astype(np.float64), pq[:, 0], pq[:, 1]


def sphere_segments(rng, n, along):
    """Segments near the smooth grid's sphere (centre 0.2, radius 0.8): random directions,
    or (along) tangent to the sphere at a point near it."""
    centre = np.full(3, 0.2)
    x = rng.normal(size=(n, 3))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    p = centre + x * rng.uniform(0.7, 0.95, (n, 1))
    d = rng.normal(size=(n, 3))
    if along:
        d -= np.sum(d * x, 1, keepdims=True) * x
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return p, p + d * rng.uniform(0.1, 0.5, (n, 1))


@pytest.mark.parametrize("name", ["grid", "affine"])
def test_the_mean_stays_within_its_budget_over_the_reach(device, prg, name):
    """Dense samples (257 a segment) of the mean over the certified stretch differ from
    its start value by at most the budget (float32 rounding: 1e-5); a budget twice as
    large reaches further somewhere, so the walk does not stop for nothing."""
    g = smooth_grid()
    mean = g if name == "grid" else Transform(g, AFFINE)
    rng = np.random.default_rng(3)
    p, q = sphere_segments(rng, 2000, along=False)
    budget = rng.uniform(0.005, 0.2, len(p))
    reach, p, q = device_variation(device, prg, mean, p, q, budget)
    t = np.linspace(0.0, 1.0, 257)
    x = p[:, None] + (t[None, :] * reach[:, None])[..., None] * (q - p)[:, None]
    v = mean.value(x.reshape(-1, 3)).reshape(len(p), -1)
    moved = np.max(np.abs(v - v[:, :1]), axis=1)
    print(f"{name}: mean reach {reach.mean():.3f}, used {np.mean(moved / budget):.1%} of "
          "the budget")
    assert np.all(moved <= budget + 1e-5)
    assert np.all(reach >= 0.0) and np.all(reach <= 1.0)
    wider, _, _ = device_variation(device, prg, mean, p, q, 2.0 * budget)
    assert np.all(wider >= reach) and np.mean(wider > reach) > 0.5


def test_the_reach_beats_the_lipschitz_bound_along_the_surface(device, prg):
    """Inside the sample box the walk's bound is at most the Lipschitz bound times the
    length (Cauchy-Schwarz over the axes), so its reach is at least budget / lipschitz;
    along the surface (tangent segments) it is several times longer on average."""
    g = smooth_grid()
    rng = np.random.default_rng(4)
    gain = {}
    for along in (False, True):
        p, q = sphere_segments(rng, 2000, along)
        budget = np.full(len(p), 0.03)
        reach, p, q = device_variation(device, prg, g, p, q, budget)
        length = np.linalg.norm(q - p, axis=1)
        lip_reach = np.minimum(budget / g.lipschitz / length, 1.0)
        assert np.all(reach >= lip_reach * (1.0 - 1e-4) - 1e-6)
        gain[along] = np.mean(reach / lip_reach)
    print(f"reach / Lipschitz reach: random directions {gain[False]:.2f}, along the "
          f"surface {gain[True]:.2f}")
    assert gain[True] > 2.0 and gain[True] > gain[False]
