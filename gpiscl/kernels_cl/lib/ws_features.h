/* Weight-space ("Global infinity") GPIS realizations: random Fourier features
 *   f(x) = mean(x) + sqrt(k(0)) sqrt(2/M) sum_i w_i cos(theta_i . x + tau_i),
 * w_i ~ N(0,1), tau_i ~ U[0, 2 pi), theta_i from the kernel's normalised spectral measure
 * (gpiscl/host/gp/spectral.py derives each sampler; gpiscl/testing/reference/weight_space.py
 * is the numpy twin).
 *
 * Memory: features are never stored. Feature i is a pure function of
 * (realization key, object, i), regenerated from Philox whenever it is needed, so a path's
 * realization costs O(1) memory (its uint2 key) whatever M is and however many paths are
 * in flight; the price is one Philox call (two for periodic, more for RQ and Matern's
 * gamma draws) per feature evaluation.
 * Streams: Philox4x32-10 (Random123's, as in pyopencl's philox.cl) with counter
 * (key.x, key.y, object, i) and key (call, WS_PHILOX_KEY1). rng.h uses key word 1 =
 * 0x6a09e667, so the two generators never share a stream. Realization key: (pixel, sample)
 * of the path, or (R, 0xffffffff) for a fixed realization R (no path has that sample).
 *
 * Speed: features are processed WS_LANES at a time in OpenCL vector types, with branch-free
 * polynomial log/sin/cos. PoCL does not vectorise across work-items through a data-dependent
 * loop (the root finder's), and its scalar transcendental builtins are opaque calls, so
 * explicit lanes are what makes the feature loop SIMD. Build with -DWS_LANES=1 on GPUs; on
 * CPUs the device's native float vector width is best (docs/design/batches.md,
 * 'Weight-space lanes'). Every lane computes its own feature from its own index, so
 * results do not depend on WS_LANES. Regenerating a feature costs several times evaluating
 * a stored one, so a root search regenerates its ray's features once into a private cache
 * (WS_CACHE_FEATURES) and reads them from there on every bound.
 *
 * Precision: float32 suffices. Values are O(sigma) and roots are wanted to ~1e-4 l, i.e. f
 * to ~1e-4 sigma, far above float's 6e-8 relative rounding. What needs care is the phase
 * theta . x + tau: its absolute error is ~eps |theta| |x|, so realizations stay smooth to
 * 1e-3 rad while |theta| |x| < ~1e4 (|x| < ~50 l): keep GPIS objects within a few hundred
 * length scales of the world origin. Phases are reduced mod pi/2 in three parts (exact for
 * |phase| < 2^15), and ws_affine's `round` accounts for the phase error in its bounds.
 */
#ifndef WS_LANES
#error "WS_LANES comes from the host (render/integrator.ws_defines)"
#endif
/* Features kept in private memory for one root search when M <= WS_CACHE_FEATURES: a
 * search evaluates its ray's realization ~35 times, and regenerating a feature (Philox,
 * two Box-Muller pairs) costs several times evaluating a stored one, so on CPUs the cache
 * makes searches several times faster for a little stack (docs/design/batches.md,
 * 'Weight-space lanes'). GPUs (WS_LANES 1) would spill it: off by default there. Caution
 * (PoCL 3.0 pthread): a kernel that fills a cache and then runs loops with uniform trip
 * counts gets the array replicated per work-item, which overflows the stack for
 * work-groups >= 512; inside the search, whose loop is data-dependent, it is not
 * replicated (tested up to 4096). */
#ifndef WS_CACHE_FEATURES
#if WS_LANES > 1
#define WS_CACHE_FEATURES 1024
#else
#define WS_CACHE_FEATURES 0
#endif
#endif
/* WS_PHILOX_KEY1, WS_CALL_*, WS_GAMMA_CALLS: layout/constants.py */
#define WS_TWO_PI 6.28318530717958648f

