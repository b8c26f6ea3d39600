"""Next-event estimation at function-space GPIS hits (fs_normal_pdf.h): the density of the
sampled normal, p_Omega(n) = N2(q(n); m_q, S_q) s^2 / |n.d|^3, against quadrature and
against normals the device draws; renders with NEE + MIS against BSDF sampling alone."""

import numpy as np
import pyopencl as cl
import pytest

from gpiscl.host.gp import Constant, Matern32, Plane, SquaredExponential
from gpiscl.testing.reference import function_space as FS
from gpiscl.host.layout.records import GPIS_MEMORIES
from gpiscl.host.render.program_sources import fs_sampler_options
from gpiscl.testing.stats import assert_agree, chi2_threshold, image_mean_se
from gpiscl.testing.scenes import function_space_sampler, gpis_scene, render_checked
from gpiscl.testing.flights import CAP_MAX, WINDOW_MAX, sampler_buffers
from gpiscl.testing.wrappers import buffer, sampler_program

LAW = r"""
/* A ray along a line that goes straight on through `restarts` hits (continuations from
 * the vertex record, as test_fs_sampling's flight): per item the last hit's sampled
 * gradient and the law it was drawn from (FsResult.law_*), and whether it hit. */
__kernel void normal_law(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                         int memory, int cap, __global const double* ray, uint seed,
                         int first, int restarts, __global double* scratch,
                         __global FsObs* rings, __global double* out)
{
    int i = get_global_id(0);
    FsScratch S = fs_scratch(scratch, i);
    FsParams prm = {0, memory, cap, 6, 0.0, 1e-5};
    FsRay r = {vload3(0, ray), vload3(1, ray), ray[6], ray[7]};
    FsRng rng = {seed, (uint)(first + i), 0u, 0u, 0u};
    FsVertex v = {0};
    __global double* o = out + 16 * i;
    for (int k = 0; k < 16; ++k) o[k] = 0.0;
    for (int b = 0; b <= restarts; ++b) {
        rng.bounce = (uint)b;
        /* as fs_object_flight: Matern without off-ray conditioning takes fs_markov.h */
        FsResult res = fs_markov_applies(kp[0], prm, S)
            ? fs_markov_free_flight(kp[0], mean, mc, prm, r, v, rng, S)
            : fs_free_flight(kp[0], mean, mc, prm, r, v, rings + (size_t)i * cap, rng, S);
        if (res.status) { o[15] = -1.0; return; }
        if (!res.hit) return;
        vstore3(res.grad, 0, o);
        vstore3(res.law_m, 1, o);
        vstore3(res.law_a, 2, o);
        vstore3(res.law_b, 3, o);
        o[12] = res.law_s;
        o[15] = b + 1;
        v = fs_vertex_at_hit(prm, r, res, v, rings + (size_t)i * cap, S);
        r.o = r.o + res.t * r.d;
        r.t1 -= res.t;
        r.t0 = 0.0;
    }
}
"""


