"""The rough conductor (bsdf/rough_conductor.h): device against its numpy twin, Fresnel limits,
reciprocity, sampling consistent with evaluation, and NEE+MIS against BSDF sampling in
renders of a metal sphere and of a GPIS with the rough conductor as its micro-BSDF."""
import math

import numpy as np
import pyopencl as cl
import pytest

from gpiscl import render_result
from gpiscl.testing.reference import rough_conductor as RC
from gpiscl.host.kinds.conductors import CONDUCTORS
from gpiscl.host.render.program_sources import PYOPENCL_CL_DIR, join_sources
from gpiscl.testing.wrappers import program
from gpiscl.testing.stats import assert_agree, z_threshold

WRAPPER = r"""
__kernel void rc_eval(__global const float* p, __global const float* n,
                      __global const float* v, __global const float* l, __global float* out,
                      int count)
{
    int i = get_global_id(0);
    if (i >= count) return;
    float pdf;
    float3 f = beckmann_conductor_eval(vload3(0, p), vload3(1, p), vload3(2, p), p[9],
                                    vload3(i, n), vload3(i, v), vload3(i, l), &pdf);
    vstore4((float4)(f, pdf), i, out);
}

__kernel void rc_sample(__global const float* p, __global const float* n,
                        __global const float* v, __global const float* u,
                        __global float* out, int count)
{
    int i = get_global_id(0);
    if (i >= count) return;
    float3 l;
    float pdf, pdf_eval;
    float3 w = beckmann_conductor_sample(vload3(0, p), vload3(1, p), vload3(2, p), p[9],
                                      vload3(i, n), vload3(i, v), vload2(i, u), &l, &pdf);
    float3 f = beckmann_conductor_eval(vload3(0, p), vload3(1, p), vload3(2, p), p[9],
                                    vload3(i, n), vload3(i, v), l, &pdf_eval);
    __global float* o = out + 12 * i;
    vstore4((float4)(w, pdf), 0, o);
    vstore4((float4)(l, pdf_eval), 1, o);
    vstore4((float4)(f, 0.0f), 2, o);
}
"""
CU = CONDUCTORS["Cu"]


@pytest.fixture(scope="module")
def prg(device):
    # the renderer's headers, then the wrappers (Program puts extra C before them)
    return program(device.ctx, join_sources([]) + WRAPPER, [f"-I{PYOPENCL_CL_DIR}"])


def _params(alpha, albedo=(1.0, 1.0, 1.0), eta_k=CU):
    return np.array([*albedo, *eta_k[0], *eta_k[1], alpha], np.float32)


def _run(device, prg, name, width, *arrays):
    count = len(arrays[1])
    bufs = [cl.Buffer(device.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                      hostbuf=np.ascontiguousarray(a, np.float32)) for a in arrays]
    out = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 4 * width * count)
    prg[name](device.queue, (count,), None, *bufs, out, np.int32(count))
    res = np.empty((count, width), np.float32)
    cl.enqueue_copy(device.queue, res, out)
    return res.astype(np.float64)


def _unit(x):
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def _hemisphere(rng, count):
    """Uniform directions about +z (pdf 1 / 2 pi)."""
    z = rng.uniform(0, 1, count)
    phi = rng.uniform(0, 2 * np.pi, count)
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


def test_device_matches_the_numpy_twin(device, prg):
    rng = np.random.default_rng(1)
    count = 4000
    n = _unit(rng.normal(size=(count, 3)))
    v, l = _unit(rng.normal(size=(count, 3))), _unit(rng.normal(size=(count, 3)))
    v = np.where(np.sum(n * v, -1, keepdims=True) < 0, -v, v)   # mostly valid pairs
    l = np.where(np.sum(n * l, -1, keepdims=True) < 0, -l, l)
    for alpha in (0.05, 0.3, 0.9):
        p = _params(alpha, (0.9, 0.8, 0.7))
        dev = _run(device, prg, "rc_eval", 4, p, n, v, l)
        f, pdf = RC.eval_fcos(p[:3], p[3:6], p[6:9], alpha, n, v, l)
        # float32 evaluation: D spans decades at small alpha, so compare relatively
        np.testing.assert_allclose(dev[:, :3], f, rtol=2e-3, atol=1e-6 * f.max())
        np.testing.assert_allclose(dev[:, 3], pdf, rtol=2e-3, atol=1e-6 * pdf.max())
        # reciprocity: f(v, l) = f(l, v)
        back = _run(device, prg, "rc_eval", 4, p, n, l, v)
        cv, cl_ = np.sum(n * v, -1), np.sum(n * l, -1)
        ok = (cv > 0.05) & (cl_ > 0.05)
        np.testing.assert_allclose((dev[ok, :3] / cl_[ok, None]),
                                   back[ok, :3] / cv[ok, None], rtol=2e-3, atol=1e-6)


def test_fresnel_limits():
    eta, k = np.asarray(CU[0]), np.asarray(CU[1])
    normal = ((eta - 1) ** 2 + k**2) / ((eta + 1) ** 2 + k**2)
    np.testing.assert_allclose(RC.fresnel_conductor(1.0, eta, k), normal, rtol=1e-12)
    np.testing.assert_allclose(RC.fresnel_conductor(0.0, eta, k), 1.0, rtol=1e-12)
    c = np.linspace(0, 1, 50)
    F = RC.fresnel_conductor(c, eta, k)
    assert np.all((F >= 0) & (F <= 1))


