/* First root of a weight-space realization along a ray, with guaranteed range bounds.
 * Needs ws_features.h, ws_posterior.h (and gp_mean.h). A posterior object's realization
 * carries its pathwise correction (ws_posterior.h), which the bounds below fold into the
 * mean's cone or the features' affine form. The one-sided convention of the reference: a
 * hit is a crossing from f >= 0 to f < 0; a ray that starts inside (f(t0) < 0) must first
 * come back to f >= 0.
 *
 * Bounds over a ray interval [a, b]: the features' affine form (ws_affine) plus the mean's
 * Lipschitz cone through both end values,
 *   max(mu_a - L (t - a), mu_b - L (b - t)) <= mean(t) <= min(mu_a + L (t - a), mu_b + L (b - t)),
 * L = Lip(mean) |d|. Their sums are piecewise-linear lower/upper bounds of f with one kink
 * each (WsTents); they are exact for a linear mean of slope +-L (a plane seen head-on) and
 * hold for any mean whose gradient norm is <= Lip (ws_mean_lipschitz).
 *
 * Search: a certified prefix [a, x_safe] where the bound proves "no crossing yet" advances
 * a; a point x_opp where the bound proves the opposite sign shrinks the bracket (a, c].
 * Steps grow after an interval is certified whole and halve when little was certified.
 * Because only bounds ever skip ray length, no crossing is missed: a dip of f below zero
 * between any two samples is inside some interval whose lower bound is negative. The only
 * approximation is at the resolution `tol`: an interval narrower than tol whose bound
 * straddles zero is decided by a point evaluation at its end (see the loop).
 * Near a simple root the features' error is O(h^2), but the mean's cones are O(h) and the
 * rounding allowance O(1): brackets shrink linearly, and within the rounding floor
 * (|f| below ~T.round, e.g. along a ray leaving a root or grazing the surface) no bound
 * decides anything, so there intervals are never much narrower than tol and point
 * evaluations decide them. (Letting the step shrink further there made it walk at
 * ~1e-7 l per bound into WS_MAX_ITER.)
 */
#define WS_STATUS_OK 0
#define WS_STATUS_ITER_CAP 1   /* WS_MAX_ITER loop passes without a decision */
#define WS_STATUS_NAN 2        /* NaN realization (thin-plate kernel, bad mean program) */
#define WS_STATUS_ROWS 3       /* more posterior rows than WS_POST_MAX */
/* Each pass costs one bound or point evaluation (M cached features and two mean
 * evaluations). A segment costs about (length / marching step) + ~10 per crossing passes,
 * the step being ~l/2 where |f| ~ sigma; a ray grazing the surface walks the stretch where
 * |f| is within the rounding floor at ~tol per pass (up to ~2000 passes seen for rays
 * within 1 degree of tangent, tests/test_ws_intersect.py). 16384 leaves room for both. */
#ifndef WS_MAX_ITER
#define WS_MAX_ITER 16384
#endif

/* Shared with the occupancy bounds (gpis_proxy.h): see gp_mean_lipschitz. */
inline float ws_mean_lipschitz(__global const MeanNode* nodes, int count)
{
    return gp_mean_lipschitz(nodes, count);
}

/* Piecewise-linear bounds of f over [a, b]: lo through (a, lo_a), (lo_k, lo_m), (b, lo_b)
 * and hi through (a, hi_a), (hi_k, hi_m), (b, hi_b). */
typedef struct {
    float lo_k, lo_a, lo_m, lo_b;
    float hi_k, hi_a, hi_m, hi_b;
    float round;   /* the rounding part: point evaluations are within it of the true f */
} WsTents;

/* The realization at x, conditioned by P when given (ws_posterior.h), with its gradient. */
inline float ws_eval_post(const float* cache, const WsPost* P, GpKernel k,
                          __global const MeanNode* mean, int mean_count,
                          __global const float* order_cdf, int order_count, int M, uint2 key,
                          int object, float3 x, float3* grad)
{
    float f = ws_eval_cached(cache, k, mean, mean_count, order_cdf, order_count, M, key,
                             object, x, grad);
    if (P) {
        double3 g;
        f = (float)((double)f + ws_post_eval(k, P, convert_double3(x), &g));
        *grad += convert_float3(g);
    }
    return f;
}