IMPLIED = r"""
/* One flight to a hit, its vertex record, then the conditioning rows fs_begin gives a
 * ray from the vertex along dnew: with the record as it is, and with the gradient that
 * the tilted normal h = normalize(n + tilt) implies (a shadow ray's copy). out: hit,
 * the implied gradient (3), rows of each (count, outside, then per row value, kind,
 * direction (3)), 4 + 2 (2 + 5 cap) doubles. */
__kernel void implied_rows(__global const GpKernel* kp, __global const MeanNode* mean, int mc,
                           int memory, int cap, __global const double* ray, uint seed,
                           __global const double* tilt, __global const double* dnew,
                           __global double* scratch, __global FsObs* rings,
                           __global double* out)
{
    FsScratch S = fs_scratch(scratch, 0);
    FsParams prm = {0, memory, cap, 6, 0.0, 1e-5};
    FsRay r = {vload3(0, ray), vload3(1, ray), ray[6], ray[7]};
    FsRng rng = {seed, 0u, 0u, 0u, 0u};
    FsVertex v = {0};
    FsResult res = fs_free_flight(kp[0], mean, mc, prm, r, v, rings, rng, S);
    out[0] = res.hit && !res.status;
    if (!out[0]) return;
    v = fs_vertex_at_hit(prm, r, res, v, rings, S);
    double3 dn = normalize(r.d), h = normalize(normalize(res.grad) + vload3(0, tilt));
    double3 g = (res.law_s / dot(h, dn)) * h;
    vstore3(g, 0, out + 1);
    FsRay sr = {r.o + res.t * r.d, vload3(0, dnew), 0.0, 1.0};
    for (int implied = 0; implied < 2; ++implied) {
        FsVertex c = v;
        if (implied) { c.grad = (float4)(convert_float3(g), 0.0f); c.implied = 1; }
        double f0;
        int outside, n_old;
        int m = fs_begin(kp[0], mean, mc, prm, sr, c, rings, rng, S, &f0, &outside, &n_old);
        __global double* o = out + 4 + implied * (2 + 5 * cap);
        o[0] = m;
        o[1] = outside;
        for (int k = 0; k < m; ++k) {
            o[2 + 5 * k] = S.rows[k].value;
            o[3 + 5 * k] = S.rows[k].kind;
            vstore3(fs_dir(S.rows + k), 0, o + 4 + 5 * k);
        }
    }
}
"""


def _programs(ctx):
    return sampler_program(ctx, LAW + IMPLIED, fs_sampler_options(WINDOW_MAX, CAP_MAX))


def _program(ctx):
    return _programs(ctx)["normal_law"]


D = np.array([1.0, 0.3, -0.2]) / np.linalg.norm([1.0, 0.3, -0.2])
# (kernel, mean, memory, restarts): the closed form (isotropic stationary, no global
# memory), the general conditional of an anisotropic kernel, and global memory at the
# third hit of a ray (the ring's rows from earlier hits lie off the ray and condition
# the tangential gradient); tilted plane means make m_q != 0
CASES = {
    "isotropic": (SquaredExponential(sigma=1.0, length_scale=1.0),
                  Plane(point=(2.0, 0, 0), normal=(-1.0, 0.5, 0.2), scale=0.6), "none", 0),
    "anisotropic": (SquaredExponential(sigma=0.8, length_scale=1.0, aniso=(1.0, 4.0, 0.5)),
                    Plane(point=(2.0, 0, 0), normal=(-1.0, -0.4, 0.3), scale=0.5), "none", 0),
    "global": (SquaredExponential(sigma=1.0, length_scale=1.0), Constant(0.3), "global", 2),
    # the Markov sampler's law (fs_markov.h: a frame orthonormal in the metric A, so the
    # tangential mean depends on the pinned slope), anisotropic
    "markov": (Matern32(sigma=0.8, length_scale=1.0, aniso=(1.0, 4.0, 0.5)),
               Plane(point=(2.0, 0, 0), normal=(-1.0, -0.4, 0.3), scale=0.5), "renewal_plus",
               0),
}


def normal_laws(device, case, n, seed=5):
    """Sampled unit normals and their laws (m, a, b, s) at the last hit of those of n device
    flights along D that reached it."""
    kernel, mean, memory, restarts = CASES[case]
    q = device.queue
    chunk = min(n, 1024)
    kp, mb, n_mean, scratch, rings = sampler_buffers(device, kernel, mean, CAP_MAX, chunk)
    rb = buffer(device, np.array([0, 0, 0, *D, 0.0, 30.0], np.float64))
    out = np.empty((n, 16))
    for first in range(0, n, chunk):
        m = min(chunk, n - first)
        ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 8 * 16 * m)
        _program(device.ctx)(q, (m,), None, kp, mb, np.int32(n_mean),
                             np.int32(GPIS_MEMORIES[memory]), np.int32(CAP_MAX), rb,
                             np.uint32(seed), np.int32(first), np.int32(restarts), scratch,
                             rings, ob)
        cl.enqueue_copy(q, out[first:first + m], ob)
    assert np.all(out[:, 15] >= 0), "solver status"
    ok = out[:, 15] == restarts + 1
    g = out[ok, 0:3]
    return g / np.linalg.norm(g, axis=1, keepdims=True), \
        (out[ok, 3:6], out[ok, 6:9], out[ok, 9:12], out[ok, 12])


