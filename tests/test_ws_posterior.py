"""ws_posterior.h: weight-space posterior realizations by pathwise conditioning (Matheron's
rule) against their numpy twin, the exact posterior's moments, a dense scan of the root
search, and function-space renders of the same posterior."""
import numpy as np
import pytest

from gpiscl.host.scene import observations as OBS
from gpiscl.host.gp import RationalQuadratic, Sphere, SquaredExponential
from gpiscl.host.gp import spectral
from gpiscl.testing.reference import weight_space as ws
from gpiscl.host.layout.gp_records import pack_kernel, pack_mean
from gpiscl.host.gp.posterior import Posterior, solve_triangular, surface_observations
from gpiscl.testing.stats import assert_agree, z_threshold
from gpiscl.testing.scenes import (fibonacci_sphere, noisy_sphere_points, posterior_tables,
                                   render_checked, sphere_scene)
from gpiscl.testing.weight_space import build, dump, eval_tolerance, keys_for
from gpiscl.testing.wrappers import buffer


def launch(device, kernel, n, *args, out_shapes):
    """test_ws_features.run with small work-groups: PoCL keeps a private array that lives
    across uniform loops (v here) once per work-item of a group, on the stack."""
    import pyopencl as cl
    outs = [np.empty(s, dt) for s, dt in out_shapes]
    bufs = [cl.Buffer(device.ctx, cl.mem_flags.WRITE_ONLY, o.nbytes) for o in outs]
    local = next(g for g in (8, 4, 2, 1) if n % g == 0)
    kernel(device.queue, (n,), (local,), *args, *bufs)
    for o, b in zip(outs, bufs):
        cl.enqueue_copy(device.queue, o, b)
    return outs

EXTRA = r"""
/* per item: key keys[i / per_key], probe x[i]: f_post and its gradient; v of each key */
__kernel void post_probe(__global const GpKernel* kp, __global const MeanNode* means,
                         int first, int mc, __global const GpisObject* obj,
                         __global const FsObs* obs, __global const double* doubles,
                         __global const float* cdf, int nc, int M,
                         __global const uint2* keys, int per_key, __global const float* x,
                         __global float4* out, __global double* v_out)
{
    int i = get_global_id(0);
    uint2 key = keys[i / per_key];
    WsPostBlock B = ws_posterior_block(obj, obs, doubles);
    double v[WS_POST_MAX];
    double rho = ws_post_prepare(0, kp[0], means + first, mc, cdf, nc, M, key, 0, B, v);
    WsPost P = {B.rows, v, B.n, rho};
    float3 g;
    float f = ws_eval_post(0, &P, kp[0], means + first, mc, cdf, nc, M, key, 0, vload3(i, x),
                           &g);
    out[i] = (float4)(g, f);
    if (i % per_key == 0)
        for (int j = 0; j < B.n; ++j) v_out[(i / per_key) * B.n + j] = v[j];
}

__kernel void post_tents(__global const GpKernel* kp, __global const MeanNode* means,
                         int first, int mc, __global const GpisObject* obj,
                         __global const FsObs* obs, __global const double* doubles,
                         __global const float* cdf, int nc, int M,
                         __global const uint2* keys, __global const float* o,
                         __global const float* d, __global const float2* ab, int npts,
                         __global float* tents, __global float2* vals)
{
    int r = get_global_id(0);
    WsPostBlock B = ws_posterior_block(obj, obs, doubles);
    double v[WS_POST_MAX];
    double rho = ws_post_prepare(0, kp[0], means + first, mc, cdf, nc, M, keys[r], 0, B, v);
    WsPost P = {B.rows, v, B.n, rho};
    float3 O = vload3(r, o), D = vload3(r, d), g;
    float a = ab[r].x, b = ab[r].y;
    WsTents T = ws_tents_post(0, &P, kp[0], means + first, mc, cdf, nc, M, keys[r], 0, O, D,
                              a, b, ws_mean_lipschitz(means + first, mc));
    float t9[9] = {T.lo_k, T.lo_a, T.lo_m, T.lo_b, T.hi_k, T.hi_a, T.hi_m, T.hi_b, T.round};
    for (int j = 0; j < 9; ++j) tents[9 * r + j] = t9[j];
    for (int j = 0; j < npts; ++j) {
        float t = j == npts - 1 ? b : a + (b - a) * ((float)j / (float)(npts - 1));
        vals[r * npts + j] = (float2)(t, ws_eval_post(0, &P, kp[0], means + first, mc, cdf,
                                                      nc, M, keys[r], 0, O + t * D, &g));
    }
}

__kernel void post_roots(__global const GpKernel* kp, __global const MeanNode* means,
                         int first, int mc, __global const GpisObject* obj,
                         __global const FsObs* obs, __global const double* doubles,
                         __global const float* cdf, int nc, int M,
                         __global const uint2* keys, __global const float* o,
                         __global const float* d, float t0, float t1, float tol,
                         __global float4* hit, __global int2* st)
{
    int r = get_global_id(0), status, evals;
    float3 n;
    WsPostSlot solve_here = {0, 0};   /* no kept weights: this ray solves for its own */
    float t = ws_first_root_post(ws_posterior_block(obj, obs, doubles), solve_here, kp[0],
                                 means + first, mc, cdf, nc, M, keys[r], 0, vload3(r, o),
                                 vload3(r, d), t0, t1, tol, &n, &status, &evals);
    hit[r] = (float4)(n, t);
    st[r] = (int2)(status, evals);
}
"""