/* Bounds of the realization, conditioned by P when given: the correction joins the mean's
 * cone (end values and slope bound add to the mean's) or the features' affine form, so the
 * tents keep one kink. */
inline WsTents ws_tents_post(const float* cache, const WsPost* P, GpKernel k,
                             __global const MeanNode* mean, int mean_count,
                             __global const float* order_cdf, int order_count, int M,
                             uint2 key, int object, float3 o, float3 d, float a, float b,
                             float lip)
{
    float tm = 0.5f * (a + b), h = 0.5f * (b - a);
    WsAffine af = ws_affine(cache, k, order_cdf, order_count, M, key, object, o, d, tm, h);
    float3 g;
    float ma = gp_mean_eval(mean, mean_count, o + a * d, &g);
    float mb = gp_mean_eval(mean, mean_count, o + b * d, &g);
    float lt = lip * length(d);
    /* mean rounding: its value, and the rounded point (|dx| ~ eps |x|) moved by lip */
    float3 xabs = fabs(o) + fmax(fabs(a), fabs(b)) * fabs(d);
    float round = af.round
                + 8.0f * FLT_EPSILON * (fabs(ma) + fabs(mb) + lip * (xabs.x + xabs.y + xabs.z));
    if (P) {
        /* the correction as a second-order form (error curv h^2 / 2, like the features')
         * or as a cone (2 slope h): the narrower; the form wins near roots, where
         * intervals are short, the cone on long intervals near observations */
        WsPostBound C = ws_post_bound(k, P, o, d, a, b);
        float slope = (float)C.slope, curv = (float)C.curv;
        if (0.25f * curv * h < slope) {
            af.f0 += (float)C.cm;
            af.f1 += (float)C.dm;
            af.err += (0.5f * curv * h * h) * (1.0f + 4.0f * FLT_EPSILON);
            round += 8.0f * FLT_EPSILON * (fabs((float)C.cm) + fabs((float)C.dm) * h);
        } else {
            ma = (float)((double)ma + C.ca);
            mb = (float)((double)mb + C.cb);
            /* rounded up: a cone a hair too shallow could cut the correction */
            lt = (lt + slope) * (1.0f + 4.0f * FLT_EPSILON);
            round += 8.0f * FLT_EPSILON * (fabs((float)C.ca) + fabs((float)C.cb));
        }
        /* the rounded point moved by the correction's slope, and the double sums' own
         * rounding (n terms of magnitude mag) */
        round += 8.0f * FLT_EPSILON * (float)C.slope_any * (xabs.x + xabs.y + xabs.z)
               + (float)(4.0 * (P->n + 2) * 2.3e-16 * C.mag);
    }
    float r = af.err + round;
    float inv2l = 0.5f / fmax(lt, FLT_MIN);
    WsTents T;
    T.round = round;
    T.lo_k = lt > 0.0f ? clamp(tm + (ma - mb) * inv2l, a, b) : tm;
    T.hi_k = lt > 0.0f ? clamp(tm + (mb - ma) * inv2l, a, b) : tm;
    float c0 = af.f0 - af.f1 * h, c1 = af.f0 + af.f1 * h;   /* feature centre at a, b */
    T.lo_a = c0 - r + fmax(ma, mb - lt * (b - a));
    T.lo_b = c1 - r + fmax(ma - lt * (b - a), mb);
    T.lo_m = af.f0 + af.f1 * (T.lo_k - tm) - r
           + fmax(ma - lt * (T.lo_k - a), mb - lt * (b - T.lo_k));
    T.hi_a = c0 + r + fmin(ma, mb + lt * (b - a));
    T.hi_b = c1 + r + fmin(ma + lt * (b - a), mb);
    T.hi_m = af.f0 + af.f1 * (T.hi_k - tm) + r
           + fmin(ma + lt * (T.hi_k - a), mb + lt * (b - T.hi_k));
    return T;
}

