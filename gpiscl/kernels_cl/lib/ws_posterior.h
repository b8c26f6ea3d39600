/* Weight-space posterior GPIS by pathwise conditioning (Matheron's rule; Wilson et al.
 * 2020). Needs ws_features.h. For the path's prior realization f (mean + random features,
 * ws_eval) and the object's observation rows y_j (values f(x_j), or derivatives
 * u_j . grad f(x_j)) with noise covariance N,
 *   f_post(x) = f(x) + sum_j v_j c_j(x),   v = (K + N)^-1 (y - f(X) - e),  e ~ N(0, N),
 * c_j(x) = cov(f(x), row j). Mean and covariance of f_post are the exact posterior's
 * whenever f has the prior's (random features do, averaged over the features), so the
 * realization needs no approximation beyond the prior's.
 *
 * Data: the function-space posterior's tables (fs_posterior.h; compile/posterior.py fills
 * them): n FsObs rows (x, u, y, kind), and among the doubles alpha (unused here), the
 * packed row-major factor L of K + N, then the n noise deviations.
 * Noise: e_j = sd_j z_j, z_j from Philox call WS_CALL_NOISE with the features' counter
 * (key, object, j): the realization stays a pure function of the path's key.
 * Cost: n prior evaluations at the rows (n M features) and two triangular solves (n^2) in
 * double, once per path and object: v depends only on the realization (key, object), so
 * the first search of a path that needs it computes it and keeps it in the path's slot
 * (WsPostSlot, sized by render/kriging_cache.py); later rays and shadow rays of the path
 * copy it back (~1/3 of a posterior ray's cost when every ray solved again). Then every
 * point evaluation and every bound adds n kernel terms. A search works on v in private
 * memory: WS_POST_MAX rows (scene/observations.WS_MAX_ROWS).
 *
 * Bounds: along the ray x(t) = o + t d the correction is smooth but not affine; over
 * [a, b] (half width h, middle tm) ws_tents_post takes the narrower of two rigorous forms
 * (ws_post_bound): its values at both ends with a Lipschitz cone of slope L_c (joins the
 * mean's cone), or c(tm) + c'(tm) (t - tm) +- C h^2 / 2 (joins the features' affine form),
 *   L_c = sqrt(dAd) sum_j |v_j| B1_j,   C = dAd sum_j |v_j| B2_j,
 * B1_j, B2_j bounding |d . grad c_j| / sqrt(dAd) and |d^T Hess c_j d| / dAd over [a, b].
 * With s = r^T A r, r = x - x_j, k(s) radial, primes in s, p = d.Ar, w = u.Ar
 * (Cauchy-Schwarz in A's metric: |p| <= sqrt(dAd s), |w| <= sqrt(uAu s)):
 *   value row:  c' = 2k' p,                  B1 = |2k'| sqrt(s)
 *               c'' = 2k' dAd + 4k'' p^2,     B2 = |2k'| + |4k''| s
 *   deriv row:  c = -2k' w,  c' = -4k'' p w - 2k' d.Au,
 *                                             B1 = sqrt(uAu) (|2k'| + |4k''| s)
 *               c'' = -8k''' p^2 w - 4k'' dAd w - 8k'' p d.Au,
 *                                             B2 = sqrt(uAu) sqrt(s) (3 |4k''| + |8k'''| s)
 * |2k'|, |4k''|, |8k'''| fall with s for SE and RQ, so over the interval's range
 * [s_min, s_max] of s each is at most its value at s_min, and s at most s_max; global
 * maxima cap the products on wide intervals:
 *   SE: |2k'| sqrt(s) <= sigma^2 e^-1/2 / l,  |2k'| + |4k''| s <= 2 e^-1/2 sigma^2 / l^2,
 *       sqrt(s) (3 |4k''| + |8k'''| s) <= 2.62 sigma^2 / l^3;
 *   RQ: |2k'| sqrt(s) peaks at s = a l^2 / (a + 1/2); s / base <= 2 a l^2 gives
 *       |4k''| s <= 2 (a + 1) |2k'| and |8k'''| s <= 2 (a + 2) |4k''|.
 * The cone's slack grows like L_c h, the form's like C h^2: the form decides the short
 * intervals around roots, the cone long ones near observations.
 * Other kernels are rejected by the scene schema (scene/observations.observations_problem).
 */
