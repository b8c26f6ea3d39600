/* Plain C baselines for tools/bench_weight_space.py: the weight-space realization and its
 * certified first-root search over stored features (theta, tau, w as float32 arrays), the
 * "same data" the device regenerates from Philox. Built by the tool at run time with
 *   gcc -O3 -march=native -ffast-math -fopenmp -shared -fPIC
 * and called through ctypes; OpenMP spreads points / rays over the cores.
 *
 * Two builds: the plain loops below, where gcc fuses sinf and cosf of one argument into
 * scalar sincosf calls, and -DWS_SPLIT_SINCOS, which takes sin and cos in separate loops
 * over chunks of features so that gcc calls glibc's vector sinf/cosf (libmvec): the same
 * arithmetic, ~10x faster on AVX-512.
 *
 * The search mirrors ws_first_root_counted (kernels_cl/lib/ws_intersect.h) for one mean,
 * a sphere of radius `radius` at the origin (Lipschitz 1), so that rays per second compare
 * like for like: same bound, same step rules, same evaluation counts up to float rounding.
 */
#include <float.h>
#include <math.h>
#include <stddef.h>

#define T_INF 1e30f
#define CHUNK 64

/* cos and sin of p[0..n) into c, s: separate loops, so each is one vector libm call */
static inline void split_sincos(int n, const float* p, float* c, float* s)
{
    for (int i = 0; i < n; ++i) c[i] = cosf(p[i]);
    for (int i = 0; i < n; ++i) s[i] = sinf(p[i]);
}

typedef struct {
    const float *tx, *ty, *tz, *tau, *w;   /* M features, structure of arrays */
    int m;
    float amp;                             /* sqrt(2 sigma^2 / M) */
} Feats;