#if WS_LANES == 1
typedef float wsf;
typedef int wsi;
typedef uint wsu;
#define ws_cvt_f convert_float
#define ws_cvt_i convert_int
#define ws_as_f as_float
#define ws_as_i as_int
#define WS_IOTA 0
#define ws_any(c) ((c) != 0)
#define ws_lane0(v) (v)
#define ws_hsum(v) (v)
#else
#define WS_CAT_(a, b) a##b
#define WS_CAT(a, b) WS_CAT_(a, b)
typedef WS_CAT(float, WS_LANES) wsf;
typedef WS_CAT(int, WS_LANES) wsi;
typedef WS_CAT(uint, WS_LANES) wsu;
#define ws_cvt_f WS_CAT(convert_float, WS_LANES)
#define ws_cvt_i WS_CAT(convert_int, WS_LANES)
#define ws_as_f WS_CAT(as_float, WS_LANES)
#define ws_as_i WS_CAT(as_int, WS_LANES)
#define ws_any(c) any(c)
#define ws_lane0(v) ((v).s0)
#if WS_LANES == 4
#define WS_IOTA ((int4)(0, 1, 2, 3))
#define ws_hsum(v) ((v).s0 + (v).s1 + (v).s2 + (v).s3)
#elif WS_LANES == 8
#define WS_IOTA ((int8)(0, 1, 2, 3, 4, 5, 6, 7))
#define ws_hsum(v) ((v).s0 + (v).s1 + (v).s2 + (v).s3 + (v).s4 + (v).s5 + (v).s6 + (v).s7)
#elif WS_LANES == 16
#define WS_IOTA ((int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15))
#define ws_hsum(v) ((v).s0 + (v).s1 + (v).s2 + (v).s3 + (v).s4 + (v).s5 + (v).s6 + (v).s7 \
                  + (v).s8 + (v).s9 + (v).sa + (v).sb + (v).sc + (v).sd + (v).se + (v).sf)
#else
#error "WS_LANES must be 1, 4, 8 or 16"
#endif
#endif

/* --- branch-free float math (Cephes minimax polynomials, ~1 ulp) ----------------------- */

/* natural log of a positive normal float */
inline wsf ws_log(wsf x)
{
    wsi bits = ws_as_i(x);
    wsi e = (bits >> 23) - 126;
    wsf m = ws_as_f((bits & 0x007fffff) | 0x3f000000);      /* [0.5, 1) */
    wsi low = m < 0.70710678f;
    e = select(e, e - 1, low);
    m = select(m - 1.0f, m + m - 1.0f, low);
    wsf z = m * m, fe = ws_cvt_f(e);
    wsf y = (((((((( 7.0376836292e-2f * m - 1.1514610310e-1f) * m + 1.1676998740e-1f) * m
             - 1.2420140846e-1f) * m + 1.4249322787e-1f) * m - 1.6668057665e-1f) * m
             + 2.0000714765e-1f) * m - 2.4999993993e-1f) * m + 3.3333331174e-1f) * m * z;
    y += -2.12194440e-4f * fe - 0.5f * z;
    return m + y + 0.693359375f * fe;
}

/* Approximation error of ws_sincos_quadrant's polynomials on |r| <= pi/4, evaluated
 * exactly: 5.6e-9 (sin), 1.3e-10 (cos) (tests/test_ws_features.py measures both with the
 * float32 coefficients below). Their float32 evaluation adds ~2 eps, which ws_affine's
 * `round` covers with every other float rounding; this bound is folded into its `err`, so
 * the bounds contain the exact realization whatever the polynomials' own error. */
#define WS_SINCOS_ERR 1e-8f

/* sin and cos of r + q pi/2 for |r| <= pi/4. The quadrant's sign is applied by flipping
 * the sign bit (xor), not by negate-and-select: the same bits, fewer vector operations in
 * the hot loop. */
inline wsf ws_sincos_quadrant(wsf r, wsi q, wsf* c)
{
    wsf z = r * r;
    wsf s0 = r + r * z * ((-1.9515295891e-4f * z + 8.3321608736e-3f) * z - 1.6666654611e-1f);
    wsf c0 = 1.0f - 0.5f * z
           + z * z * ((2.443315711809948e-5f * z - 1.388731625493765e-3f) * z
                      + 4.166664568298827e-2f);
    wsi odd = (q & 1) != 0;
    wsf s = select(s0, c0, odd), cc = select(c0, s0, odd);
    /* sin is negative in quadrants 2, 3 (bit 1 of q), cos in quadrants 1, 2 (bit 1 of
     * q + 1); << 30 moves that bit to the sign bit */
    *c = ws_as_f(ws_as_i(cc) ^ (((q + 1) & 2) << 30));
    return ws_as_f(ws_as_i(s) ^ ((q & 2) << 30));
}