def normal_pdf(n, law, jacobian=True):
    """The numpy twin's density for rays along D."""
    return FS.normal_pdf(n, D, law, jacobian)


def frame(d):
    t = np.cross(d, [0.0, 0.0, 1.0])
    t /= np.linalg.norm(t)
    return t, np.cross(d, t)


def hemisphere(n_theta, n_phi, d=D):
    """Midpoint quadrature of the hemisphere n . d < 0 in u = 1 - cos(angle to -d), phi
    (equal-area: dOmega = du dphi): points (n_theta, n_phi, 3) and the cell's weight."""
    t, b = frame(d)
    u = (np.arange(n_theta) + 0.5) / n_theta
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    ct, st = 1 - u, np.sqrt(u * (2 - u))
    pts = (-ct[:, None, None] * d + st[:, None, None]
           * (np.cos(phi)[None, :, None] * t + np.sin(phi)[None, :, None] * b))
    return pts, (1.0 / n_theta) * (2 * np.pi / n_phi)


@pytest.mark.parametrize("memory", ["renewal_plus", "global"])
def test_shadow_rays_condition_on_the_implied_gradient(device, memory):
    """A shadow ray's copy of the vertex record with the gradient a light sample's normal
    h implies, g = s / (h.d) h: renewal_plus conditions on its slope along the new ray;
    global replaces the ring's two tangential rows of the vertex by g's components and
    keeps everything else (the slope row: g.d = s); the record itself is unchanged."""
    kernel, mean = SquaredExponential(sigma=1.0, length_scale=1.0), Constant(0.3)
    cap = 64
    kp, mb, n_mean, scratch, rings = sampler_buffers(device, kernel, mean, cap, 1)
    rb = buffer(device, np.array([0, 0, 0, *D, 0.0, 30.0], np.float64))
    dnew = np.array([0.2, 0.9, 0.4]) / np.linalg.norm([0.2, 0.9, 0.4])
    size = 4 + 2 * (2 + 5 * cap)
    checked = 0
    for seed in range(1, 6):
        ob = cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, 8 * size)
        _programs(device.ctx)["implied_rows"](
            device.queue, (1,), None, kp, mb, np.int32(n_mean),
            np.int32(GPIS_MEMORIES[memory]), np.int32(cap), rb, np.uint32(seed),
            buffer(device, np.array([0.3, -0.2, 0.1])), buffer(device, dnew), scratch, rings, ob)
        out = np.empty(size)
        cl.enqueue_copy(device.queue, out, ob)
        if not out[0]:
            continue
        g = out[1:4]
        assert g @ D < 0
        rows = []
        for implied in range(2):
            o = out[4 + implied * (2 + 5 * cap):]
            m = int(o[0])
            rows.append(o[2:2 + 5 * m].reshape(m, 5))
        plain, shadow = rows
        assert plain.shape == shadow.shape
        g32 = g.astype(np.float32).astype(np.float64)   # FsVertex.grad is float
        if memory == "renewal_plus":
            assert len(shadow) == 2 and shadow[1, 1] == 1
            np.testing.assert_allclose(shadow[1, 0], g32 @ dnew, rtol=1e-12)
            assert abs(plain[1, 0] - shadow[1, 0]) > 1e-6   # h differs from the sample
        else:
            np.testing.assert_array_equal(plain[:-2], shadow[:-2])
            assert np.all(shadow[-3:, 1] == 1)                    # slope, d_T f, d_B f
            np.testing.assert_allclose(shadow[-3:, 2:] @ D, [1, 0, 0], atol=1e-12)
            np.testing.assert_allclose(shadow[-2:, 0], shadow[-2:, 2:] @ g32, rtol=1e-10)
            np.testing.assert_allclose(shadow[-3, 0], g @ D, rtol=1e-6)   # s itself
        checked += 1
    assert checked >= 3