@pytest.mark.parametrize("alpha", [0.05, 0.3, 0.8])
def test_sampling_is_consistent_with_evaluation(device, prg, alpha):
    """For three viewing angles: the mean sampling weight (f cos / pdf) and a uniform
    hemisphere estimate of the directional albedo (2 pi f cos) agree within their
    standard errors; the fraction of samples that stay above the surface equals the
    uniform estimate of the pdf's integral; the sampler's pdf equals the evaluator's."""
    rng = np.random.default_rng(int(alpha * 100))
    count = 200_000
    z = z_threshold(3 * 3 * 2)
    p = _params(alpha)
    for cos_v in (0.95, 0.5, 0.15):
        v = np.array([math.sqrt(1 - cos_v**2), 0.0, cos_v])
        n = np.tile([0.0, 0.0, 1.0], (count, 1))
        vs = np.tile(v, (count, 1))
        out = _run(device, prg, "rc_sample", 12, p, n, vs, rng.uniform(0, 1, (count, 2)))
        w, pdf, pdf_eval = out[:, 0], out[:, 3], out[:, 7]
        valid = pdf > 0
        np.testing.assert_allclose(pdf[valid], pdf_eval[valid], rtol=2e-3)
        np.testing.assert_allclose(out[valid, 0:3], out[valid, 8:11] / pdf[valid, None],
                                   rtol=3e-3)
        l = _hemisphere(rng, count)
        f, pdf_u = RC.eval_fcos(p[:3], p[3:6], p[6:9], alpha, n, vs, l)
        est = 2 * np.pi * f[:, 0]
        a, b = w.mean(), est.mean()
        se = math.hypot(w.std() / math.sqrt(count), est.std() / math.sqrt(count))
        assert abs(a - b) < z * se, (cos_v, a, b, se)
        mass = 2 * np.pi * pdf_u
        fa, fb = valid.mean(), mass.mean()
        se = math.hypot(math.sqrt(fa * (1 - fa) / count), mass.std() / math.sqrt(count))
        assert abs(fa - fb) < z * se + 1e-12, (cos_v, fa, fb, se)


def _metal_scene(nee, spp, gpis=False):
    metal = {"type": "rough_conductor", "material": "Au", "roughness": 0.4}
    ball = ({"type": "gpis", "proxy": {"type": "sphere", "radius": 0.9},
             "mean": {"type": "sphere", "radius": 0.6},
             "kernel": {"type": "squared_exponential", "sigma": 0.05, "length_scale": 0.3},
             "sampler": {"type": "function_space"}, "bsdf": metal}
            if gpis else {"type": "sphere", "center": [0, 0, 0], "radius": 0.6, "bsdf": metal})
    return {"camera": {"position": [0, 0.4, 2.6], "look_at": [0, 0, 0], "fov": 40,
                       "resolution": [16, 16]},
            "render": {"spp": spp, "seed": 5, "max_depth": 4, "nee": nee},
            "shapes": [ball, {"type": "rectangle", "center": [0, -0.6, 0], "u": [4, 0, 0],
                              "v": [0, 0, -4], "bsdf": {"type": "diffuse", "albedo": 0.5}}],
            # a large light: BSDF sampling alone must find it often enough for its
            # standard errors to be trustworthy (a small one makes its estimator
            # heavy-tailed: rare hits, underestimated errors)
            "lights": [{"type": "sphere", "center": [1.0, 1.6, 0.8], "radius": 1.0,
                        "radiance": 1.5},
                       {"type": "environment", "radiance": [0.2, 0.25, 0.3]}]}


@pytest.mark.parametrize("gpis", [False, True], ids=["sphere", "gpis"])
def test_nee_and_bsdf_sampling_agree(device, gpis):
    """NEE+MIS (rough_conductor_eval's f and pdf) and BSDF sampling alone
    (rough_conductor_sample) estimate the same image, on a metal sphere and on a GPIS
    ball whose micro-BSDF is the metal."""
    on = render_result(_metal_scene(True, 64, gpis), device=device)
    off = render_result(_metal_scene(False, 1024, gpis), device=device)
    for r in (on, off):
        assert r.stats.nan_paths == 0 and r.stats.gpis_failed == 0, r.stats.summary()
    assert on.image.mean.max() > 0.05
    assert_agree(on.image.mean, on.image.stderr, off.image.mean, off.image.stderr, block=4,
                 what="NEE on/off, rough conductor")


def test_white_conductor_conserves_energy(device, prg):
    """With F ~ 1 (k = 1e4) the directional albedo is the fraction of energy the
    single-scattering masking keeps: <= 1 always, and near 1 for smooth surfaces seen
    steeply (Heitz 2014: the loss grows with roughness and grazing angles). Mean sampling
    weight over 100000 draws, z-tested against 1 from above."""
    rng = np.random.default_rng(9)
    count = 100_000
    z = z_threshold(6)
    white = ((1.0, 1.0, 1.0), (1e4, 1e4, 1e4))
    for alpha, cos_v, floor in ((0.05, 0.95, 0.995), (0.3, 0.95, 0.97), (0.8, 0.3, 0.6)):
        p = _params(alpha, eta_k=white)
        v = np.array([math.sqrt(1 - cos_v**2), 0.0, cos_v])
        out = _run(device, prg, "rc_sample", 12, p, np.tile([0.0, 0.0, 1.0], (count, 1)),
                   np.tile(v, (count, 1)), rng.uniform(0, 1, (count, 2)))
        w = out[:, 0]
        se = w.std() / math.sqrt(count)
        print(alpha, cos_v, w.mean(), se)
        assert w.mean() <= 1.0 + z * se and w.mean() >= floor, (alpha, cos_v, w.mean())