/* sin(x), cos(x) with Cody-Waite reduction by pi/2 (three parts, exact for |x| < 2^15) */
inline wsf ws_sincos(wsf x, wsf* c)
{
    wsf q = rint(x * 0.63661977236758134f);
    wsf r = ((x - q * 1.5703125f) - q * 4.837512969970703125e-4f) - q * 7.549789948768648e-8f;
    return ws_sincos_quadrant(r, ws_cvt_i(q), c);
}

/* sin, cos of 2 pi u for u in [0, 1]: the reduction u - q/4 is exact */
inline wsf ws_sincos_2pi(wsf u, wsf* c)
{
    wsf q = rint(4.0f * u);
    return ws_sincos_quadrant(WS_TWO_PI * (u - 0.25f * q), ws_cvt_i(q), c);
}

/* --- random numbers -------------------------------------------------------------------- */

/* Philox4x32-10 of counters (c0, c1, c2, c3) under key (k0, k1), in place */
inline void ws_philox(wsu* c0, wsu* c1, wsu* c2, wsu* c3, uint k0, uint k1)
{
    for (int round = 0; round < 10; ++round) {
        wsu hi0 = mul_hi(*c0, (wsu)0xD2511F53u), lo0 = *c0 * 0xD2511F53u;
        wsu hi1 = mul_hi(*c2, (wsu)0xCD9E8D57u), lo1 = *c2 * 0xCD9E8D57u;
        *c0 = hi1 ^ *c1 ^ k0;
        *c1 = lo1;
        *c2 = hi0 ^ *c3 ^ k1;
        *c3 = lo0;
        k0 += 0x9E3779B9u;
        k1 += 0xBB67AE85u;
    }
}

/* Philox words of features idx of (key, object) for one call */
inline void ws_draw(uint2 key, int object, wsi idx, uint call, wsu* r0, wsu* r1, wsu* r2,
                    wsu* r3)
{
    *r0 = (wsu)key.x;
    *r1 = (wsu)key.y;
    *r2 = (wsu)(uint)object;
#if WS_LANES == 1
    *r3 = as_uint(idx);
#else
    *r3 = WS_CAT(as_uint, WS_LANES)(idx);
#endif
    ws_philox(r0, r1, r2, r3, call, WS_PHILOX_KEY1);
}

inline wsf ws_u01(wsu r) { return ws_cvt_f(r >> 8) * (1.0f / 16777216.0f); }        /* [0,1) */
inline wsf ws_u01_open(wsu r) { return ws_cvt_f((r >> 8) + 1) * (1.0f / 16777216.0f); } /* (0,1] */

/* Box-Muller: two independent N(0,1) per lane from two words */
inline wsf ws_normal2(wsu r0, wsu r1, wsf* second)
{
    wsf rad = sqrt(-2.0f * ws_log(ws_u01_open(r0)));
    wsf c, s = ws_sincos_2pi(ws_u01(r1), &c);
    *second = rad * s;
    return rad * c;
}

/* The low bytes of a call's words are unused by ws_u01*: together a fresh 32-bit word. */
inline wsu ws_low_bytes(wsu r0, wsu r1, wsu r2, wsu r3)
{
    return (r0 & 255u) | ((r1 & 255u) << 8) | ((r2 & 255u) << 16) | (r3 << 24);
}

/* Gamma(shape a, scale 1) per lane by Marsaglia & Tsang (2000); for a < 1 the standard
 * boost G(a) = G(a + 1) U^(1/a), U from the accepting call's spare low bytes (independent
 * of the acceptance test). Acceptance is >= 0.95 per trial for every shape. */