@pytest.fixture(scope="module")
def prg(device):
    return build(device, EXTRA)


def case(kind, rng, n_points=None):
    """A posterior on noisy points of the unit sphere with a rough prior (radius 1.2):
    'se': anisotropic SE, values only; 'rq': RQ with normals and inside/outside points."""
    mean = Sphere(radius=1.2)
    if kind == "se":
        kernel = SquaredExponential(sigma=0.5, length_scale=0.625, aniso=(1.0, 0.75, 1.5))
        pts = fibonacci_sphere(n_points or 100)
        obs = surface_observations(pts * (1 + rng.normal(0, 0.01, (len(pts), 1))), noise=1e-4)
    else:
        kernel = RationalQuadratic(sigma=0.5, length_scale=0.5, alpha=1.5)
        pts = fibonacci_sphere(n_points or 30)
        obs = surface_observations(pts, pts, noise=1e-4, normal_noise=1e-3,
                                   inside=rng.uniform(-0.3, 0.3, (5, 3)),
                                   outside=2.0 * fibonacci_sphere(5))
    return kernel, mean, Posterior(kernel, mean, obs)


def device_args(device, kernel, mean, post):
    """(kernel, means, first, count, object, rows, doubles, cdf, ncdf): another program
    first, then the object's, and its posterior after another's in the tables."""
    other = pack_mean(Sphere(radius=0.5))
    prog = pack_mean(mean)
    nodes = np.concatenate([other, prog])
    cdf = spectral.order_table(kernel)
    return (buffer(device, pack_kernel(kernel)), buffer(device, nodes),
            np.int32(len(other)), np.int32(len(prog)),
            *(buffer(device, a) for a in posterior_tables(post)), buffer(device, cdf),
            np.int32(len(cdf)))


def probe(device, prg, args, rows, m, keys, x):
    """f_post (R, P) and gradients (R, P, 3) at x (R, P, 3), and v (R, rows)."""
    r, p = x.shape[:2]
    out, v = launch(device, prg["post_probe"], r * p, *args, np.int32(m), buffer(device, keys),
                    np.int32(p), buffer(device, x.reshape(-1, 3).astype(np.float32)),
                    out_shapes=[((r * p, 4), np.float32), ((r, rows), np.float64)])
    return out[:, 3].reshape(r, p), out[:, :3].reshape(r, p, 3), v


def setup(device, kind, rng, **kw):
    kernel, mean, post = case(kind, rng, **kw)
    return kernel, mean, post, device_args(device, kernel, mean, post)