inline WsTents ws_tents_cached(const float* cache, GpKernel k, __global const MeanNode* mean,
                               int mean_count, __global const float* order_cdf,
                               int order_count, int M, uint2 key, int object, float3 o,
                               float3 d, float a, float b, float lip)
{
    return ws_tents_post(cache, 0, k, mean, mean_count, order_cdf, order_count, M, key, object,
                         o, d, a, b, lip);
}

inline WsTents ws_tents(GpKernel k, __global const MeanNode* mean, int mean_count,
                        __global const float* order_cdf, int order_count, int M, uint2 key,
                        int object, float3 o, float3 d, float a, float b, float lip)
{
    return ws_tents_cached(0, k, mean, mean_count, order_cdf, order_count, M, key, object, o,
                           d, a, b, lip);
}

/* First t in [a, b] where the 2-piece linear function through (a, pa), (k, pk), (b, pb) is
 * negative; T_INFINITY if none. */
inline float ws_first_negative(float a, float pa, float k, float pk, float b, float pb)
{
    if (pa < 0.0f) return a;
    if (pk < 0.0f) return a + (k - a) * (pa / (pa - pk));
    if (pb < 0.0f) return k + (b - k) * (pk / (pk - pb));
    return T_INFINITY;
}

/* The first t in (t0, t1] where the realization crosses from >= 0 to < 0, to within tol
 * (the returned t is the end of the final bracket, a point with f < 0), or T_INFINITY if
 * there is none. normal = grad f / |grad f| at the returned t. *status: WS_STATUS_OK, or
 * WS_STATUS_ITER_CAP / WS_STATUS_NAN with T_INFINITY returned (the caller must count or
 * kill such rays: "no hit" is then not proven). d need not be unit length; t is in units
 * of d. tol is raised to the float resolution of t where needed. *evaluations counts the
 * M-feature passes (bounds and point evaluations, and the n of a posterior's solve when
 * it runs), the search's cost. B: the object's posterior block (n = 0: the prior); S: the
 * path's slot for its weights (ws_post_weights), or none. */
