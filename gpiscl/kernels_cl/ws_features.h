/* Weight-space ("Global infinity") GPIS realizations: random Fourier features
 *   f(x) = mean(x) + sqrt(k(0)) sqrt(2/M) sum_i w_i cos(theta_i . x + tau_i),
 * w_i ~ N(0,1), tau_i ~ U[0, 2 pi), theta_i from the kernel's normalised spectral measure
 * (gpiscl/host/gp/spectral.py derives each sampler; weight_space.py is the numpy twin).
 *
 * Memory: features are never stored. Feature i is a pure function of
 * (realization key, object, i), regenerated from Philox whenever it is needed, so a path's
 * realization costs O(1) memory (the uint2 key) whatever M is and however many paths are
 * in flight; the price is one Philox call (two for periodic/RQ) per feature evaluation.
 * Streams: counter (key.x, key.y, object, i), Philox key (call, WS_PHILOX_KEY1). rng.h uses
 * key word 1 = 0x6a09e667, so the two generators can never produce the same stream.
 * Realization key: (pixel, sample) of the path, or (R, 0xffffffff) for a fixed
 * realization R (no path has sample index 0xffffffff, so the two never coincide).
 *
 * Precision: float32 is enough. Values are O(sigma) and roots are wanted to ~1e-4 l,
 * i.e. f to ~1e-4 sigma, far above float's 6e-8 relative rounding. The one place that
 * needs care is the phase theta . x: its absolute error is ~eps |theta| |x|, so the
 * realization is smooth to 1e-3 rad only while |theta| |x| < ~1e4, e.g. |x| < 50 l. Scenes
 * should keep GPIS objects within a few hundred length scales of the world origin. The
 * interval bounds account for this error explicitly (ws_affine's `round`).
 */
#define WS_PHILOX_KEY1 0x3c6ef372u   /* SHA-256 IV word 2; rng.h uses word 0 */
#define WS_CALL_MAIN 0u              /* 3 normals (frequency), w, tau */
#define WS_CALL_ORDERS 1u            /* periodic orders and signs */
#define WS_CALL_GAMMA 2u             /* first RQ gamma call; two trials per call */
#define WS_GAMMA_CALLS 24            /* P(all 48 trials rejected) < 0.05^48 */
#define WS_TWO_PI 6.28318530717958648f

inline uint4 ws_philox(uint2 key, int object, int i, uint call)
{
    philox4x32_ctr_t c = {{key.x, key.y, (uint)object, (uint)i}};
    philox4x32_key_t k = {{call, WS_PHILOX_KEY1}};
    philox4x32_ctr_t r = philox4x32(c, k);
    return (uint4)(r.v[0], r.v[1], r.v[2], r.v[3]);
}

/* (0, 1]: safe for log. 24 high bits, exactly representable. */
inline float ws_u01_open(uint r) { return (float)((r >> 8) + 1u) * (1.0f / 16777216.0f); }

/* [0, 1) */
inline float ws_u01(uint r) { return (float)(r >> 8) * (1.0f / 16777216.0f); }

/* Box-Muller: two independent N(0,1) from two uniform words. */
inline float2 ws_normal2(uint r0, uint r1)
{
    float rad = sqrt(-2.0f * log(ws_u01_open(r0)));
    float s, c = sincos(WS_TWO_PI * ws_u01(r1), &s);
    return (float2)(rad * c, rad * s);
}

/* The low bytes of a Philox output are unused by ws_u01*: together a fresh 32-bit word. */
inline uint ws_low_bytes(uint4 r)
{
    return (r.x & 255u) | ((r.y & 255u) << 8) | ((r.z & 255u) << 16) | (r.w << 24);
}

/* Gamma(shape a, scale 1) by Marsaglia & Tsang (2000); for a < 1 the standard boost
 * G(a) = G(a + 1) U^(1/a). Each Philox call feeds two trials (normal by Box-Muller, its
 * own acceptance uniform); acceptance is >= 0.95 per trial for every shape. */