@pytest.mark.parametrize("kind", ["se", "rq"])
def test01_device_realization_equals_numpy_pathwise_sample(device, prg, kind):
    """f_post at probes (value and gradient) equals posterior.PathwiseSample built from the
    device's features and the numpy twin of its noise draws, to float tolerance: the float
    error of the prior at the rows (eval_tolerance), carried into f_post by the kriging
    weights k(x, X) (K + N)^-1 (independent errors: root-sum-square), plus the prior's own
    at x."""
    rng = np.random.default_rng(1)
    kernel, mean, post, args = setup(device, kind, rng)
    m, nk, p = 64, 6, 40
    keys = keys_for(nk, 31)
    x = rng.uniform(-1.6, 1.6, (nk, p, 3)).astype(np.float32)
    f, g, v = probe(device, prg, args, len(post.obs), m, keys, x)
    theta, tau, w = dump(device, prg, kernel, keys, m)
    obs = post.obs
    for r in range(nk):
        s = ws.pathwise_sample(post, theta[r], tau[r], w[r], keys[r])
        xr = x[r].astype(float)
        ev, eg = eval_tolerance(theta[r], tau[r], w[r], kernel.variance, xr)
        ov, og = eval_tolerance(theta[r], tau[r], w[r], kernel.variance, obs.x)
        z = ws.noise_normals(keys[r], 0, len(obs))
        # per row: the prior's float error there, and the float Box-Muller's (~1e-6 z)
        dr = np.where(obs.is_value, ov, og) + 1e-6 * np.sqrt(obs.noise) * (1 + np.abs(z))
        W = solve_triangular(post.L, solve_triangular(post.L, post.cross(xr).T), transpose=True)
        # the rows' float errors are independent: they add like a random walk (4 sd)
        tol = 2 * ev + 4 * np.sqrt((W**2).T @ dr**2) + 1e-6 * (1 + np.abs(s(xr)))
        err = np.abs(f[r] - s(xr))
        if r == 0:
            print(f"{kind}: |f_post| up to {np.abs(s(xr)).max():.3g}, max error "
                  f"{err.max():.2g}, max tolerance {tol.max():.2g}")
        assert np.all(err <= tol), (r, err.max(), (err / tol).max())
        # where K is ill-conditioned the kriging weights make tol loose: float's own scale
        # (measured max error 1.8e-6) must hold too
        assert np.all(err <= 2e-5 * (1 + np.abs(s(xr)))), (r, err.max())
        grad = s.gradient(xr)
        for axis in range(3):
            Wa = solve_triangular(post.L, solve_triangular(
                post.L, post.cross(xr, np.eye(3)[axis]).T), transpose=True)
            tol_g = (2 * eg + 4 * np.sqrt((Wa**2).T @ dr**2)
                     + 1e-5 * (1 + np.abs(grad[:, axis])))
            err_g = np.abs(g[r][:, axis] - grad[:, axis])
            assert np.all(err_g <= tol_g), (r, axis, err_g.max(), (err_g / tol_g).max())


def test02_noise_draws_match_numpy(device, prg):
    """The device's per-row noise draws are the numpy twin's: K v = y - f(X) - e with the
    device's v and the host's f(X) exposes them (to the float error of f(X))."""
    rng = np.random.default_rng(2)
    kernel, mean, post, args = setup(device, "se", rng, n_points=37)
    m, nk = 64, 3
    keys = keys_for(nk, 5)
    _, _, v = probe(device, prg, args, len(post.obs), m, keys, np.zeros((nk, 1, 3), np.float32))
    theta, tau, w = dump(device, prg, kernel, keys, m)
    for r in range(nk):
        s = ws.pathwise_sample(post, theta[r], tau[r], w[r], keys[r])
        K = post.L @ post.L.T
        # K v = y - f(X) - e: recover e from the device's v and the host's f(X)
        f_obs = s._prior(post.obs.x)[0]
        e_dev = post.obs.y - f_obs - K @ v[r]
        z = ws.noise_normals(keys[r], 0, len(post.obs))
        np.testing.assert_allclose(e_dev, np.sqrt(post.obs.noise) * z, rtol=0, atol=3e-5)
        assert np.std(z) > 0.5


@pytest.mark.parametrize("kind", ["se", "rq"])
def test03_realizations_have_the_posterior_mean_and_variance(device, prg, kind):
    """Across realizations (features, weights and noise all redrawn), f_post at probes has
    the exact posterior's mean and variance: Matheron's rule needs only the prior's first
    two moments, which random features have exactly. z-tests, Bonferroni over all."""
    rng = np.random.default_rng(3)
    kernel, mean, post, args = setup(device, kind, rng, n_points=40 if kind == "se" else 20)
    m, nk = 32, 3000
    pts = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.05, 0.0], [0.7, 0.7, 0.3],
                    [1.5, 0.2, -0.3], [0.3, -0.4, 1.3]])
    keys = keys_for(nk, 77)
    x = np.broadcast_to(pts, (nk, len(pts), 3)).astype(np.float32)
    f, _, _ = probe(device, prg, args, len(post.obs), m, keys, x)
    mu, var = post.mean(pts), post.variance(pts)
    mean_hat, var_hat = f.mean(0), f.var(0, ddof=1)
    se_mean = np.sqrt(var_hat / nk)
    m4 = ((f - mean_hat) ** 4).mean(0)
    se_var = np.sqrt(np.maximum(m4 - var_hat**2, 0) / nk)
    z = np.concatenate([(mean_hat - mu) / se_mean, (var_hat - var) / se_var])
    t = z_threshold(len(z))
    print("posterior sd", np.sqrt(var), "z", np.round(z, 2))
    assert np.all(np.abs(z) < t), (z, t)
    # and the conditioning did something: the prior's variance is far larger on the points
    assert var[1] < 0.1 * kernel.variance


