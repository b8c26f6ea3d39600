"""gp_kernel.h and gp_mean.h on the device against the numpy references."""

import numpy as np
import pyopencl as cl
import pytest

from gpiscl.host.gp import (Box, Capsule, Constant, Difference, Intersection,
                            LocallyPeriodic, Periodic, Plane, RationalQuadratic,
                            RoundedBox, Sphere, Matern32, Matern52, SquaredExponential, ThinPlate, Torus,
                            Transform, Union)
from gpiscl.host.layout import gp_records
from gpiscl.host.render.program_sources import kernel_source
from gpiscl.testing.wrappers import GP_COVARIANCE_WRAPPER, GP_MEAN_WRAPPER


WRAPPERS = GP_COVARIANCE_WRAPPER + GP_MEAN_WRAPPER

# Parameters are exact in float32 so the double build can be compared tightly.
ANISO = (1.0, 0.5, 2.0)
KERNELS = [
    SquaredExponential(sigma=1.25, length_scale=0.75, aniso=ANISO),
    RationalQuadratic(sigma=0.875, length_scale=1.125, alpha=0.625, aniso=ANISO),
    Periodic(sigma=1.125, length_scale=0.875, w=0.625, aniso=ANISO),
    LocallyPeriodic(sigma=0.75, length_scale=1.25, w=0.5, se_length_scale=1.5, aniso=ANISO),
    ThinPlate(sigma=0.5, radius=4.0, aniso=ANISO),
    Matern32(sigma=1.125, length_scale=0.875, aniso=ANISO),
    Matern52(sigma=0.875, length_scale=0.625, aniso=ANISO),
]


def _program(device, real):
    src = ["#pragma OPENCL EXTENSION cl_khr_fp64 : enable", gp_records.c_declarations()]
    src += [kernel_source(h) for h in ("gp_kernel.h", "gp_mean.h")]
    return cl.Program(device.ctx, "\n".join(src) + WRAPPERS).build(
        options=[f"-DGP_REAL={real}"])


@pytest.fixture(scope="module", params=["float", "double"])
def program(request, device):
    prg = _program(device, request.param)
    return request.param, {k.function_name: k for k in prg.all_kernels()}


def _buffer(device, array):
    return cl.Buffer(device.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                     hostbuf=np.ascontiguousarray(array))


@pytest.mark.parametrize("kernel", KERNELS, ids=lambda k: k.kind)
def test_kernel_covariances_match_host(device, program, kernel):
    real, prg = program
    dtype = np.float32 if real == "float" else np.float64
    rng = np.random.default_rng(8)
    n = 256
    a, b = rng.uniform(-1, 1, (n, 3)), rng.uniform(-1, 1, (n, 3))
    b[:16] = a[:16]                          # zero lag: the exact limits, no NaN
    u, v = rng.standard_normal((n, 3)), rng.standard_normal((n, 3))
    a, u, b, v = (x.astype(dtype) for x in (a, u, b, v))
    out = np.empty((n, 8), dtype)
    out_buf = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    prg["covariances"](device.queue, (n,), None, _buffer(device, gp_records.pack_kernel(kernel)),
                    *(_buffer(device, x) for x in (a, u, b, v)), out_buf)
    cl.enqueue_copy(device.queue, out, out_buf)
    a, u, b, v = (x.astype(np.float64) for x in (a, u, b, v))
    vv, dv = kernel.cov(a, b), kernel.cov_dv(a, u, b)
    vd, dd = kernel.cov_vd(a, b, v), kernel.cov_dd(a, u, b, v)
    expected = np.stack([vv, dv, vd, dd, vv, dv, vd, dd], axis=1)
    # Errors scale with each covariance's natural size (k(0), gradient variance, their
    # geometric mean) times |u||v| <= 3 here. float: a few ulp (1.2e-7) amplified by
    # arguments up to ~10 in exp/sin; double: the same at 2.2e-16.
    g = kernel.gradient_variance().max()
    scale = np.array([1, 3, 3, 9, 1, 3, 3, 9]) * np.array(
        [kernel.variance, np.sqrt(kernel.variance * g), np.sqrt(kernel.variance * g), g] * 2)
    tol = 4e-6 if real == "float" else 1e-12
    assert np.all(np.isfinite(out))
    err = np.max(np.abs(out - expected) / scale)
    assert err < tol, err