inline float ws_first_root_post(WsPostBlock B, WsPostSlot S, GpKernel k,
                                __global const MeanNode* mean, int mean_count,
                                __global const float* order_cdf, int order_count, int M,
                                uint2 key, int object, float3 o, float3 d, float t0, float t1,
                                float tol, float3* normal, int* status, int* evaluations)
{
    *status = WS_STATUS_OK;
    *evaluations = 0;
    *normal = (float3)(0.0f);
    if (!(t1 > t0)) return T_INFINITY;
    float lip = ws_mean_lipschitz(mean, mean_count);
    /* grid means: each interval takes the bound of the cells it crosses (bricks of cells
     * far from a distance's ridges are ~1, the whole grid's up to ~1.5, ~6 for cubic) */
    int local_lip = gp_mean_has_grid(mean, mean_count);
    float tres = 4.0f * FLT_EPSILON * (fabs(t0) + fabs(t1) + length(o) / length(d));
    tol = fmax(tol, 2.0f * tres);
    float h0 = 0.5f * rsqrt(fmax(ws_lambda2(k, d), 1e-30f));
    /* the narrowest interval: tol less the rounding of a + hmin (<= eps |t| / 2, and
     * tol >= 8 eps |t|), so that a + hmin - a <= tol and the end point decides it */
    float hmin = 0.875f * tol;
#if WS_CACHE_FEATURES > 0
    float cache_mem[WS_CACHE_FLOATS];
    const float* cache = 0;
    if (M <= WS_CACHE_FEATURES) {
        ws_fill_cache(k, order_cdf, order_count, key, object, M, cache_mem);
        cache = cache_mem;
    }
#else
    const float* cache = 0;
#endif
    /* a posterior conditions this ray's realization once, here (or reads the weights the
     * path's first search kept in S); with the constant empty block of the prior's
     * callers all posterior code compiles away */
    double post_v[WS_POST_MAX];
    WsPost post;
    const WsPost* P = 0;
    int evals = 0;
    if (B.n > 0) {
        if (B.n > WS_POST_MAX) {
            *status = WS_STATUS_ROWS;
            return T_INFINITY;
        }
        int computed;
        post.rho = ws_post_weights(S, cache, k, mean, mean_count, order_cdf, order_count, M,
                                   key, object, B, post_v, &computed);
        post.rows = B.rows;
        post.v = post_v;
        post.n = B.n;
        P = &post;
        evals = computed ? B.n : 0;
    }
    float3 g;
    float f = ws_eval_post(cache, P, k, mean, mean_count, order_cdf, order_count, M, key, object,
                           o + t0 * d, &g);
    ++evals;
    if (isnan(f)) {
        *status = WS_STATUS_NAN;
        *evaluations = evals;
        return T_INFINITY;
    }
    /* sgn = +1: outside, looking for f < 0; -1: inside, looking for f >= 0 */
    float sgn = f < 0.0f ? -1.0f : 1.0f;
    /* First step: a bound cannot certify further than phi = sgn f can fall, so heading
     * towards a sign change the Newton distance phi / |phi'| is the natural step. Rays that
     * leave a root (every bounce and shadow ray) start with phi ~ 0: without this they
     * spend ~log2(h0 / tol) bounds halving h0. */
    float phi = sgn * f, dphi = sgn * dot(g, d);
    float step = dphi < 0.0f ? clamp(phi / -dphi, hmin, h0) : h0;
    float a = t0, c = T_INFINITY, hit = T_INFINITY;
    float noise = 0.0f;     /* the last bound's rounding allowance */
    int done = 0, g_at_c = 0, walk = 0;
    int it;
    for (it = 0; it < WS_MAX_ITER && !done; ++it) {
        if (c - a <= tol) {            /* the sign change is bracketed in (a, c] */
            if (sgn > 0.0f) {
                hit = c;
                done = 1;
            } else {                   /* back outside at c: now look for the hit */
                /* f(c) is within noise of 0, so nothing wider than the minimum step
                 * can be certified there yet; doubling from it is the fastest way up */
                sgn = 1.0f;
                a = c;
                c = T_INFINITY;
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
            /* |f| is within the rounding floor, where no bound decides anything: go on
             * deciding intervals narrower than tol by their end point, without the bound
             * (which would only straddle zero again), until f clears the floor */
            float b = fmin(fmin(a + hmin, t1), c);
            f = ws_eval_post(cache, P, k, mean, mean_count, order_cdf, order_count, M, key,
                             object, o + b * d, &g);
            ++evals;
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
        /* intervals never narrower than hmin: below tol the end-point sign decides
         * (below), and a bound cannot certify anything within its rounding floor */
        float b = fmin(fmin(a + fmax(step, hmin), t1), c);
        float lip_ab = local_lip
            ? fmin(lip, gp_mean_lipschitz_on(mean, mean_count, o + a * d, o + b * d)) : lip;
        WsTents T = ws_tents_post(cache, P, k, mean, mean_count, order_cdf, order_count, M, key,
                                  object, o, d, a, b, lip_ab);
        ++evals;
        noise = T.round;
        /* bounds of phi = sgn f: certified "same sign" where phi_lo >= 0, opposite
         * where phi_hi < 0 */
        float x_safe, x_opp;
        if (sgn > 0.0f) {
            x_safe = ws_first_negative(a, T.lo_a, T.lo_k, T.lo_m, b, T.lo_b);
            x_opp = ws_first_negative(a, T.hi_a, T.hi_k, T.hi_m, b, T.hi_b);
        } else {
            x_safe = ws_first_negative(a, -T.hi_a, T.hi_k, -T.hi_m, b, -T.hi_b);
            x_opp = ws_first_negative(a, -T.lo_a, T.lo_k, -T.lo_m, b, -T.lo_b);
        }
        if (isnan(T.lo_a + T.lo_m + T.lo_b + T.hi_a + T.hi_m + T.hi_b)) {
            *status = WS_STATUS_NAN;
            *evaluations = evals;
            return T_INFINITY;
        }
        if (x_opp < c) {
            c = x_opp;
            g_at_c = 0;
        }
        if (x_safe >= b) {             /* the whole interval is certified */
            /* grow by the margin m the bound left over its own width e (less rounding):
             * the features' part of e grows ~h^2, so sqrt(m / e) predicts how much wider
             * still certifies; a quarter of m keeps failed (partial) tries rare. At least
             * x2 (plain doubling); x8 mostly just after leaving a root, where e ~ 0. */
            float m = sgn > 0.0f ? fmin(T.lo_a, fmin(T.lo_m, T.lo_b))
                                 : -fmax(T.hi_a, fmax(T.hi_m, T.hi_b));
            float e = 0.5f * fmax(T.hi_a - T.lo_a, T.hi_b - T.lo_b) - T.round;
            float grow = e > 0.0f ? clamp(sqrt(0.25f * m / e), 2.0f, 8.0f) : 8.0f;
            step = (b - a) * grow;
            a = b;
            continue;
        }
        float width = b - a;
        a = x_safe;
        float rest = b - a;
        if (c - a <= tol) continue;
        if (rest <= tol) {
            /* too narrow for the bound to decide: the sign at its end does. A dip of f
             * below zero that starts and ends inside such an interval is at most
             * max|f''| tol^2 / 8 deep (~1e-8 sigma for tol = 1e-4 l), far below float
             * noise, so accepting the interval misses nothing resolvable. Leaving the
             * inside needs f clear of rounding noise, else noise just after an
             * up-crossing could fake a hit there. */
            f = ws_eval_post(cache, P, k, mean, mean_count, order_cdf, order_count, M, key,
                             object, o + b * d, &g);
            ++evals;
            if (sgn > 0.0f ? f < 0.0f : f > T.round) {
                c = b;
                g_at_c = 1;            /* the hit's normal needs no second evaluation */
            } else {
                a = b;
                g_at_c = 0;
            }
            step = hmin;
            walk = sgn * f <= 2.0f * noise;
            continue;
        }
        /* Next try all that is left undecided (of this interval, or of the bracket,
         * which the bound may have pulled in) when the bound decided at least half of
         * it, else half of it: a bracketed root gets bounds over its whole bracket,
         * which shrink it from both ends. */
        float left = fmin(c, b) - a;
        step = left <= 0.5f * width ? left : 0.5f * left;
    }
    if (!done) {
        *status = WS_STATUS_ITER_CAP;
        *evaluations = evals;
        return T_INFINITY;
    }
    if (hit < T_INFINITY) {
        if (!g_at_c) {
            ws_eval_post(cache, P, k, mean, mean_count, order_cdf, order_count, M, key, object,
                         o + hit * d, &g);
            ++evals;
        }
        float gl = length(g);
        *normal = gl > 0.0f && isfinite(gl) ? g / gl : -d / length(d);
    }
    *evaluations = evals;
    return hit;
}

/* The prior's search (no posterior). */
inline float ws_first_root_counted(GpKernel k, __global const MeanNode* mean,
                                   int mean_count, __global const float* order_cdf,
                                   int order_count, int M, uint2 key, int object, float3 o,
                                   float3 d, float t0, float t1, float tol, float3* normal,
                                   int* status, int* evaluations)
{
    WsPostBlock none = {0, 0, 0, 0};
    WsPostSlot no_slot = {0, 0};
    return ws_first_root_post(none, no_slot, k, mean, mean_count, order_cdf, order_count, M,
                              key, object, o, d, t0, t1, tol, normal, status, evaluations);
}

/* ws_first_root_counted without the evaluation count (the count is for profiling). */
inline float ws_first_root(GpKernel k, __global const MeanNode* mean, int mean_count,
                           __global const float* order_cdf, int order_count, int M,
                           uint2 key, int object, float3 o, float3 d, float t0, float t1,
                           float tol, float3* normal, int* status)
{
    int evaluations;
    return ws_first_root_counted(k, mean, mean_count, order_cdf, order_count, M, key, object,
                                 o, d, t0, t1, tol, normal, status, &evaluations);
}