@pytest.mark.parametrize("kind", ["se", "rq"])
def test04_bounds_contain_every_point_evaluation(device, prg, kind):
    """The tents of a posterior realization (features' affine form, mean and correction
    cones) contain the device's point evaluations and the float64 realization with the
    device's v, over random intervals from 1e-4 l to 4 l, many through the observations."""
    rng = np.random.default_rng(4)
    kernel, mean, post, args = setup(device, kind, rng)
    n, npts, m = 96, 33, 48
    o = rng.uniform(-1.5, 1.5, (n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3))
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)
         * rng.uniform(0.5, 2.0, (n, 1))).astype(np.float32)
    half = kernel.length_scale * 10.0 ** rng.uniform(-4, 0.3, n) / np.linalg.norm(d, axis=1)
    a = rng.uniform(0.0, 1.0, n)
    ab = np.stack([a, a + 2 * half], -1).astype(np.float32)
    keys = keys_for(n, 41)
    tents, vals = launch(device, prg["post_tents"], n, *args, np.int32(m), buffer(device, keys),
                         buffer(device, o), buffer(device, d), buffer(device, ab), np.int32(npts),
                         out_shapes=[((n, 9), np.float32), ((n, npts, 2), np.float32)])
    _, _, v = probe(device, prg, args, len(post.obs), m, keys, np.zeros((n, 1, 3), np.float32))
    theta, tau, w = dump(device, prg, kernel, keys, m)
    for r in range(n):
        t = vals[r, :, 0].astype(float)
        x = o[r].astype(float) + t[:, None] * d[r].astype(float)
        exact = (ws.evaluate_value(theta[r], tau[r], w[r], kernel.variance, x, mean)
                 + post.cross(x) @ v[r])
        (lk, la, lm, lb, hk, ha, hm, hb, _), (a_, b_) = tents[r].astype(float), ab[r]
        lo = np.interp(t, [a_, lk, b_], [la, lm, lb])
        hi = np.interp(t, [a_, hk, b_], [ha, hm, hb])
        for val in (vals[r, :, 1], exact):
            assert np.all((lo <= val) & (val <= hi)), (r, np.min(val - lo), np.min(hi - val))


@pytest.mark.long
@pytest.mark.parametrize("kind", ["se", "rq"])
def test05_first_roots_match_a_dense_scan(device, prg, long_run, kind):
    """The certified search on posterior realizations misses no crossing that a dense
    float64 scan of the same realization (device features and v) finds, and every root
    it reports is a genuine >= 0 -> < 0 crossing."""
    rng = np.random.default_rng(5)
    kernel, mean, post, args = setup(device, kind, rng)
    n, m, t0, t1 = (192 if long_run else 64), 64, 0.0, 5.0   # the dense scans are the cost
    tol = 1e-4 * kernel.length_scale
    # rays from a shell of radius 2.5 towards points near the sphere (most hit it)
    o = rng.normal(size=(n, 3))
    o *= 2.5 / np.linalg.norm(o, axis=1, keepdims=True)
    d = rng.normal(size=(n, 3)) * 0.5 - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o, d = o.astype(np.float32), d.astype(np.float32)
    keys = keys_for(n, 60)
    hit, st = launch(device, prg["post_roots"], n, *args, np.int32(m), buffer(device, keys),
                     buffer(device, o), buffer(device, d), np.float32(t0), np.float32(t1),
                     np.float32(tol), out_shapes=[((n, 4), np.float32), ((n, 2), np.int32)])
    assert np.all(st[:, 0] == 0)
    print("evaluations per search: mean", st[:, 1].mean(), "max", st[:, 1].max(),
          "(rows", len(post.obs), ")")
    _, _, v = probe(device, prg, args, len(post.obs), m, keys, np.zeros((n, 1, 3), np.float32))
    theta, tau, w = dump(device, prg, kernel, keys, m)
    ts = np.linspace(t0, t1, int((t1 - t0) / (kernel.length_scale / 200)) + 1)
    t_dev = hit[:, 3].astype(float)
    hits = 0
    for r in range(n):
        x = o[r].astype(float) + ts[:, None] * d[r].astype(float)
        f = (ws.evaluate_value(theta[r], tau[r], w[r], kernel.variance, x, mean)
             + post.cross(x) @ v[r])
        t_lo, t_hi = (q[0] for q in ws.dense_scan_first_root(f[None], ts))
        if np.isfinite(t_hi):
            hits += 1
            assert t_dev[r] <= t_hi + tol, ("missed a root", r, t_dev[r], t_hi)
        if t_dev[r] < 1e29:
            near = t_dev[r] - tol * np.linspace(1, 0, 9)
            xn = o[r].astype(float) + near[:, None] * d[r].astype(float)
            fn = (ws.evaluate_value(theta[r], tau[r], w[r], kernel.variance, xn, mean)
                  + post.cross(xn) @ v[r])
            noise, _ = eval_tolerance(theta[r], tau[r], w[r], kernel.variance, xn)
            noise = noise + 1e-5 * (1 + np.abs(post.cross(xn)) @ np.abs(v[r]))
            assert fn[-1] <= noise[-1] and np.max(fn + noise) >= 0, (r, fn)
    assert hits > n // 2