@pytest.mark.parametrize("case", list(CASES))
def test_normal_pdf_integrates_to_one(device, case):
    """Quadrature over the hemisphere of each of 8 laws the device produced: 1 to 1e-4
    (midpoint rule on a 2000 x 400 equal-area grid; without the s^2 / |n.d|^3 Jacobian
    the integral is E|n.d|^3 / s^2, nowhere near 1: 0.45 to 0.97 away, the same to 1e-4
    on a 200 x 40 grid, which this check uses)."""
    _, laws = normal_laws(device, case, 64)
    assert len(laws[3]) >= 8
    pts, w = hemisphere(2000, 400)
    coarse, w_coarse = hemisphere(200, 40)
    for k in range(8):
        law = tuple(x[k] for x in laws)
        total = normal_pdf(pts, law).sum() * w
        assert abs(total - 1.0) < 1e-4, (case, k, total)
        broken = normal_pdf(coarse, law, jacobian=False).sum() * w_coarse
        assert abs(broken - 1.0) > 1e-2, (case, k, broken)


def cell_chi_square(normals, laws, pdf, d=D, cells=(6, 8), sub=8, chunk=250):
    """Pearson's chi-square of sampled normals in equal-area cells of the hemisphere (u =
    1 - cos(angle to -d), phi) when every sample has its own law: a cell's expected count
    is the sum over samples of its probability under that sample's law, by a sub x sub
    midpoint rule inside the cell. Cells expecting < 5 are pooled into one. Sums of
    independent non-identical categorical draws have counts' variances E (1 - p) at most,
    so chi-square(df = cells - 1) thresholds are conservative. Returns (statistic, df,
    expected total / samples: 1 if the pdf integrates to 1)."""
    t, b = frame(d)
    nu, nphi = cells
    pts, w = hemisphere(nu * sub, nphi * sub, d)
    expected = np.zeros(nu * nphi)
    for k in range(0, len(normals), chunk):
        law = tuple(x[k:k + chunk, None, None] for x in laws[:3]) + (laws[3][k:k + chunk, None, None],)
        p = pdf(pts[None], law) * w                     # (chunk, nu sub, nphi sub)
        p = p.reshape(len(p), nu, sub, nphi, sub).sum(axis=(0, 2, 4))
        expected += p.ravel()
    u = 1 + normals @ d
    phi = np.mod(np.arctan2(normals @ b, normals @ t), 2 * np.pi)
    idx = (np.minimum((u * nu).astype(int), nu - 1) * nphi
           + np.minimum((phi / (2 * np.pi) * nphi).astype(int), nphi - 1))
    observed = np.bincount(idx, minlength=nu * nphi).astype(float)
    small = expected < 5
    e = np.append(expected[~small], expected[small].sum())
    o = np.append(observed[~small], observed[small].sum())
    keep = e > 0
    return float(np.sum((o[keep] - e[keep]) ** 2 / e[keep])), int(keep.sum()) - 1, \
        expected.sum() / len(normals)


@pytest.mark.parametrize("case", list(CASES))
def test_sampled_normals_match_the_pdf(device, case):
    """2000 device normals, each from its own law, binned against that law's pdf
    (chi-square); the same statistic rejects the pdf without the s^2 / |n.d|^3 Jacobian
    (renormalised per law so only its shape differs), so the test can fail. The
    renormalisation's 60 x 30 midpoint grid gives the statistic the 120 x 60 grid gave to
    0.1 (1099, 1428, 1678, 1882 against 3 x thresholds of 171-188) at 0.4x the time."""
    normals, laws = normal_laws(device, case, 2000, seed=12)
    assert len(normals) > 1500
    chi2, df, total = cell_chi_square(normals, laws, normal_pdf)
    assert abs(total - 1.0) < 2e-3, total
    t = chi2_threshold(df)
    assert chi2 < t, f"{case}: chi-square {chi2:.1f}, df {df} (threshold {t:.1f})"
    pts, w = hemisphere(60, 30)

    def shape_only(n, law):   # no Jacobian, each law normalised on the hemisphere
        s = law[3]
        flat = tuple(x.reshape(-1, 1, 1, *x.shape[s.ndim:]) for x in law)
        norm = normal_pdf(pts[None], flat, jacobian=False).sum(axis=(1, 2)) * w
        return normal_pdf(n, law, jacobian=False) / norm.reshape(s.shape)

    chi2b, dfb, _ = cell_chi_square(normals, laws, shape_only)
    assert chi2b > 3 * chi2_threshold(dfb), f"{case}: no-Jacobian pdf passes ({chi2b:.1f}, df {dfb})"