ROT = np.array([[0.36, 0.48, -0.8], [-0.8, 0.6, 0.0], [0.48, 0.64, 0.6]])
SPHERE = Sphere(center=(0.25, -0.125, 0.25), radius=0.625)
BOX = Box(half_extents=(0.5, 0.25, 0.75), center=(0.125, 0.0, -0.25))
CSG = Difference(
    Union(Transform(Union(SPHERE, BOX, k=0.25),
                    np.concatenate([ROT * 1.5, [[0.25], [0.0], [-0.5]]], 1)),
          Union(Torus(major=0.75, minor=0.125),
                Union(Capsule(a=(-1, 0, 0), b=(0, 1, 0.5), radius=0.125),
                      Intersection(Plane(normal=(0, 1, 0), point=(0, -0.5, 0), scale=0.5,
                                         min_value=-0.25),
                                   RoundedBox(half_extents=(0.5, 0.5, 0.5), radius=0.125,
                                              center=(0.5, -0.5, 0.5)), k=0.125)))),
    Transform(Sphere(radius=0.375), np.diag([2.0, 1.0, 0.5, 1.0])), k=0.0625)

MEANS = {"constant": Constant(0.5), "plane": Plane(normal=(1, 2, 2), scale=2.0),
         "sphere": SPHERE, "box": BOX, "rounded_box": RoundedBox(radius=0.25),
         "torus": Torus(), "capsule": Capsule(), "csg": CSG}


@pytest.mark.parametrize("name", MEANS)
def test_mean_values_and_gradients_match_host(device, program, name):
    _, prg = program
    mean = MEANS[name]
    nodes = gp_records.pack_mean(mean)
    x = np.random.default_rng(9).uniform(-1.5, 1.5, (1000, 3)).astype(np.float32)
    out = np.empty((len(x), 4), np.float32)
    out_buf = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, out.nbytes)
    prg["mean_eval"](device.queue, (len(x),), None, _buffer(device, nodes), np.int32(len(nodes)),
                  _buffer(device, x), out_buf)
    cl.enqueue_copy(device.queue, out, out_buf)
    value, grad = mean.value_and_gradient(x.astype(np.float64))
    # float32 evaluation of O(1) distances with float32-rounded maps: a few ulp, ~5e-7;
    # smooth blend weights divide such errors by k >= 0.0625, which gradients inherit
    np.testing.assert_allclose(out[:, 3], value, atol=4e-6)
    np.testing.assert_allclose(out[:, :3], grad, atol=2e-5)


def test_csg_packing_keeps_the_stack_small():
    nodes = gp_records.pack_mean(CSG)
    chain = Sphere()
    for i in range(30):                          # right-deep: needs 2 entries after swaps
        chain = Union(Sphere(center=(i, 0, 0)), chain)
    assert gp_records._stack_need(chain) == 2
    # every union but the innermost (two single leaves) emits its deeper right child first
    assert np.sum(gp_records.pack_mean(chain)["flags"]) == 29
    def balanced(depth):
        return Sphere() if depth == 0 else Union(balanced(depth - 1), balanced(depth - 1))
    gp_records.pack_mean(balanced(gp_records.MEAN_STACK_DEPTH - 1))
    with pytest.raises(ValueError, match="stack"):
        gp_records.pack_mean(balanced(gp_records.MEAN_STACK_DEPTH))
    assert nodes.dtype == gp_records.MEAN_NODE.dtype