/* WS_CALL_NOISE, WS_POST_MAX: layout/constants.py */

typedef struct {
    __global const FsObs* rows;
    __global const double* L;
    __global const double* sd;
    int n;
} WsPostBlock;

/* One ray's conditioned correction: the block, v = (K + N)^-1 (y - f(X) - e), and rho,
 * a bound on the correction's norm in the kernel's RKHS (ws_post_prepare). */
typedef struct {
    __global const FsObs* rows;
    const double* v;
    int n;
    double rho;
} WsPost;

/* Object g's posterior in the scene's posterior tables (n = 0: none, the prior). */
inline WsPostBlock ws_posterior_block(__global const GpisObject* g, __global const FsObs* obs,
                                      __global const double* doubles)
{
    WsPostBlock B;
    B.rows = 0;
    B.L = B.sd = 0;
    B.n = g->posterior_count;
    if (B.n == 0) return B;
    B.rows = obs + g->posterior_first;
    B.L = doubles + g->posterior_doubles + B.n;      /* after alpha */
    B.sd = B.L + B.n * (B.n + 1) / 2;
    return B;
}

inline double3 ws_post_x(__global const FsObs* row)
{
    return (double3)(row->px, row->py, row->pz);
}
inline double3 ws_post_u(__global const FsObs* row)
{
    return (double3)(row->ux, row->uy, row->uz);
}
inline int ws_post_is_deriv(__global const FsObs* row) { return row->kind != FS_OBS_VALUE; }

inline double3 ws_post_aniso(GpKernel k)
{
    return (double3)((double)k.aniso.x, (double)k.aniso.y, (double)k.aniso.z);
}

/* Rows are processed WS_POST_LANES at a time in double vectors (the cross-covariances'
 * exp and log1p): PoCL's scalar double exp is an opaque per-call routine, its double8 one
 * is vector code with an order of magnitude more throughput on AVX-512
 * (docs/design/batches.md, 'Weight-space lanes'). A point evaluation costs n
 * cross-covariances and a bound 4n, against M float features: with scalar rows a 100-row
 * posterior's bound would cost many times its features'. Lanes past n read row n - 1
 * with weight 0. GPUs (WS_LANES 1) keep one row per step. */
#if WS_LANES > 1
#define WS_POST_LANES 8
typedef double8 wpd;
typedef long8 wpl;
#define wp_hsum(v) ((v).s0 + (v).s1 + (v).s2 + (v).s3 + (v).s4 + (v).s5 + (v).s6 + (v).s7)
#define wp_lane0(v) ((v).s0)
#else
#define WS_POST_LANES 1
typedef double wpd;
typedef long wpl;
#define wp_hsum(v) (v)
#define wp_lane0(v) (v)
#endif

/* Rows j0 .. j0 + WS_POST_LANES - 1 of the block, structure of arrays */
typedef struct {
    wpd x, y, z;      /* observation point */
    wpd ux, uy, uz;   /* derivative direction (derivative rows) */
    wpl deriv;        /* all bits set on derivative rows */
    wpd v;            /* weight v_j, 0 past n */
} WsPostRows;