def lit_scene(memory, bsdf, spp, nee, seed, radius=0.3, kernel=None):
    """The rough GPIS ball of test_fs_render under a sphere light (radius 0.3 at distance
    2.4: small), nothing else: every pixel is light reflected by the micro-BSDF."""
    light = [{"type": "sphere", "center": [1.2, 1.4, 1.6], "radius": radius,
              "radiance": 12.0 * (0.3 / radius) ** 2}]
    scene = gpis_scene(function_space_sampler(memory), "mirror", 1.0, light, spp=spp, seed=seed,
                       max_depth=64, rr_start=3)
    scene["shapes"][0]["bsdf"] = bsdf
    if kernel:
        scene["shapes"][0]["kernel"] = kernel
    scene["render"]["nee"] = nee
    return scene


MIRROR = {"type": "mirror", "albedo": 0.9}
GOLD_MIRROR = {"type": "mirror", "albedo": 0.9, "material": "Au"}
CONDUCTOR = {"type": "rough_conductor", "material": "Au", "roughness": 0.3}


# the Markov sampler's hits (Matern 3/2, anisotropic: its own law of the normal)
MATERN = {"type": "matern32", "sigma": 0.3, "length_scale": 0.2, "aniso": [1.0, 2.0, 0.7]}


@pytest.mark.parametrize("bsdf,memory,radius,kernel", [
    (MIRROR, "renewal_plus", 0.3, None), (MIRROR, "global", 0.3, None),
    (MIRROR, "none", 0.3, None), (MIRROR, "renewal", 0.3, None),
    (CONDUCTOR, "renewal_plus", 0.3, None), (CONDUCTOR, "renewal_plus", 0.8, None),
    (MIRROR, "renewal_plus", 0.3, MATERN), (GOLD_MIRROR, "renewal_plus", 0.3, None)],
    ids=["mirror-renewal_plus", "mirror-global", "mirror-none", "mirror-renewal",
         "conductor-renewal_plus", "conductor-large-light", "mirror-markov",
         "mirror-fresnel"])
def test_nee_with_mis_equals_bsdf_sampling(device, bsdf, memory, radius, kernel):
    """NEE + MIS against BSDF sampling alone, per 4x4 block (z-test from the per-pixel
    sample variances) and over the whole image. The mirror's light samples pick their
    own normal (the half vector) and condition their shadow rays on its gradient; the
    renders agree only if p(wl) = p_Omega(h) / (4 |d.h|) is the density BSDF sampling
    has: measured, without the s^2 max |z| 5.0 (threshold 4.3) and the image 0.0168 vs
    0.052, without the 4 |d.h| max |z| 18. The conductor under a large light, where BSDF
    samples meet the light often, fails (image z 12.8) when BSDF sampling's weight
    ignores the lobe strategy's density (fs_conductor_light_pdf without q). A gold
    mirror's light samples take Fresnel at the half vector, its BSDF samples at the
    sampled normal."""
    spp = 256
    a = render_checked(lit_scene(memory, bsdf, spp, True, seed=21, radius=radius, kernel=kernel), device)
    b = render_checked(lit_scene(memory, bsdf, spp, False, seed=22, radius=radius, kernel=kernel), device)
    assert a.stats.killed_paths == 0 and b.stats.killed_paths == 0
    assert b.image.mean.max() > 0.05, "the light is seen through the ball"
    assert_agree(a.image.mean, a.image.stderr, b.image.mean, b.image.stderr, block=4,
                 what="NEE + MIS vs BSDF sampling")
    # and the whole image (a bias spread thinly over every block adds up here)
    assert_agree(*whole(a.image), *whole(b.image), what="NEE + MIS vs BSDF sampling, image")


def whole(img):
    """The image's mean and its standard error (stats.image_mean_se)."""
    return np.array([img.mean.mean()]), np.array([image_mean_se(img.stderr)])
