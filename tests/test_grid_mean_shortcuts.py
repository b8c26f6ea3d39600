"""gp_mean.h's short ways for baked grids, checked against the long ones they replace.

gp_mean_value takes a program of one grid leaf (trilinear or cubic) without the gradient
and the interpreter: its value must be gp_mean_eval's, bit for bit (the images depend on it), inside
and outside the sample box, under a transform, and programs that do not qualify must fall
back. gp_div_small (gp_grid_slope_on's brick indices) must be integer division."""
import numpy as np
import pyopencl as cl
import pytest

from gpiscl.host.gp.means import GridMean, Sphere, Transform, Union
from gpiscl.host.layout.gp_records import pack_mean
from gpiscl.host.render.program_sources import PYOPENCL_CL_DIR, join_sources
from gpiscl.testing.wrappers import buffer, program

KERNELS = r"""
__kernel void values(__global const MeanNode* nodes, int count, __global const float* x,
                     __global float2* out)
{
    int i = get_global_id(0);
    float3 g;
    out[i] = (float2)(gp_mean_value(nodes, count, vload3(i, x)),
                      gp_mean_eval(nodes, count, vload3(i, x), &g));
}

__kernel void div_small(__global const int* a, int b, __global int* out)
{
    int i = get_global_id(0);
    out[i] = gp_div_small((int3)(a[i]), (float)b).x;
}
"""

AFFINE = np.array([[0.54, 0.36, -0.8, 0.1], [-1.2, 0.45, 0.0, 0.2], [0.72, 0.48, 0.6, 0.0]])


@pytest.fixture(scope="module")
def prg(device):
    src = join_sources((), ("ws_features.h", "ws_posterior.h", "ws_intersect.h")) + KERNELS
    return program(device.ctx, src, [f"-I{PYOPENCL_CL_DIR}", "-DWS_LANES=8"])


def grid(interp="linear"):
    """Distances to a sphere with noise on a 30 x 26 x 28 grid over about [-1, 1]^3."""
    rng = np.random.default_rng(7)
    shape, origin, h = (30, 26, 28), np.array([-1.0, -0.9, -0.95]), 0.07
    axes = [origin[a] + h * np.arange(shape[a]) for a in range(3)]
    x = np.stack(np.meshgrid(*axes, indexing="ij"), -1)
    v = np.linalg.norm(x, axis=-1) - 0.6 + 0.01 * rng.normal(size=shape)
    return GridMean(v, tuple(origin), h, interp)


def device_values(device, prg, mean, x):
    nodes = pack_mean(mean)
    out = np.empty((len(x), 2), np.float32)
    ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    prg["values"](device.queue, (len(x),), None, buffer(device, nodes), np.int32(len(nodes)),
                  buffer(device, np.asarray(x, np.float32)), ob)
    cl.enqueue_copy(device.queue, out, ob)
    return out


@pytest.mark.parametrize("name", ["grid", "affine", "cubic", "union"])
def test_the_value_alone_is_the_programs_value(device, prg, name):
    """20000 points, a fifth of them outside the sample box (the outside continuation):
    gp_mean_value equals gp_mean_eval's value exactly, shortcut (one trilinear leaf,
    transformed or not, and a cubic one) or fallback (a union)."""
    g = grid()
    mean = {"grid": g, "affine": Transform(g, AFFINE), "cubic": grid("cubic"),
            "union": Union(g, Sphere(radius=0.3))}[name]
    x = np.random.default_rng(3).uniform(-1.4, 1.4, (20000, 3))
    out = device_values(device, prg, mean, x)
    assert np.all(np.isfinite(out))
    assert np.array_equal(out[:, 0].view(np.int32), out[:, 1].view(np.int32))
    # and it is the mean: the host's value to float rounding
    assert np.allclose(out[:, 0], mean.value(x), atol=1e-5)


def test_brick_indices_by_float_division_are_integer_division(device, prg):
    a = np.arange(1 << 16, dtype=np.int32)
    out = np.empty_like(a)
    ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    for b in (1, 2, 3, 4, 5, 7, 8, 16, 31, 64):
        prg["div_small"](device.queue, (len(a),), None, buffer(device, a), np.int32(b), ob)
        cl.enqueue_copy(device.queue, out, ob)
        assert np.array_equal(out, a // b), b