/* f(x) and its gradient: zero-mean part plus the sphere mean */
static float eval_point(const Feats* F, float radius, const float x[3], float g[3])
{
    float v = 0.0f, gx = 0.0f, gy = 0.0f, gz = 0.0f;
#ifdef WS_SPLIT_SINCOS
    for (int i0 = 0; i0 < F->m; i0 += CHUNK) {
        int n = F->m - i0 < CHUNK ? F->m - i0 : CHUNK;
        const float *tx = F->tx + i0, *ty = F->ty + i0, *tz = F->tz + i0, *w = F->w + i0;
        float p[CHUNK], c[CHUNK], sn[CHUNK];
        for (int i = 0; i < n; ++i)
            p[i] = tx[i] * x[0] + ty[i] * x[1] + tz[i] * x[2] + F->tau[i0 + i];
        split_sincos(n, p, c, sn);
        for (int i = 0; i < n; ++i) {
            float s = w[i] * sn[i];
            v += w[i] * c[i];
            gx -= s * tx[i];
            gy -= s * ty[i];
            gz -= s * tz[i];
        }
    }
#else
#pragma omp simd reduction(+ : v, gx, gy, gz)
    for (int i = 0; i < F->m; ++i) {
        float p = F->tx[i] * x[0] + F->ty[i] * x[1] + F->tz[i] * x[2] + F->tau[i];
        float c = cosf(p), s = F->w[i] * sinf(p);
        v += F->w[i] * c;
        gx -= s * F->tx[i];
        gy -= s * F->ty[i];
        gz -= s * F->tz[i];
    }
#endif
    float r = sqrtf(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
    float inv = r > 0.0f ? 1.0f / r : 0.0f;
    g[0] = F->amp * gx + x[0] * inv;
    g[1] = F->amp * gy + x[1] * inv;
    g[2] = F->amp * gz + x[2] * inv;
    return F->amp * v + r - radius;
}

/* n points x (n, 3): values and gradients (n, 4) = (gx, gy, gz, f) */
void ws_eval_points(int n, const float* x, int m, const float* tx, const float* ty,
                    const float* tz, const float* tau, const float* w, float amp,
                    float radius, float* out)
{
    Feats F = {tx, ty, tz, tau, w, m, amp};
#pragma omp parallel for schedule(static)
    for (int i = 0; i < n; ++i) {
        float g[3];
        float v = eval_point(&F, radius, x + 3 * i, g);
        out[4 * i] = g[0];
        out[4 * i + 1] = g[1];
        out[4 * i + 2] = g[2];
        out[4 * i + 3] = v;
    }
}

typedef struct {
    float lo_k, lo_a, lo_m, lo_b, hi_k, hi_a, hi_m, hi_b, round;
} Tents;

/* one feature's terms of ws_affine, factored as there: sb = |B| h, q = bh^2 / 2 */
#define AFFINE_TERMS(tx, ty, tz, tau, w, c, s)                                          \
    do {                                                                                \
        float beta = tx * d[0] + ty * d[1] + tz * d[2];                                \
        float sb = fabsf(s * beta) * h, q = beta * beta * hh;                          \
        float E = q * (sb * (1.0f / 3.0f) + 0.5f * fabsf(c));                         \
        int trivial = sb + E > 1.0f;                                                   \
        float wt = trivial ? 0.0f : w;                                                 \
        f0 += wt * (c - c * (0.5f * q));                                               \
        f1 -= (wt * s) * beta;                                                         \
        err += fabsf(w) * (trivial ? 1.0f : E);                                        \
    } while (0)

/* ws_features.h's rounding moments (WsMoments) of the features: once per ray, as the
 * device computes them when it fills a search's feature cache */
typedef struct {
    float sxx, syy, szz, sxy, sxz, syz, vx, vy, vz, c, w2, w1;
} Moments;

static Moments moments(const Feats* F)
{
    Moments m = {0};
    for (int i = 0; i < F->m; ++i) {
        float w = F->w[i], ww = w * w, t2 = F->tau[i] + 2.0f;
        float ax = fabsf(F->tx[i]), ay = fabsf(F->ty[i]), az = fabsf(F->tz[i]);
        m.sxx += ww * ax * ax; m.syy += ww * ay * ay; m.szz += ww * az * az;
        m.sxy += ww * ax * ay; m.sxz += ww * ax * az; m.syz += ww * ay * az;
        m.vx += ww * ax * t2; m.vy += ww * ay * t2; m.vz += ww * az * t2;
        m.c += ww * t2 * t2; m.w2 += ww; m.w1 += fabsf(w);
    }
    return m;
}

#define WS_SINCOS_ERR 1e-8f   /* ws_features.h: folded into err (the device's polynomials) */

/* ws_affine + ws_tents of ws_intersect.h, for the sphere mean */
static Tents tents(const Feats* F, const Moments* M, float radius, const float o[3],
                   const float d[3], float a, float b)
{
    float tm = 0.5f * (a + b), h = 0.5f * (b - a);
    float xm[3], xabs[3];
    for (int j = 0; j < 3; ++j) {
        xm[j] = o[j] + tm * d[j];
        xabs[j] = fabsf(o[j]) + (fabsf(tm) + h) * fabsf(d[j]);
    }
    float hh = 0.5f * h * h;
    float f0 = 0.0f, f1 = 0.0f, err = 0.0f;
#ifdef WS_SPLIT_SINCOS
    for (int i0 = 0; i0 < F->m; i0 += CHUNK) {
        int n = F->m - i0 < CHUNK ? F->m - i0 : CHUNK;
        const float *tx = F->tx + i0, *ty = F->ty + i0, *tz = F->tz + i0, *tau = F->tau + i0,
                    *w = F->w + i0;
        float p[CHUNK], c[CHUNK], sn[CHUNK];
        for (int i = 0; i < n; ++i) p[i] = tx[i] * xm[0] + ty[i] * xm[1] + tz[i] * xm[2] + tau[i];
        split_sincos(n, p, c, sn);
        for (int i = 0; i < n; ++i) AFFINE_TERMS(tx[i], ty[i], tz[i], tau[i], w[i], c[i], sn[i]);
    }
#else
#pragma omp simd reduction(+ : f0, f1, err)
    for (int i = 0; i < F->m; ++i) {
        float p = F->tx[i] * xm[0] + F->ty[i] * xm[1] + F->tz[i] * xm[2] + F->tau[i];
        float c = cosf(p), s = sinf(p);
        AFFINE_TERMS(F->tx[i], F->ty[i], F->tz[i], F->tau[i], F->w[i], c, s);
    }
#endif
    float amp = F->amp;
    f0 *= amp;
    f1 *= amp;
    err = amp * (err + 16.0f * WS_SINCOS_ERR * M->w1);
    float sx_[3] = {M->sxx * xabs[0] + M->sxy * xabs[1] + M->sxz * xabs[2],
                    M->sxy * xabs[0] + M->syy * xabs[1] + M->syz * xabs[2],
                    M->sxz * xabs[0] + M->syz * xabs[1] + M->szz * xabs[2]};
    float r2 = 4.0f * (xabs[0] * sx_[0] + xabs[1] * sx_[1] + xabs[2] * sx_[2])
             + 4.0f * (M->vx * xabs[0] + M->vy * xabs[1] + M->vz * xabs[2]) + M->c;
    float af_round = 4.0f * amp * FLT_EPSILON * sqrtf(r2 + (float)F->m * M->w2)
                   + amp * WS_SINCOS_ERR * M->w1;
    float xa[3], xb[3];
    for (int j = 0; j < 3; ++j) {
        xa[j] = o[j] + a * d[j];
        xb[j] = o[j] + b * d[j];
    }
    float ma = sqrtf(xa[0] * xa[0] + xa[1] * xa[1] + xa[2] * xa[2]) - radius;
    float mb = sqrtf(xb[0] * xb[0] + xb[1] * xb[1] + xb[2] * xb[2]) - radius;
    float lt = sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    float ta = fmaxf(fabsf(a), fabsf(b));
    float sx = 0.0f;
    for (int j = 0; j < 3; ++j) sx += fabsf(o[j]) + ta * fabsf(d[j]);
    float round = af_round + 8.0f * FLT_EPSILON * (fabsf(ma) + fabsf(mb) + sx);
    float r = err + round, inv2l = 0.5f / lt;
    Tents T;
    T.round = round;
    T.lo_k = fminf(fmaxf(tm + (ma - mb) * inv2l, a), b);
    T.hi_k = fminf(fmaxf(tm + (mb - ma) * inv2l, a), b);
    float c0 = f0 - f1 * h, c1 = f0 + f1 * h;
    T.lo_a = c0 - r + fmaxf(ma, mb - lt * (b - a));
    T.lo_b = c1 - r + fmaxf(ma - lt * (b - a), mb);
    T.lo_m = f0 + f1 * (T.lo_k - tm) - r + fmaxf(ma - lt * (T.lo_k - a), mb - lt * (b - T.lo_k));
    T.hi_a = c0 + r + fminf(ma, mb + lt * (b - a));
    T.hi_b = c1 + r + fminf(ma + lt * (b - a), mb);
    T.hi_m = f0 + f1 * (T.hi_k - tm) + r + fminf(ma + lt * (T.hi_k - a), mb + lt * (b - T.hi_k));
    return T;
}

static float first_negative(float a, float pa, float k, float pk, float b, float pb)
{
    if (pa < 0.0f) return a;
    if (pk < 0.0f) return a + (k - a) * (pa / (pa - pk));
    if (pb < 0.0f) return k + (b - k) * (pk / (pk - pb));
    return T_INF;
}

/* ws_first_root_counted's loop; returns t or T_INF, *evals the M-feature passes */
static float first_root(const Feats* F, float radius, float h0, const float o[3],
                        const float d[3], float t0, float t1, float tol, int max_iter,
                        int* evals)
{
    float ol = sqrtf(o[0] * o[0] + o[1] * o[1] + o[2] * o[2]);
    float dl = sqrtf(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    float tres = 4.0f * FLT_EPSILON * (fabsf(t0) + fabsf(t1) + ol / dl);
    tol = fmaxf(tol, 2.0f * tres);
    float hmin = 0.875f * tol;
    Moments mo = moments(F);
    float x[3], g[3];
    for (int j = 0; j < 3; ++j) x[j] = o[j] + t0 * d[j];
    float f = eval_point(F, radius, x, g);
    int ev = 1;
    float sgn = f < 0.0f ? -1.0f : 1.0f;
    float phi = sgn * f, dphi = sgn * (g[0] * d[0] + g[1] * d[1] + g[2] * d[2]);
    float step = dphi < 0.0f ? fminf(fmaxf(phi / -dphi, hmin), h0) : h0;
    float a = t0, c = T_INF, hit = T_INF, noise = 0.0f;
    int done = 0, g_at_c = 0, walk = 0;
    for (int it = 0; it < max_iter && !done; ++it) {
        if (c - a <= tol) {
            if (sgn > 0.0f) {
                hit = c;
                done = 1;
            } else {
                sgn = 1.0f;
                a = c;
                c = T_INF;
                step = hmin;
                g_at_c = 0;
            }
            continue;
        }
        if (a >= t1) {
            done = 1;
            continue;
        }
        if (walk) {
            float b = fminf(fminf(a + hmin, t1), c);
            for (int j = 0; j < 3; ++j) x[j] = o[j] + b * d[j];
            f = eval_point(F, radius, x, g);
            ++ev;
            if (sgn > 0.0f ? f < 0.0f : f > noise) {
                c = b;
                g_at_c = 1;
            } else {
                a = b;
                g_at_c = 0;
            }
            walk = sgn * f <= 2.0f * noise;
            continue;
        }
        float b = fminf(fminf(a + fmaxf(step, hmin), t1), c);
        Tents T = tents(F, &mo, radius, o, d, a, b);
        ++ev;
        noise = T.round;
        float x_safe, x_opp;
        if (sgn > 0.0f) {
            x_safe = first_negative(a, T.lo_a, T.lo_k, T.lo_m, b, T.lo_b);
            x_opp = first_negative(a, T.hi_a, T.hi_k, T.hi_m, b, T.hi_b);
        } else {
            x_safe = first_negative(a, -T.hi_a, T.hi_k, -T.hi_m, b, -T.hi_b);
            x_opp = first_negative(a, -T.lo_a, T.lo_k, -T.lo_m, b, -T.lo_b);
        }
        if (x_opp < c) {
            c = x_opp;
            g_at_c = 0;
        }
        if (x_safe >= b) {
            float m = sgn > 0.0f ? fminf(T.lo_a, fminf(T.lo_m, T.lo_b))
                                 : -fmaxf(T.hi_a, fmaxf(T.hi_m, T.hi_b));
            float e = 0.5f * fmaxf(T.hi_a - T.lo_a, T.hi_b - T.lo_b) - T.round;
            float grow = e > 0.0f ? fminf(fmaxf(sqrtf(0.25f * m / e), 2.0f), 8.0f) : 8.0f;
            step = (b - a) * grow;
            a = b;
            continue;
        }
        float width = b - a;
        a = x_safe;
        float rest = b - a;
        if (c - a <= tol) continue;
        if (rest <= tol) {
            for (int j = 0; j < 3; ++j) x[j] = o[j] + b * d[j];
            f = eval_point(F, radius, x, g);
            ++ev;
            if (sgn > 0.0f ? f < 0.0f : f > T.round) {
                c = b;
                g_at_c = 1;
            } else {
                a = b;
                g_at_c = 0;
            }
            step = hmin;
            walk = sgn * f <= 2.0f * noise;
            continue;
        }
        float left = fminf(c, b) - a;
        step = left <= 0.5f * width ? left : 0.5f * left;
    }
    if (!done) {
        *evals = ev;
        return -1.0f;   /* undecided */
    }
    if (hit < T_INF && !g_at_c) {
        for (int j = 0; j < 3; ++j) x[j] = o[j] + hit * d[j];
        eval_point(F, radius, x, g);   /* the normal, as the device computes it */
        ++ev;
    }
    *evals = ev;
    return hit;
}

/* rays r = 0..n-1 with their own realizations: features (n, m) per array */
void ws_first_roots(int n, const float* o, const float* d, const float* t01, float tol,
                    int m, const float* tx, const float* ty, const float* tz,
                    const float* tau, const float* w, float amp, float radius, float h0,
                    int max_iter, float* t_out, int* evals)
{
#pragma omp parallel for schedule(dynamic, 16)
    for (int r = 0; r < n; ++r) {
        size_t k = (size_t)r * (size_t)m;
        Feats F = {tx + k, ty + k, tz + k, tau + k, w + k, m, amp};
        t_out[r] = first_root(&F, radius, h0, o + 3 * r, d + 3 * r, t01[2 * r],
                              t01[2 * r + 1], tol, max_iter, evals + r);
    }
}