inline wsf ws_gamma(float a, uint2 key, int object, wsi idx)
{
    float ab = a < 1.0f ? a + 1.0f : a;
    float dd = ab - 1.0f / 3.0f, cc = rsqrt(9.0f * dd);
    wsf g = (wsf)dd;
    wsu boost = (wsu)0u;
    wsi todo = (wsi)(WS_LANES == 1 ? 1 : -1);   /* all lanes pending, in "true" encoding */
    for (int call = 0; call < WS_GAMMA_CALLS && ws_any(todo); ++call) {
        wsu r0, r1, r2, r3;
        ws_draw(key, object, idx, WS_CALL_GAMMA + (uint)call, &r0, &r1, &r2, &r3);
        wsf x1, x0 = ws_normal2(r0, r1, &x1);
        wsu low = ws_low_bytes(r0, r1, r2, r3);
        wsf v0 = 1.0f + cc * x0, v1 = 1.0f + cc * x1;
        v0 = v0 * v0 * v0;
        v1 = v1 * v1 * v1;
        wsi ok0 = (v0 > 0.0f) & (ws_log(ws_u01_open(r2))
                                 < 0.5f * x0 * x0 + dd - dd * v0 + dd * ws_log(fmax(v0, 1e-30f)));
        wsi ok1 = (v1 > 0.0f) & (ws_log(ws_u01_open(r3))
                                 < 0.5f * x1 * x1 + dd - dd * v1 + dd * ws_log(fmax(v1, 1e-30f)));
        wsi take0 = todo & ok0, take1 = todo & !ok0 & ok1;
        g = select(g, dd * v0, take0);
        g = select(g, dd * v1, take1);
        boost = select(boost, low, take0 | take1);
        todo = todo & !(take0 | take1);
    }
    if (a < 1.0f) g *= pow(ws_u01_open(boost), 1.0f / a);
    return g;
}

/* signed periodic order per lane: |n| from the host's CDF table (cdf[m] = P(|n| <= m),
 * last entry exactly 1; weight_space.periodic_order_cdf), counted by a uniform-trip scan,
 * and a random sign */
inline wsf ws_periodic_order(__global const float* cdf, int count, wsu r, wsu sign_bit)
{
    wsf u = ws_u01(r), n = (wsf)0.0f;
    for (int m = 0; m < count - 1; ++m)
        n += select((wsf)0.0f, (wsf)1.0f, u >= cdf[m]);
    return select(n, -n, sign_bit != 0u);
}

/* --- features ---------------------------------------------------------------------------- */

/* Each kernel's frequency law (lib/gp_kernels/<name>.h, spectral part): generated. */
/* @kinds gp_kernels spectral */

/* Features idx = i0 .. i0 + WS_LANES - 1 of realization `key` of GPIS `object`: frequency
 * theta, phase tau, weight w (w = 0 for idx >= M, so chunks may overrun M). order_cdf /
 * order_count: the object's periodic order table (unused by SE and RQ). The thin-plate
 * kernel has no spectral measure: theta is NaN. */
inline void ws_features(GpKernel k, __global const float* order_cdf, int order_count,
                        uint2 key, int object, int i0, int M, wsf* tx, wsf* ty, wsf* tz,
                        wsf* tau, wsf* w)
{
    wsi idx = i0 + WS_IOTA;
    wsu r0, r1, r2, r3;
    ws_draw(key, object, idx, WS_CALL_MAIN, &r0, &r1, &r2, &r3);
    wsf z1, z0 = ws_normal2(r0, r1, &z1);
    wsf wv, z2 = ws_normal2(r2, r3, &wv);
    *w = select((wsf)0.0f, wv, idx < M);
    *tau = WS_TWO_PI * ws_u01(ws_low_bytes(r0, r1, r2, r3));
    float3 sa = sqrt(k.aniso.xyz);
    wsf s = gp_kernel_ws_scale(k.kind, k, key, object, idx);   /* NaN: no spectral density */
    *tx = sa.x * s * z0;
    *ty = sa.y * s * z1;
    *tz = sa.z * s * z2;
    if (GP_KERNEL_IS_PERIODIC_ORDERS(k.kind)) {
        ws_draw(key, object, idx, WS_CALL_ORDERS, &r0, &r1, &r2, &r3);
        float3 f = (WS_TWO_PI * k.w) * sa;
        *tx += f.x * ws_periodic_order(order_cdf, order_count, r0, r3 & 1u);
        *ty += f.y * ws_periodic_order(order_cdf, order_count, r1, r3 & 2u);
        *tz += f.z * ws_periodic_order(order_cdf, order_count, r2, r3 & 4u);
    }
}