inline WsPostRows ws_post_rows(__global const FsObs* rows, const double* v, int n, int j0)
{
    double t[6][WS_POST_LANES], vv[WS_POST_LANES];
    long dv[WS_POST_LANES];
    for (int l = 0; l < WS_POST_LANES; ++l) {
        int j = min(j0 + l, n - 1);
        __global const FsObs* row = rows + j;
        t[0][l] = row->px; t[1][l] = row->py; t[2][l] = row->pz;
        t[3][l] = row->ux; t[4][l] = row->uy; t[5][l] = row->uz;
        dv[l] = ws_post_is_deriv(row) ? -1 : 0;
        vv[l] = j0 + l < n ? v[j] : 0.0;
    }
    WsPostRows R;
#if WS_POST_LANES == 1
    R.x = t[0][0]; R.y = t[1][0]; R.z = t[2][0];
    R.ux = t[3][0]; R.uy = t[4][0]; R.uz = t[5][0];
    R.deriv = dv[0];
    R.v = vv[0];
#else
    R.x = vload8(0, t[0]); R.y = vload8(0, t[1]); R.z = vload8(0, t[2]);
    R.ux = vload8(0, t[3]); R.uy = vload8(0, t[4]); R.uz = vload8(0, t[5]);
    R.deriv = vload8(0, dv);
    R.v = vload8(0, vv);
#endif
    return R;
}

/* k(s), 2 k'(s), 4 k''(s) in double (gp_radial's SE and RQ), per lane */
inline wpd ws_post_radial(GpKernel k, wpd s, wpd* dk2, wpd* ddk4)
{
    double v = (double)k.sigma2, l2 = (double)k.length_scale * (double)k.length_scale;
    if (k.kind == GP_KERNEL_RATIONAL_QUADRATIC) {
        double a = (double)k.alpha;
        wpd base = 1.0 + s / (2.0 * a * l2);
        wpd kv = v * exp(-a * log1p(s / (2.0 * a * l2)));
        *dk2 = -kv / (l2 * base);
        *ddk4 = kv * (a + 1.0) / (a * l2 * l2 * base * base);
        return kv;
    }
    wpd kv = v * exp(-s / (2.0 * l2));
    *dk2 = -kv / l2;
    *ddk4 = kv / (l2 * l2);
    return kv;
}

/* c_j at r = x - x_j (components rx, ry, rz), and its gradient, per lane */
inline wpd ws_post_cross(GpKernel k, double3 A, const WsPostRows* R, wpd rx, wpd ry, wpd rz,
                         wpd* gx, wpd* gy, wpd* gz)
{
    wpd ax = A.x * rx, ay = A.y * ry, az = A.z * rz;
    wpd dk2, ddk4, kv = ws_post_radial(k, ax * rx + ay * ry + az * rz, &dk2, &ddk4);
    wpd bx = A.x * R->ux, by = A.y * R->uy, bz = A.z * R->uz;   /* A u */
    wpd uar = bx * rx + by * ry + bz * rz, t = ddk4 * uar;
    *gx = select(dk2 * ax, -dk2 * bx - t * ax, R->deriv);
    *gy = select(dk2 * ay, -dk2 * by - t * ay, R->deriv);
    *gz = select(dk2 * az, -dk2 * bz - t * az, R->deriv);
    return select(kv, -dk2 * uar, R->deriv);
}

/* The correction sum_j v_j c_j(x) and its gradient. */
inline double ws_post_eval(GpKernel k, const WsPost* P, double3 x, double3* grad)
{
    double3 A = ws_post_aniso(k);
    wpd c = 0.0, gx = 0.0, gy = 0.0, gz = 0.0;
    for (int j0 = 0; j0 < P->n; j0 += WS_POST_LANES) {
        WsPostRows R = ws_post_rows(P->rows, P->v, P->n, j0);
        wpd hx, hy, hz;
        wpd cj = ws_post_cross(k, A, &R, x.x - R.x, x.y - R.y, x.z - R.z, &hx, &hy, &hz);
        c += R.v * cj;
        gx += R.v * hx;
        gy += R.v * hy;
        gz += R.v * hz;
    }
    *grad = (double3)(wp_hsum(gx), wp_hsum(gy), wp_hsum(gz));
    return wp_hsum(c);
}