inline float ws_gamma(float a, uint2 key, int object, int i)
{
    float ab = a < 1.0f ? a + 1.0f : a;
    float dd = ab - 1.0f / 3.0f, cc = rsqrt(9.0f * dd);
    float g = dd;   /* unreachable fallback (see WS_GAMMA_CALLS) */
    uint boost = 0u;
    for (int call = 0; call < WS_GAMMA_CALLS; ++call) {
        uint4 r = ws_philox(key, object, i, WS_CALL_GAMMA + (uint)call);
        boost = ws_low_bytes(r);   /* unused by the trials: independent of acceptance */
        float2 x = ws_normal2(r.x, r.y);
        float v0 = 1.0f + cc * x.x, v1 = 1.0f + cc * x.y;
        v0 = v0 * v0 * v0;
        v1 = v1 * v1 * v1;
        if (v0 > 0.0f && log(ws_u01_open(r.z)) < 0.5f * x.x * x.x + dd - dd * v0 + dd * log(v0)) {
            g = dd * v0;
            break;
        }
        if (v1 > 0.0f && log(ws_u01_open(r.w)) < 0.5f * x.y * x.y + dd - dd * v1 + dd * log(v1)) {
            g = dd * v1;
            break;
        }
    }
    if (a < 1.0f) g *= pow(ws_u01_open(boost), 1.0f / a);
    return g;
}

/* |n| ~ P(|n| = m) by the host's CDF table (weight_space.periodic_order_cdf: cdf[m] =
 * P(|n| <= m), last entry exactly 1), then a random sign. Branch-free binary search with
 * a trip count that depends only on count, so work-items stay in lockstep. */
inline float ws_periodic_order(__global const float* cdf, int count, uint r, uint sign_bit)
{
    float u = ws_u01(r);
    int n = 0;
    int s = 1;
    while (2 * s <= count) s *= 2;
    for (; s > 0; s >>= 1)
        if (n + s <= count && cdf[n + s - 1] <= u) n += s;
    return sign_bit ? -(float)n : (float)n;
}

inline float3 ws_sqrt_aniso(GpKernel k)
{
    return sqrt(k.aniso.xyz);
}

/* Feature i of realization `key` of GPIS `object`: frequency theta, phase tau, weight w.
 * order_cdf/order_count: the periodic order table of this object's kernel (unused for
 * SE and RQ). thin_plate has no spectral measure: theta is NaN. */
inline void ws_feature(GpKernel k, __global const float* order_cdf, int order_count,
                       uint2 key, int object, int i, float3* theta, float* tau, float* w)
{
    uint4 r = ws_philox(key, object, i, WS_CALL_MAIN);
    float2 g01 = ws_normal2(r.x, r.y), g23 = ws_normal2(r.z, r.w);
    float3 z = (float3)(g01, g23.x);
    uint low = ws_low_bytes(r);
    *w = g23.y;
    *tau = WS_TWO_PI * ws_u01(low);
    float3 sa = ws_sqrt_aniso(k);
    if (k.kind == GP_KERNEL_SQUARED_EXPONENTIAL) {
        *theta = sa * z / k.length_scale;
    } else if (k.kind == GP_KERNEL_RATIONAL_QUADRATIC) {
        /* tau_g ~ Gamma(shape a, rate a l^2); theta = sqrt(tau_g) sqrt(A) z */
        float gam = ws_gamma(k.alpha, key, object, i);
        *theta = sa * z * sqrt(gam / (k.alpha * k.length_scale * k.length_scale));
    } else if (k.kind == GP_KERNEL_PERIODIC || k.kind == GP_KERNEL_LOCALLY_PERIODIC) {
        uint4 q = ws_philox(key, object, i, WS_CALL_ORDERS);
        float3 n = (float3)(ws_periodic_order(order_cdf, order_count, q.x, q.w & 1u),
                            ws_periodic_order(order_cdf, order_count, q.y, q.w & 2u),
                            ws_periodic_order(order_cdf, order_count, q.z, q.w & 4u));
        *theta = (WS_TWO_PI * k.w) * sa * n;
        if (k.kind == GP_KERNEL_LOCALLY_PERIODIC) *theta += sa * z / k.se_length_scale;
    } else {
        *theta = (float3)(NAN);
    }
}

/* E[(theta . d)^2] = lambda_2 / lambda_0 along d: the spectral second moment, i.e.
 * Var(d/dt f(o + t d)) / k(0). Sets the natural step of ray marching (and Rice's rate). */
inline float ws_lambda2(GpKernel k, float3 d)
{
    float3 ad = k.aniso.xyz * d * d;
    float s = ad.x + ad.y + ad.z;
    if (k.kind == GP_KERNEL_PERIODIC || k.kind == GP_KERNEL_LOCALLY_PERIODIC) {
        /* per axis E[n^2] = 1 / l^2 (n is Skellam(z/2, z/2), z = 1/l^2) */
        float c = WS_TWO_PI * k.w / k.length_scale;
        float v = c * c * s;
        if (k.kind == GP_KERNEL_LOCALLY_PERIODIC)
            v += s / (k.se_length_scale * k.se_length_scale);
        return v;
    }
    return s / (k.length_scale * k.length_scale);   /* SE, and RQ since E[tau_g] = 1/l^2 */
}