/* Feature cache: WS_CACHE_FLOATS floats, per chunk of WS_LANES features theta_x,
 * theta_y, theta_z, tau, w, then the realization's rounding moments (WsMoments, at
 * WS_CACHE_MOMENTS). A float array read by vloadn, not an array of vectors: the stack of a
 * PoCL work-item is not aligned to whole vectors, and aligned vector moves on it fault. */
#define WS_CACHE_MOMENTS (5 * WS_CACHE_FEATURES)
#define WS_CACHE_FLOATS (5 * WS_CACHE_FEATURES + 12)
#if WS_LANES == 1
#define ws_vload(i, p) ((p)[i])
#define ws_vstore(v, i, p) ((p)[i] = (v))
#else
#define ws_vload(i, p) WS_CAT(vload, WS_LANES)(i, p)
#define ws_vstore(v, i, p) WS_CAT(vstore, WS_LANES)(v, i, p)
#endif

/* Sums over a realization's features that ws_affine's rounding allowance needs: with
 * a = |theta| per feature and e = 2 a . xabs + tau + 2 its phase's error scale (in eps),
 *   sum w^2 e^2 = 4 xabs^T S xabs + 4 V . xabs + C,
 *   S = sum w^2 a a^T, V = sum w^2 (tau + 2) a, C = sum w^2 (tau + 2)^2,
 * every term non-negative, so the expansion rounds like the direct sum. They depend on the
 * features only, not on the interval: a cached search computes them once per ray instead
 * of ~11 operations per feature per bound. w1 = sum |w| scales WS_SINCOS_ERR. */
typedef struct {
    float sxx, syy, szz, sxy, sxz, syz, vx, vy, vz, c, w2, w1;
} WsMoments;

typedef struct {
    wsf sxx, syy, szz, sxy, sxz, syz, vx, vy, vz, c, w2, w1;
} WsMomentSums;

inline void ws_moments_add(WsMomentSums* m, wsf tx, wsf ty, wsf tz, wsf tau, wsf w)
{
    wsf ww = w * w, ax = fabs(tx), ay = fabs(ty), az = fabs(tz), t2 = tau + 2.0f;
    wsf wx = ww * ax, wy = ww * ay, wz = ww * az;
    m->sxx += wx * ax;
    m->syy += wy * ay;
    m->szz += wz * az;
    m->sxy += wx * ay;
    m->sxz += wx * az;
    m->syz += wy * az;
    m->vx += wx * t2;
    m->vy += wy * t2;
    m->vz += wz * t2;
    m->c += ww * t2 * t2;
    m->w2 += ww;
    m->w1 += fabs(w);
}

inline WsMoments ws_moments_total(const WsMomentSums* m)
{
    WsMoments r = {ws_hsum(m->sxx), ws_hsum(m->syy), ws_hsum(m->szz), ws_hsum(m->sxy),
                   ws_hsum(m->sxz), ws_hsum(m->syz), ws_hsum(m->vx), ws_hsum(m->vy),
                   ws_hsum(m->vz), ws_hsum(m->c), ws_hsum(m->w2), ws_hsum(m->w1)};
    return r;
}

/* sum w^2 e^2 for the phase error scales e at |x| <= xabs (componentwise) */
inline float ws_moments_phase2(WsMoments m, float3 xabs)
{
    float3 sx = (float3)(m.sxx * xabs.x + m.sxy * xabs.y + m.sxz * xabs.z,
                         m.sxy * xabs.x + m.syy * xabs.y + m.syz * xabs.z,
                         m.sxz * xabs.x + m.syz * xabs.y + m.szz * xabs.z);
    return 4.0f * dot(xabs, sx) + 4.0f * dot((float3)(m.vx, m.vy, m.vz), xabs) + m.c;
}