/* v = (K + N)^-1 (y - f(X) - e) for the realization (key, object): the prior at the rows
 * (features from `cache` if given), the path's noise draws, two triangular solves.
 * Returns rho >= ||c||_H, the correction c = sum_j v_j c_j's norm in the kernel's RKHS:
 * ||c||^2 = v^T K v = |z|^2 - v^T N v with z = L^-1 (y - f(X) - e) (L L^T = K + N; a jitter
 * the host added stays in, which only raises the bound), plus 1e-6 n max_j (K+N)_jj |v|^2
 * for the device kernel's float parameters, which differ from the host's K by ~1e-7. */
inline double ws_post_prepare(const float* cache, GpKernel k, __global const MeanNode* mean,
                            int mean_count, __global const float* order_cdf, int order_count,
                            int M, uint2 key, int object, WsPostBlock B, double* v)
{
    for (int j0 = 0; j0 < B.n; j0 += WS_LANES) {
        wsu r0, r1, r2, r3;
        ws_draw(key, object, j0 + WS_IOTA, WS_CALL_NOISE, &r0, &r1, &r2, &r3);
        wsf unused, z = ws_normal2(r0, r1, &unused);
        float zs[WS_LANES];
        ws_vstore(z, 0, zs);
        for (int l = 0; l < WS_LANES && j0 + l < B.n; ++l) {
            int j = j0 + l;
            __global const FsObs* row = B.rows + j;
            float3 g;
            float f = ws_eval_cached(cache, k, mean, mean_count, order_cdf, order_count, M,
                                     key, object, convert_float3(ws_post_x(row)), &g);
            double fo = ws_post_is_deriv(row) ? dot(convert_double3(g), ws_post_u(row))
                                              : (double)f;
            v[j] = row->value - fo - B.sd[j] * (double)zs[l];
        }
    }
    double zz = 0.0, diag = 0.0, vv = 0.0, nv = 0.0;
    for (int i = 0; i < B.n; ++i) {          /* L z = r */
        __global const double* Li = B.L + i * (i + 1) / 2;
        double s = v[i], row = Li[i] * Li[i];
        for (int j = 0; j < i; ++j) {
            s -= Li[j] * v[j];
            row += Li[j] * Li[j];
        }
        v[i] = s / Li[i];
        zz += v[i] * v[i];
        diag = fmax(diag, row);              /* (K + N)_ii */
    }
    for (int i = B.n - 1; i >= 0; --i) {     /* L^T v = z, by rows of L */
        __global const double* Li = B.L + i * (i + 1) / 2;
        v[i] /= Li[i];
        for (int j = 0; j < i; ++j) v[j] -= Li[j] * v[i];
    }
    for (int j = 0; j < B.n; ++j) {
        vv += v[j] * v[j];
        nv += B.sd[j] * B.sd[j] * v[j] * v[j];
    }
    return sqrt(fmax(zz - nv, 0.0) * (1.0 + 1e-9) + 1e-6 * B.n * diag * vv);
}

/* A path's kept weights for one object: its tag says whose they are, (key.x, key.y,
 * object + 1, 0), all zero while empty (the host zeroes the tags; values are never read
 * without a matching tag, so they need no clearing). A slot is reused by the next batch's
 * path of the same index, whose key differs (or, for one fixed realization, whose weights
 * are the same), so a tag match means exactly these weights. No tag: no slot. */
typedef struct {
    __global uint4* tag;
    __global double* values;   /* rho, then v_0 .. v_{n-1} */
} WsPostSlot;

inline uint4 ws_post_tag(uint2 key, int object)
{
    return (uint4)(key.x, key.y, (uint)object + 1u, 0u);
}

/* ws_post_prepare through the path's slot: the kept v and rho when the slot holds this
 * realization's (bit for bit what ws_post_prepare returned then), else computed and kept.
 * *computed: whether the solve ran. One work-item per path and slot in a launch (one ray
 * per path in the ray queue, one shadow ray per path in the shadow queue), so no races. */