# --- scenes -------------------------------------------------------------------------------

def test06_scene_key_accepts_weight_space(tmp_path):
    """Observations on a weight-space object load; kernels whose cross-covariance slopes
    ws_posterior.h does not bound, and more rows than its private vector holds, do not."""
    from gpiscl.host.errors import SceneError
    from gpiscl.host.scene.loading import load_scene
    pts = noisy_sphere_points(tmp_path / "p.xyz", 30, 0.01)
    s = sphere_scene(1.2, 0.3, 1, {"file": pts})
    s["shapes"][0]["sampler"] = {"type": "weight_space", "features": 64}
    load_scene(s)
    for kind in ("periodic", "matern32", "matern52"):
        bad = dict(s, shapes=[dict(s["shapes"][0], kernel={"type": kind, "sigma": 0.3})])
        with pytest.raises(SceneError, match="squared_exponential and rational_quadratic"):
            load_scene(bad)
    # function space conditions Matern priors with the general conditional sampler
    fs = dict(s, shapes=[dict(s["shapes"][0], kernel={"type": "matern32", "sigma": 0.3},
                              sampler={"type": "function_space"})])
    load_scene(fs)
    np.savetxt(tmp_path / "big.xyz", fibonacci_sphere(OBS.WS_MAX_ROWS + 1))
    s["shapes"][0]["observations"] = {"file": str(tmp_path / "big.xyz")}
    with pytest.raises(SceneError, match="weight_space sampler"):
        load_scene(s)


@pytest.mark.long
def test07_render_agrees_with_function_space(device, tmp_path, long_run):
    """The reconstructed sphere of test_posterior_render.py (prior radius 1.2, sigma
    0.05, 100 noisy points of the unit sphere): weight space (M = 1024, pathwise) and
    function space (exact conditioning) render the same expected image, per pixel and in
    4x4 blocks; the weight-space prior alone differs measurably (the test has power).
    Measured max |z|: 3.1 per pixel, 2.2 per block; the prior 6.1 and 5.4. The short form
    renders 8x8 pixels instead of 16x16 at the same spp (a pixel's power is unchanged; a
    lower spp would leave each pixel's error estimate too few samples): measured
    (2026-12-07) posterior 2.8 per pixel (threshold 4.56), 1.8 per block (3.93); the
    prior, i.e. observations ignored, 6.7 and 13.8 (at 12x12: 21.2 and 18.4)."""
    sigma, spp, res = 0.05, 32, (16 if long_run else 8)
    pts = noisy_sphere_points(tmp_path / "pts.xyz", 100, 0.05 * sigma)
    obs = {"file": pts, "noise": 0.05 * sigma}
    fs = render_checked(sphere_scene(1.2, sigma, spp, obs, seed=3, res=res), device).image
    images = {}
    for name, o in (("posterior", obs), ("prior", None)):
        s = sphere_scene(1.2, sigma, spp, o, seed=4, res=res)
        s["shapes"][0]["sampler"] = {"type": "weight_space", "features": 1024}
        images[name] = render_checked(s, device).image
    wsi = images["posterior"]
    assert_agree(wsi.mean, wsi.stderr, fs.mean, fs.stderr, what="ws vs fs posterior")
    assert_agree(wsi.mean, wsi.stderr, fs.mean, fs.stderr, block=4,
                 what="ws vs fs posterior, 4x4 blocks")
    prior = images["prior"]
    z = np.abs(prior.mean - fs.mean) / np.sqrt(prior.stderr**2 + fs.stderr**2 + 1e-30)
    assert z.max() > z_threshold(z.size), z.max()