inline void ws_fill_cache(GpKernel k, __global const float* order_cdf, int order_count,
                          uint2 key, int object, int M, float* cache)
{
    WsMomentSums ms = {0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f};
    for (int i0 = 0; i0 < M; i0 += WS_LANES) {
        wsf tx, ty, tz, tau, w;
        ws_features(k, order_cdf, order_count, key, object, i0, M, &tx, &ty, &tz, &tau, &w);
        int j = 5 * (i0 / WS_LANES);
        ws_vstore(tx, j, cache);
        ws_vstore(ty, j + 1, cache);
        ws_vstore(tz, j + 2, cache);
        ws_vstore(tau, j + 3, cache);
        ws_vstore(w, j + 4, cache);
        ws_moments_add(&ms, tx, ty, tz, tau, w);
    }
    *(WsMoments*)(cache + WS_CACHE_MOMENTS) = ws_moments_total(&ms);
}

/* Features i0 .. i0 + WS_LANES - 1 as ws_features, read from `cache` when it is given
 * (filled by ws_fill_cache), else regenerated. */
inline void ws_features_of(const float* cache, GpKernel k, __global const float* order_cdf,
                           int order_count, uint2 key, int object, int i0, int M, wsf* tx,
                           wsf* ty, wsf* tz, wsf* tau, wsf* w)
{
    if (cache) {
        int j = 5 * (i0 / WS_LANES);
        *tx = ws_vload(j, cache);
        *ty = ws_vload(j + 1, cache);
        *tz = ws_vload(j + 2, cache);
        *tau = ws_vload(j + 3, cache);
        *w = ws_vload(j + 4, cache);
    } else {
        ws_features(k, order_cdf, order_count, key, object, i0, M, tx, ty, tz, tau, w);
    }
}

/* Feature i alone (for debugging and tests; the hot loops use ws_features). */
inline void ws_feature(GpKernel k, __global const float* order_cdf, int order_count,
                       uint2 key, int object, int i, float3* theta, float* tau, float* w)
{
    wsf tx, ty, tz, tv, wv;
    ws_features(k, order_cdf, order_count, key, object, i, i + 1, &tx, &ty, &tz, &tv, &wv);
    *theta = (float3)(ws_lane0(tx), ws_lane0(ty), ws_lane0(tz));
    *tau = ws_lane0(tv);
    *w = ws_lane0(wv);
}

/* E[(theta . d)^2] = Var(d/dt f(o + t d)) / k(0), the spectral second moment along d:
 * sets the natural marching step (and Rice's crossing rate). */
inline float ws_lambda2(GpKernel k, float3 d)
{
    float3 ad = k.aniso.xyz * d * d;
    float s = ad.x + ad.y + ad.z;
    return gp_kernel_ws_lambda2(k.kind, k, s);
}

inline float ws_amplitude(GpKernel k, int M) { return sqrt(2.0f * k.sigma2 / (float)M); }

/* Value of the realization at x, with its analytic gradient (features from `cache` if
 * given: ws_features_of). */
inline float ws_eval_cached(const float* cache, GpKernel k, __global const MeanNode* mean,
                            int mean_count, __global const float* order_cdf, int order_count,
                            int M, uint2 key, int object, float3 x, float3* grad)
{
    wsf v = 0.0f, gx = 0.0f, gy = 0.0f, gz = 0.0f;
    for (int i0 = 0; i0 < M; i0 += WS_LANES) {
        wsf tx, ty, tz, tau, w;
        ws_features_of(cache, k, order_cdf, order_count, key, object, i0, M, &tx, &ty, &tz,
                       &tau, &w);
        wsf c, s = ws_sincos(tx * x.x + ty * x.y + tz * x.z + tau, &c);
        v += w * c;
        s *= w;
        gx -= s * tx;
        gy -= s * ty;
        gz -= s * tz;
    }
    float amp = ws_amplitude(k, M);
    float3 gm;
    float mu = gp_mean_eval(mean, mean_count, x, &gm);
    *grad = amp * (float3)(ws_hsum(gx), ws_hsum(gy), ws_hsum(gz)) + gm;
    return amp * ws_hsum(v) + mu;
}

inline float ws_eval(GpKernel k, __global const MeanNode* mean, int mean_count,
                     __global const float* order_cdf, int order_count, int M, uint2 key,
                     int object, float3 x, float3* grad)
{
    return ws_eval_cached(0, k, mean, mean_count, order_cdf, order_count, M, key, object, x,
                          grad);
}