inline double ws_post_weights(WsPostSlot S, const float* cache, GpKernel k,
                              __global const MeanNode* mean, int mean_count,
                              __global const float* order_cdf, int order_count, int M,
                              uint2 key, int object, WsPostBlock B, double* v, int* computed)
{
    uint4 want = ws_post_tag(key, object);
    if (S.tag && all(*S.tag == want)) {
        for (int j = 0; j < B.n; ++j) v[j] = S.values[1 + j];
        *computed = 0;
        return S.values[0];
    }
    double rho = ws_post_prepare(cache, k, mean, mean_count, order_cdf, order_count, M, key,
                                 object, B, v);
    if (S.tag) {
        S.values[0] = rho;
        for (int j = 0; j < B.n; ++j) S.values[1 + j] = v[j];
        *S.tag = want;
    }
    *computed = 1;
    return rho;
}

/* The correction along o + t d over [a, b], for ws_tents_post: values at a, b and the
 * middle tm, the slope there, bounds of |slope| (per unit t; per unit length in any
 * direction, for rounded points) and of |curvature| per unit t^2 over [a, b] (header
 * comment), and sum |v_j c_j| at the three points (the double sums' rounding scale). */
typedef struct {
    double ca, cb, cm, dm;
    double slope, slope_any, curv, mag;
} WsPostBound;