inline float ws_amplitude(GpKernel k, int M)
{
    return sqrt(2.0f * k.sigma2 / (float)M);
}

/* Value of the realization at x, with its analytic gradient. */
inline float ws_eval(GpKernel k, __global const MeanNode* mean, int mean_count,
                     __global const float* order_cdf, int order_count, int M, uint2 key,
                     int object, float3 x, float3* grad)
{
    float v = 0.0f;
    float3 g = (float3)(0.0f);
    for (int i = 0; i < M; ++i) {
        float3 th;
        float tau, w;
        ws_feature(k, order_cdf, order_count, key, object, i, &th, &tau, &w);
        float s, c = sincos(dot(th, x) + tau, &s);
        v += w * c;
        g -= (w * s) * th;
    }
    float amp = ws_amplitude(k, M);
    float3 gm;
    float mu = gp_mean_eval(mean, mean_count, x, &gm);
    *grad = amp * g + gm;
    return amp * v + mu;
}

/* Affine form of the zero-mean part along a ray segment: for every t with |t - tm| <= h,
 *   f(o + t d) - mean = f0 + f1 (t - tm) + e,   |e| <= err (+ round for float rounding).
 * Per feature, with c = theta.x(tm) + tau, beta = theta.d, x = beta (t - tm), |x| <= bh:
 *   cos(c + x) = cos c (1 - delta) - sin c x + sin c rho,
 *   0 <= delta = 1 - cos x <= bh^2/2,  |rho| = |x - sin x| <= bh^3/6,
 * so centre cos c (1 - bh^2/4), slope -beta sin c, error |cos c| bh^2/4 + |sin c| bh^3/6
 * (half the first-order Lagrange remainder bh^2/2 near extrema, where roots graze). When
 * the trivial range [-1, 1] is narrower (bh >~ 1.5), it is used instead.
 * Rounding: a feature's computed phase is off by e_i ~ eps (|theta| . |x| + tau + few);
 * the M errors are independent, so they add like a random walk: round is 4 standard
 * deviations of that walk (worst-case sum would be sqrt(M) times larger and never occurs;
 * tests/test_ws_intersect.py checks containment of device evaluations exactly). */
typedef struct {
    float f0;
    float f1;
    float err;
    float round;
} WsAffine;

inline WsAffine ws_affine(GpKernel k, __global const float* order_cdf, int order_count,
                          int M, uint2 key, int object, float3 o, float3 d, float tm, float h)
{
    float3 xm = o + tm * d;
    float3 xabs = fabs(o) + (fabs(tm) + h) * fabs(d);
    float f0 = 0.0f, f1 = 0.0f, err = 0.0f, r2 = 0.0f, w2 = 0.0f;
    for (int i = 0; i < M; ++i) {
        float3 th;
        float tau, w;
        ws_feature(k, order_cdf, order_count, key, object, i, &th, &tau, &w);
        float beta = dot(th, d);
        float s, c = sincos(dot(th, xm) + tau, &s);
        float bh = fabs(beta) * h, q = 0.5f * bh * bh;
        float A = c * (1.0f - 0.5f * q);
        float B = -s * beta;
        float E = 0.5f * fabs(c) * q + fabs(s) * q * bh * (1.0f / 3.0f);
        int trivial = fabs(B) * h + E > 1.0f;
        A = trivial ? 0.0f : A;
        B = trivial ? 0.0f : B;
        E = trivial ? 1.0f : E;
        f0 += w * A;
        f1 += w * B;
        err += fabs(w) * E;
        float e = 6.0f * dot(fabs(th), xabs) + 2.0f * tau + 4.0f;
        r2 += w * w * e * e;
        w2 += w * w;
    }
    float amp = ws_amplitude(k, M);
    WsAffine out;
    out.f0 = amp * f0;
    out.f1 = amp * f1;
    out.err = amp * err;
    /* phase errors plus the summation's own rounding (~sqrt(M) eps per unit weight) */
    out.round = 4.0f * amp * FLT_EPSILON * sqrt(r2 + (float)M * w2);
    return out;
}