/* Affine form of the zero-mean part along a ray segment: for every t with |t - tm| <= h,
 *   f(o + t d) - mean = f0 + f1 (t - tm) + e,   |e| <= err (+ round, for float rounding).
 * Per feature, with c = theta.x(tm) + tau, beta = theta.d, x = beta (t - tm), |x| <= bh:
 *   cos(c + x) = cos c (1 - delta) - x sin c + rho sin c,
 *   0 <= delta = 1 - cos x <= bh^2/2,  |rho| = |x - sin x| <= bh^3/6,
 * so centre cos c (1 - bh^2/4), slope -beta sin c, error |cos c| bh^2/4 + |sin c| bh^3/6:
 * half the first-order Lagrange remainder bh^2/2 near extrema (where roots graze). Where
 * the trivial range [-1, 1] is narrower (bh >~ 1.5) it is used instead.
 * Rounding: a feature's computed phase is off by e_i ~ eps (|theta| . |x| + tau + few);
 * the M errors are independent, so they add like a random walk, and `round` is 4 standard
 * deviations of it (the worst-case sum, sqrt(M) times larger, never occurs; the tests check
 * that device point evaluations always lie inside the bounds). */
typedef struct {
    float f0;
    float f1;
    float err;
    float round;
} WsAffine;

inline WsAffine ws_affine(const float* cache, GpKernel k, __global const float* order_cdf,
                          int order_count, int M, uint2 key, int object, float3 o, float3 d,
                          float tm, float h)
{
    float3 xm = o + tm * d;
    float3 xabs = fabs(o) + (fabs(tm) + h) * fabs(d);
    float hh = 0.5f * h * h;
    wsf f0 = 0.0f, f1 = 0.0f, err = 0.0f;
    WsMomentSums ms = {0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f};
    for (int i0 = 0; i0 < M; i0 += WS_LANES) {
        wsf tx, ty, tz, tau, w;
        ws_features_of(cache, k, order_cdf, order_count, key, object, i0, M, &tx, &ty, &tz,
                       &tau, &w);
        wsf beta = tx * d.x + ty * d.y + tz * d.z;
        wsf c, s = ws_sincos(tx * xm.x + ty * xm.y + tz * xm.z + tau, &c);
        /* the header's terms, factored for fewer vector operations: sb = |B| h = |s| bh,
         * q = bh^2 / 2, E = q (|c| / 2 + sb / 3) */
        wsf sb = fabs(s * beta) * h, q = beta * beta * hh;
        wsf E = q * (sb * (1.0f / 3.0f) + 0.5f * fabs(c));
        wsi trivial = sb + E > 1.0f;
        wsf wt = select(w, (wsf)0.0f, trivial);
        f0 += wt * (c - c * (0.5f * q));
        f1 -= (wt * s) * beta;
        err += fabs(w) * select(E, (wsf)1.0f, trivial);
        if (!cache) ws_moments_add(&ms, tx, ty, tz, tau, w);   /* regenerated features */
    }
    WsMoments mo = cache ? *(const WsMoments*)(cache + WS_CACHE_MOMENTS) : ws_moments_total(&ms);
    float amp = ws_amplitude(k, M);
    WsAffine out;
    out.f0 = amp * ws_hsum(f0);
    out.f1 = amp * ws_hsum(f1);
    /* The polynomials' own error eps_sc: computed c, s are within it of the exact ones, so
     * A is off by <= eps_sc (1 + q/2), B (t - tm) by <= eps_sc bh and E by <= eps_sc (q/2 +
     * q bh / 3). A feature kept (not trivial) has |B| h + E <= 1 with max(|c|, |s|) >=
     * 1/sqrt 2, so bh <= 2.4 and q <= 2.9: those add up to < 16 eps_sc per unit weight (the
     * trivial range [-1, 1] needs nothing). */
    out.err = amp * (ws_hsum(err) + 16.0f * WS_SINCOS_ERR * mo.w1);
    /* phase errors, plus the summation's own rounding (~sqrt(M) eps per unit weight), plus
     * the polynomials' error of a point evaluation (which T.round stands for) */
    out.round = 4.0f * amp * FLT_EPSILON * sqrt(ws_moments_phase2(mo, xabs) + (float)M * mo.w2)
              + amp * WS_SINCOS_ERR * mo.w1;
    return out;
}