inline WsPostBound ws_post_bound(GpKernel k, const WsPost* P, float3 o, float3 d, float a,
                                 float b)
{
    double3 A = ws_post_aniso(k), od = convert_double3(o), dd = convert_double3(d);
    double ad = dot(A * dd, dd), amax = fmax(A.x, fmax(A.y, A.z));
    double ta = (double)a, tb = (double)b, tm = 0.5 * (ta + tb);
    double v2 = (double)k.sigma2, l = (double)k.length_scale, l2 = l * l;
    int rq = k.kind == GP_KERNEL_RATIONAL_QUADRATIC;
    double al = (double)k.alpha, cap_v;
    if (rq) {   /* |2k'(s)| sqrt(s) at its peak (every lane the same s) */
        double s_peak = al * l2 / (al + 0.5);
        wpd pk2, pk4;
        ws_post_radial(k, (wpd)s_peak, &pk2, &pk4);
        cap_v = fabs(wp_lane0(pk2)) * sqrt(s_peak);
    } else {
        cap_v = v2 * exp(-0.5) / l;
    }
    WsPostBound R = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    wpd ca = 0.0, cb = 0.0, cm = 0.0, dm = 0.0, mag = 0.0, sum1 = 0.0, sum2 = 0.0;
    double3 Ad = A * dd;
    for (int j0 = 0; j0 < P->n; j0 += WS_POST_LANES) {
        WsPostRows W = ws_post_rows(P->rows, P->v, P->n, j0);
        wpd r0x = od.x - W.x, r0y = od.y - W.y, r0z = od.z - W.z, gx, gy, gz;
        wpd rax = r0x + ta * dd.x, ray = r0y + ta * dd.y, raz = r0z + ta * dd.z;
        wpd rbx = r0x + tb * dd.x, rby = r0y + tb * dd.y, rbz = r0z + tb * dd.z;
        wpd xa = ws_post_cross(k, A, &W, rax, ray, raz, &gx, &gy, &gz);
        wpd xb = ws_post_cross(k, A, &W, rbx, rby, rbz, &gx, &gy, &gz);
        wpd xm = ws_post_cross(k, A, &W, r0x + tm * dd.x, r0y + tm * dd.y, r0z + tm * dd.z,
                               &gx, &gy, &gz);
        wpd vj = W.v, av = fabs(vj);
        ca += vj * xa;
        cb += vj * xb;
        cm += vj * xm;
        dm += vj * (gx * dd.x + gy * dd.y + gz * dd.z);
        mag += av * (fabs(xa) + fabs(xb) + fabs(xm));
        /* the range of s over the interval: s(t) = |r0 + t d|_A^2 is a convex quadratic */
        wpd tc = ad > 0.0 ? clamp(-(Ad.x * r0x + Ad.y * r0y + Ad.z * r0z) / ad, ta, tb)
                          : (wpd)ta;
        wpd rcx = r0x + tc * dd.x, rcy = r0y + tc * dd.y, rcz = r0z + tc * dd.z;
        wpd s_a = A.x * rax * rax + A.y * ray * ray + A.z * raz * raz;
        wpd s_b = A.x * rbx * rbx + A.y * rby * rby + A.z * rbz * rbz;
        wpd s_c = A.x * rcx * rcx + A.y * rcy * rcy + A.z * rcz * rcz;
        wpd s_max = fmax(s_a, s_b), s_min = fmin(s_c, fmin(s_a, s_b));
        wpd dk2, ddk4;
        ws_post_radial(k, s_min, &dk2, &ddk4);
        /* |8 k'''(s_min)|: SE k / l^6, RQ k (a+1)(a+2) / (a^2 l^6 base^3) */
        wpd dk3 = rq ? fabs(ddk4) * (al + 2.0) / (al * l2 * (1.0 + s_min / (2.0 * al * l2)))
                     : fabs(ddk4) / l2;
        /* |2k'| + |4k''| s, with its cap (header comment) */
        wpd h1 = fmin(fabs(dk2) + fabs(ddk4) * s_max,
                      rq ? (2.0 * al + 3.0) * fabs(dk2) : (wpd)(2.0 * exp(-0.5) * v2 / l2));
        wpd b1v = fmin(fabs(dk2) * sqrt(s_max), cap_v), b2v = h1;      /* value rows */
        /* derivative rows: sqrt(s) (3 |4k''| + |8k'''| s): SE's peaks at s = sqrt(3) l^2
         * at 2.62 sigma^2 / l^3; RQ's bracket is <= (2a + 7) |4k''| */
        wpd su = sqrt(A.x * W.ux * W.ux + A.y * W.uy * W.uy + A.z * W.uz * W.uz);
        wpd h2 = fmin(3.0 * fabs(ddk4) + dk3 * s_max,
                      rq ? (2.0 * al + 7.0) * fabs(ddk4) : (wpd)INFINITY);
        wpd b1d = su * h1;
        wpd b2d = su * fmin(sqrt(s_max) * h2, rq ? (wpd)INFINITY : (wpd)(2.62 * v2 / (l2 * l)));
        sum1 += av * select(b1v, b1d, W.deriv);
        sum2 += av * select(b2v, b2d, W.deriv);
    }
    R.ca = wp_hsum(ca);
    R.cb = wp_hsum(cb);
    R.cm = wp_hsum(cm);
    R.dm = wp_hsum(dm);
    R.mag = wp_hsum(mag);
    double s1 = wp_hsum(sum1), s2 = wp_hsum(sum2);
    /* The reproducing property caps both sums whatever the signs of v: for a unit d (in
     * A's metric), |d . grad c| <= rho sqrt(Var d_d f) = rho sigma / l and
     * |d^2 c| <= rho sqrt(Var d_d^2 f) = rho sqrt(12 k''(0)) (12 k''(0) = 3 sigma^2 / l^4
     * for SE, times (a + 1) / a for RQ). Termwise sums decay away from the observations;
     * the RKHS caps win where large v of both signs cancel (near the observed surface). */
    double rk1 = P->rho * sqrt(v2) / l;
    double rk2 = P->rho * sqrt(3.0 * v2 * (rq ? (al + 1.0) / al : 1.0)) / l2;
    s1 = fmin(s1, rk1);
    R.slope = sqrt(ad) * s1;
    R.slope_any = sqrt(amax) * s1;
    R.curv = ad * fmin(s2, rk2);
    return R;
}
