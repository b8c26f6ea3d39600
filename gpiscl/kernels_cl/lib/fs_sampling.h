/* Function-space GPIS free flight: conditioning rows, start conditions, memory models.
 * Needs gp_kernel.h built with -DGP_REAL=double, gp_mean.h, fs_linalg.h, philox (rng.h),
 * and the declarations of function_space_records.c_declarations(); FS_MAX_ROWS and
 * FS_SCRATCH_DOUBLES come from function_space_records.defines().
 * fs_march.h (included after this) marches along the ray.
 * gpiscl/testing/reference/function_space.py is the numpy reference of everything here.
 *
 * Conventions (sign as everywhere: f > 0 outside; a hit is the first f >= 0 -> f < 0):
 *  - Stepping, online sampling, the crossing bracket, the slope at a hit: fs_march.h
 *    (fs_free_flight). The fixed step of fs_step below (neighbours at correlation c: dt =
 *    l sqrt(-2 ln c) / sqrt(d'Ad) for SE, l sqrt(2a (c^(-1/a) - 1) / d'Ad) for RQ,
 *    bisection on k(t d)/k(0) = c otherwise) gives fs_march.h its length scale l_d
 *    (c = e^-1/2) and the benchmarks their uniform baseline.
 *  - Start condition (a ray entering from free space or a surface, and every ray
 *    from a vertex under `none`): f(x(t0)) = v0 with v0 ~ N(mu, k(0)) truncated to [0, inf)
 *    (the authors' convention: the ray starts outside; k(0) is k(x, x) under a sigma(x)
 *    field). Exact inverse-CDF sampler, so a ray whose mean at t0 is far inside gets
 *    v0 ~ s/|a| just above 0, not an atom at 0.
 *  - Memory models at a new ray from a vertex (inside a ray every model conditions on
 *    the ray's window of samples, fs_march.h):
 *      none          fresh start condition at the start point (forgets everything);
 *      renewal       f(x) = 0; the slope
 *                    along the new direction is free, and we draw it from its prior law
 *                    truncated to >= 0: the ray leaves to the outside. Consequence: no
 *                    re-hit atom at t = 0+ (a free slope would send ~half the rays
 *                    straight back inside, i.e. an immediate second scattering at the
 *                    vertex, which is what the reference's `dori` does), and the slope is
 *                    independent of the vertex's sampled normal;
 *      renewal_plus  value and the slope along the new direction: g . d_new
 *                    (g . d_new < 0, e.g. transmission, starts the ray inside);
 *      global        the draws of the path so far (each ray's window up to its hit's
 *                    first negative sample, the bisection points, and at each hit the
 *                    three gradient components, each derivative with its own
 *                    direction), the most recent `cap` of them; the path's
 *                    observations live in a per-path ring of capacity cap
 *                    (FsVertex.obs_end/obs_count). The ring holds genuine draws and,
 *                    at a hit, the crossing's f(x_h) = 0 (fs_march.h), never a secant.
 *  - Normal at a hit: the slope along d is drawn from its law at a down-crossing
 *    (fs_march.h); the tangential components from their conditional law given all rows,
 *    f(x_h) = 0 and that slope. Isotropic radial kernels (SE, RQ, thin-plate with equal
 *    aniso) without global memory have every row on the ray, and cov(d_T f(x_h),
 *    anything on the ray) = 0, so the closed form N(T . grad mu(x_h), -2k'(0) I_2) is
 *    used; anisotropic/product kernels take the general conditional (two appended rows),
 *    and so do kernels with sigma(x) or l(x) fields (grad sigma, grad l correlate
 *    d_T f(x_h) with the ray's values), a posterior (observations correlate d_T f(x_h)
 *    with everything) and global memory (the ring's rows lie off the ray).
 *  - Posterior GPIS (FsPost, S.post; fs_posterior.h finds an object's): every mean and
 *    covariance above is the posterior's, m + k alpha and k - v.v, so start values,
 *    renewal slopes, the march, bisection and normals are all conditioned on the
 *    observations exactly. Cost per conditioned row O(n^2) (a triangular solve; v is
 *    cached per row in S.v, FS_POST_MAX n per row), so n stays at a few hundred.
 *    The step rule keeps the prior's: the mean correction varies on the kernel's scale and
 *    the residual's derivative variances never exceed the prior's.
 *  - Random numbers: philox4x32, key (seed, FS_PHILOX_KEY) (rng.h uses another key
 *    word), counter (pixel, sample, bounce, stream << 28 | step << 12 | block): one
 *    block = two 53-bit uniforms; fixed block numbers per draw (fs_march.h), so results
 *    are independent of batching and queue order. `stream` separates the rays traced
 *    from one vertex (e.g. 0 continuation, 1 light-sample shadow, 2 BSDF-sample shadow).
 */
typedef char fs_gp_real_must_be_double[sizeof(GP_REAL) == 8 ? 1 : -1];

/* FS_MAX_ROWS, FS_POST_MAX (observation rows of the largest posterior GPIS),
 * FS_SCRATCH_DOUBLES and FS_MAX_WINDOW (the largest FsParams.window of the program) */
#if !defined(FS_MAX_ROWS) || !defined(FS_POST_MAX) || !defined(FS_SCRATCH_DOUBLES) \
    || !defined(FS_MAX_WINDOW)
#error "FS_MAX_ROWS, ... come from the host (layout/function_space_records.defines)"
#endif
#define FS_TN_TAIL 30.0            /* beyond: exact rejection tail, erfc would underflow */
/* FS_PHILOX_KEY: layout/constants.py; FS_SLOT_* (normals), FS_U_* (uniform blocks):
 * layout/random_slots.py */

typedef struct { uint seed, pixel, sample, bounce, stream; } FsRng;
/* window: samples kept besides the memory (0: FS_WINDOW); step_corr > 0: the uniform
 * baseline step (benchmarks), else the adaptive rule with miss_tol (fs_march.h). */
typedef struct { int window, memory, cap, refine; double step_corr, miss_tol; } FsParams;
typedef struct { double3 o, d; double t0, t1; } FsRay;
/* A posterior GPIS (gpiscl/host/gp/posterior.py; packed by compile/posterior.py): the
 * prior conditioned on n observation rows X (values and directional derivatives, with
 * noise). Every prior mean and covariance below becomes
 *   m'(x) = m(x) + k(x, X) alpha,            alpha = K^-1 (y - m(X)),
 *   k'(a, b) = k(a, b) - v_a . v_b,          v_a = L^-1 k(X, a),  K + noise = L L^T,
 * which is exact: the observations join every ray's conditioning set, with their
 * factor computed once on the host instead of per ray. n = 0: the prior. */
typedef struct {
    __global const FsObs* obs;
    __global const double* alpha;
    __global const double* L;      /* packed lower triangle (fs_tri) */
    int n;
} FsPost;

typedef struct {
    __global FsObs* rows;
    __global double* L;
    __global double* e;
    __global double* mu;
    /* A kernel with sigma(x) or l(x) fields: row i's multipliers at fields + 8 i
     * (fs_store_fields), evaluated once when the row is factored: O(rows) field
     * evaluations (a grid field reads 8 samples) instead of O(rows^2). */
    __global double* fields;
    /* The posterior rides along with the scratch because every function that needs it
     * already takes S; v caches v_a of row i at v + i n (an O(n^2) solve per row, reused
     * by all O(rows^2) covariance entries of the row). */
    __global double* v;
    FsPost post;
} FsScratch;
typedef struct {
    int status, hit;
    double t;               /* hit distance, or t1 */
    double3 grad;           /* sampled gradient of f at the hit (outward, grad . d < 0) */
    int samples, evals;     /* work done: GP values drawn, step-rule moment evaluations */
    int new_first, new_end;  /* global: rows [new_first, new_end) join the memory */
    /* The law the hit's normal was drawn from (fs_march.h, "Hit"; its density is
     * fs_normal_pdf.h): the slope along the unit ray direction, law_s < 0, pinned; the
     * tangential gradient g_t = g - (g.d) d ~ N(law_m, S_q) in the plane normal to d,
     * given as world vectors: law_m the mean, and law_a, law_b with
     * (law_a . (g_t - law_m), law_b . (g_t - law_m)) ~ N(0, I_2), i.e. the rows of
     * L^-1 (S_q = L L^T in the frame T, B of fs_frame(d)) written in world space, so the
     * scatter stage needs no frame: |law_a x law_b| = 1 / sqrt(det S_q). */
    double law_s;
    double3 law_m, law_a, law_b;
    int roots;              /* of `samples`: drawn by the root search at the hit */
#ifdef FS_PROFILE
    int prof[FS_PROF_COUNT];   /* fs_march.h's profile counters */
#endif
} FsResult;

inline FsScratch fs_scratch(__global double* base, int item)
{
    __global double* s = base + (size_t)item * FS_SCRATCH_DOUBLES;
    FsScratch S;
    S.rows = (__global FsObs*)s;
    S.L = s + 8 * FS_MAX_ROWS;
    S.e = S.L + FS_MAX_ROWS * (FS_MAX_ROWS + 1) / 2;
    S.mu = S.e + FS_MAX_ROWS;
    S.fields = S.mu + FS_MAX_ROWS;
    S.v = S.fields + 8 * FS_MAX_ROWS;
    S.post.obs = 0;
    S.post.alpha = S.post.L = 0;
    S.post.n = 0;
    return S;
}

inline double2 fs_uniform2(FsRng r, uint seg, uint block)
{
    philox4x32_ctr_t c = {{r.pixel, r.sample, r.bounce,
                           (r.stream << 28) | ((seg & 0xffffu) << 12) | (block & 0xfffu)}};
    philox4x32_key_t k = {{r.seed, FS_PHILOX_KEY}};
    philox4x32_ctr_t x = philox4x32(c, k);
    const double s = 1.0 / 9007199254740992.0;   /* 2^-53: uniforms in [0, 1) */
    return (double2)((double)(((ulong)x.v[0] << 21) ^ (x.v[1] >> 11)) * s,
                     (double)(((ulong)x.v[2] << 21) ^ (x.v[3] >> 11)) * s);
}

inline double fs_normal(FsRng r, uint seg, uint slot)
{
    double2 u = fs_uniform2(r, seg, slot >> 1);
    double rad = sqrt(-2.0 * log(1.0 - u.x)), ang = 2.0 * M_PI * u.y;
    return (slot & 1) ? rad * sin(ang) : rad * cos(ang);
}

/* Upper tail Q(x) = P(Z > x), and its inverse: Abramowitz-Stegun 26.2.23 (|err| < 5e-4)
 * polished by two Halley steps on Q(x) = q (cubic: ~1e-15 relative, tails included). */
inline double fs_q(double x) { return 0.5 * erfc(x * M_SQRT1_2); }

inline double fs_qinv(double q)
{
    q = clamp(q, DBL_MIN, 1.0 - DBL_EPSILON);
    double p = fmin(q, 1.0 - q), t = sqrt(-2.0 * log(p));
    double x = t - (2.515517 + t * (0.802853 + t * 0.010328))
                 / (1.0 + t * (1.432788 + t * (0.189269 + t * 0.001308)));
    if (q > 0.5) x = -x;
    for (int it = 0; it < 2; ++it) {
        double u = (fs_q(x) - q) * 2.5066282746310002 * exp(0.5 * x * x);
        x += u / (1.0 - 0.5 * x * u);
    }
    return x;
}

/* x ~ N(mu, s^2) conditioned on x >= 0, by inverting the truncated CDF in double. The
 * lower tail (a < 0) inverts Phi and the upper tail Q, so both stay accurate where the
 * truncated mass is tiny; past FS_TN_TAIL standard deviations below 0, Marsaglia's tail
 * sampler with its acceptance test (the reference dropped the test: a Rayleigh tail). */
inline double fs_truncnorm_pos(double mu, double s, FsRng rng, uint seg, uint block)
{
    if (!(s > 0.0)) return fmax(mu, 0.0);
    double a = -mu / s, z = a;
    if (a > FS_TN_TAIL) {
        for (uint k = 0; k < FS_TN_TAIL_TRIES; ++k) {
            double2 u = fs_uniform2(rng, seg, block + 1 + k);
            double x = sqrt(a * a - 2.0 * log(1.0 - u.x));
            if (u.y * x <= a) { z = x; break; }
        }
    } else {
        double u = fs_uniform2(rng, seg, block).x;
        z = a < 0.0 ? -fs_qinv(fs_q(-a) + u * fs_q(a))    /* Phi(z) = Phi(a) + u Q(a) */
                    : fs_qinv(fs_q(a) * (1.0 - u));        /* Q(z) = Q(a) (1 - u) */
    }
    return fmax(mu + s * fmax(z, a), 0.0);
}

inline double fs_corr(GpKernel p, double3 d, double t)
{
    return gp_kernel_value(p, t * d) / gp_kernel_value(p, (double3)(0.0));
}

/* The lag dt with corr(f(x), f(x + dt d)) = c (stationary kernels: independent of x). */
inline double fs_step_stationary(GpKernel p, double3 d, double c)
{
    double dad = dot(gp_aniso(p) * d, d);
    if (GP_KERNEL_IS_CORR_LAG(p.kind)) return gp_kernel_corr_lag(p.kind, p, dad, c);
    double3 o = (double3)(0.0);
    double lam = gp_cov(p, o, d, 1, o, d, 1) / gp_kernel_value(p, o);
    double lo = 0.0, hi = sqrt(2.0 * (1.0 - c) / lam);
    int k = 0;
    for (; k < 40 && fs_corr(p, d, hi) > c; ++k) { lo = hi; hi *= 2.0; }
    if (k == 40) return sqrt(2.0 * (1.0 - c) / lam);
    for (k = 0; k < 60; ++k) {
        double mid = 0.5 * (lo + hi);
        if (fs_corr(p, d, mid) > c) lo = mid; else hi = mid;
    }
    return 0.5 * (lo + hi);
}

/* The smallest l(x) on the segment [a, b] of a ray inside the proxy: a linear field at an
 * end; a radial one (monotone in q = |x - c|^2, which is convex along the segment) where q
 * is smallest or largest; a grid field the proxy's smallest (ls_step). Never below
 * ls_step, the smallest over the proxy. */
inline double fs_ls_min_on(GpKernel p, double3 a, double3 b)
{
    double l = p.length_scale, m = p.ls_step / l;
    double3 g;
    if (p.ls_field == GP_FIELD_LINEAR) {
        m = fmin(gp_field(p.ls_field, p.ls_p0, p.ls_p1, a, &g),
                 gp_field(p.ls_field, p.ls_p0, p.ls_p1, b, &g));
    } else if (p.ls_field == GP_FIELD_RADIAL) {
        double3 c = (double3)(p.ls_p0.x, p.ls_p0.y, p.ls_p0.z), ab = b - a;
        double w = dot(ab, ab) > 0.0 ? clamp(dot(c - a, ab) / dot(ab, ab), 0.0, 1.0) : 0.0;
        double3 near = a + w * ab, far = dot(a - c, a - c) > dot(b - c, b - c) ? a : b;
        /* outer >= inner: m grows with q, so its minimum is nearest the centre */
        double3 x = p.ls_p1.y >= p.ls_p1.x ? near : far;
        m = gp_field(p.ls_field, p.ls_p0, p.ls_p1, x, &g);
    }
    return fmax(l * m, (double)p.ls_step);
}

/* A variance field leaves the correlation stationary (sigma(x) sigma(y) cancels), so the
 * stationary rule is exact for it. A length-scale field is stepped with the smallest l(x)
 * on the ray's segment [t0, t1] (fs_ls_min_on): never coarser than the local rule
 * anywhere on the ray, at the price of oversampling where l(x) is larger. */
inline double fs_step(GpKernel p, FsRay ray, double c)
{
    if (p.ls_field)
        p.length_scale = fs_ls_min_on(p, ray.o + ray.t0 * ray.d, ray.o + ray.t1 * ray.d);
    p.sigma_field = p.ls_field = GP_FIELD_NONE;
    return fs_step_stationary(p, ray.d, c);
}

inline FsObs fs_obs(double3 x, double3 u, int kind, double value)
{
    FsObs o = {x.x, x.y, x.z, u.x, u.y, u.z, value, kind, 0};
    return o;
}

inline double3 fs_pos(__global const FsObs* o) { return (double3)(o->px, o->py, o->pz); }
inline double3 fs_dir(__global const FsObs* o) { return (double3)(o->ux, o->uy, o->uz); }

inline double fs_prior_mean(__global const MeanNode* mean, int mc, double3 x, double3 u,
                            int kind)
{
    if (kind != FS_OBS_DERIV) return (double)gp_mean_value(mean, mc, convert_float3(x));
    float3 g;
    gp_mean_eval(mean, mc, convert_float3(x), &g);
    return dot(convert_double3(g), u);
}

inline __global double* fs_post_v(FsScratch S, int i) { return S.v + (size_t)i * S.post.n; }

/* A grid field's multiplier and world gradient at x: grid record n maps world points to
 * index coordinates (row0..row2); trilinear with the border held (gp_grid_trilinear). */
inline double fs_grid_field(__global const MeanNode* n, double3 x, double3* grad)
{
    float3 xf = convert_float3(x), gu, out;
    float3 u = gp_leaf_local(n, xf);
    float m = gp_grid_trilinear(n, u, &gu, &out);
    *grad = convert_double3(gu.x * n->row0.xyz + gu.y * n->row1.xyz + gu.z * n->row2.xyz);
    return (double)m;
}

/* The kernel's field multipliers at x; grid fields are records at mean + p.sigma_grid /
 * p.ls_grid, offsets from the object's mean program (compile/gpis.py puts them after
 * every mean program). */
inline GpFieldsAt fs_fields(GpKernel p, __global const MeanNode* mean, double3 x)
{
    GpFieldsAt f = gp_fields_analytic(p, x);
    if (p.sigma_field == GP_FIELD_GRID) f.ms = fs_grid_field(mean + p.sigma_grid, x, &f.gs);
    if (p.ls_field == GP_FIELD_GRID) f.ml = fs_grid_field(mean + p.ls_grid, x, &f.gl);
    return f;
}

/* The smallest and largest of a kernel grid field over the segment [a, b]: the samples
 * of every trilinear cell (gp_grid_cell) the segment's index box meets, padded for the
 * float map. fs_classical.h's tracker keeps stretches within a voxel (at most 3^3
 * samples); fs_mean_step's balls may be longer and check fs_grid_box_samples first
 * (FS_SD_BOX_SAMPLES: the most samples one segment's bound reads). */
#define FS_SD_BOX_SAMPLES 64
inline void fs_grid_box(__global const MeanNode* n, double3 a, double3 b, int3* c0, int3* c1)
{
    float3 fa = convert_float3(a), fb = convert_float3(b);
    float3 ua = gp_leaf_local(n, fa), ub = gp_leaf_local(n, fb);
    float3 pad = 2e-3f + 4.0f * FLT_EPSILON * fmax(fabs(ua), fabs(ub));
    float3 top = n->p1.xyz - 1.0f;
    *c0 = convert_int3(fmin(floor(fmin(fmax(fmin(ua, ub) - pad, 0.0f), top)), top - 1.0f));
    *c1 = convert_int3(fmin(floor(fmin(fmax(fmax(ua, ub) + pad, 0.0f), top)), top - 1.0f)) + 1;
}

/* How many samples fs_grid_field_range reads for the segment [a, b]. */
inline int fs_grid_box_samples(__global const MeanNode* n, double3 a, double3 b)
{
    int3 c0, c1;
    fs_grid_box(n, a, b, &c0, &c1);
    int3 w = c1 - c0 + 1;
    return w.x * w.y * w.z;
}

/* One pass over the samples of fs_grid_box's cells for the segment [a, b] (at most
 * FS_SD_BOX_SAMPLES; callers check fs_grid_box_samples, a larger box gives NaN): their
 * smallest and largest, and per index axis the range [dlo, dhi] of the differences of
 * neighbouring samples (each read once, into the box's own array). gp_lesser / gp_greater,
 * not fmin / fmax: the same results here (a NaN sample is passed over as fmin does, since
 * the running values start at +-INFINITY and never become NaN), and fmin's NaN rule was a
 * third of the scan's time (docs/design/grid-means.md, "Sigma grids' box scans"). */
inline double2 fs_grid_box_scan(__global const MeanNode* n, double3 a, double3 b,
                                float3* dlo, float3* dhi)
{
    int3 c0, c1;
    fs_grid_box(n, a, b, &c0, &c1);
    int3 wd = c1 - c0 + 1;
    *dlo = (float3)(INFINITY);
    *dhi = (float3)(-INFINITY);
    if (wd.x * wd.y * wd.z > FS_SD_BOX_SAMPLES) return (double2)(NAN);
    int ny = (int)n->p1.y, nz = (int)n->p1.z;
    float box[FS_SD_BOX_SAMPLES];     /* strides wd.y wd.z, wd.z, 1 */
    float lo = INFINITY, hi = -INFINITY;
    for (int i = 0, at = 0; i < wd.x; ++i)
        for (int j = 0; j < wd.y; ++j) {
            int k;                                   /* a run along z (gp_grid_run) */
            __global const float* f =
                gp_grid_place(n + 1, ((c0.x + i) * ny + c0.y + j) * nz + c0.z, &k);
            for (int q = 0; q < wd.z; ++q, ++at) {
                float v = gp_grid_run(&f, &k);
                box[at] = v;
                lo = gp_lesser(lo, v);
                hi = gp_greater(hi, v);
                if (i) { float e = v - box[at - wd.y * wd.z]; dlo->x = gp_lesser(dlo->x, e); dhi->x = gp_greater(dhi->x, e); }
                if (j) { float e = v - box[at - wd.z]; dlo->y = gp_lesser(dlo->y, e); dhi->y = gp_greater(dhi->y, e); }
                if (q) { float e = v - box[at - 1]; dlo->z = gp_lesser(dlo->z, e); dhi->z = gp_greater(dhi->z, e); }
            }
        }
    return (double2)(lo, hi);
}

inline double2 fs_grid_field_range(__global const MeanNode* n, double3 a, double3 b)
{
    float3 dlo, dhi;
    return fs_grid_box_scan(n, a, b, &dlo, &dhi);
}

/* The range of one field multiplier over the segment [a, b]: 1 without a field, a linear
 * field's end values, a radial one's inner and outer levels (it blends between them), a
 * grid's samples (fs_grid_field_range). */
inline double2 fs_field_range(int kind, float4 p0, float4 p1,
                                 __global const MeanNode* grid, double3 a, double3 b)
{
    double3 g;
    if (kind == GP_FIELD_LINEAR) {
        double va = gp_field(kind, p0, p1, a, &g), vb = gp_field(kind, p0, p1, b, &g);
        return (double2)(fmin(va, vb), fmax(va, vb));
    }
    if (kind == GP_FIELD_RADIAL) return (double2)(fmin(p1.x, p1.y), fmax(p1.x, p1.y));
    if (kind == GP_FIELD_GRID) return fs_grid_field_range(grid, a, b);
    return (double2)(1.0);
}

/* Bounds of how fast one field multiplier m may fall and rise along x(t) = a + t d on
 * t in [0, 1] (d = b - a): (.x, .y) = (max of -dm/dt, max of dm/dt), both >= 0. A linear
 * field's slope has its sign; a radial blend's largest tanh slope on the segment (|q| at
 * most its end's, 1 - tanh^2 at its smallest |argument|) either way; a grid's range of
 * sample differences along each index axis over the cells the segment's index box meets
 * (a trilinear cell's partial derivative lies between its four edge differences), at
 * most FS_SD_BOX_SAMPLES samples, else INFINITY (the caller shortens the segment). */
inline double2 fs_field_slope(int kind, float4 p0, float4 p1, __global const MeanNode* grid,
                              double3 a, double3 b)
{
    double3 d = b - a;
    if (kind == GP_FIELD_LINEAR) {
        double s = dot(convert_double3(p0.xyz), d);
        return (double2)(fmax(-s, 0.0), fmax(s, 0.0));
    }
    if (kind == GP_FIELD_RADIAL) {
        double3 c = convert_double3(p0.xyz), qa = a - c;
        double R = p0.w, w = p1.z, h = 0.5 * fabs((double)p1.y - (double)p1.x);
        double dd = dot(d, d);
        double s = dd > 0.0 ? clamp(-dot(qa, d) / dd, 0.0, 1.0) : 0.0;
        double3 qn = qa + s * d;
        double rmin2 = dot(qn, qn), rmax2 = fmax(dot(qa, qa), dot(b - c, b - c));
        double ulo = (rmin2 - R * R) / (2.0 * R * w), uhi = (rmax2 - R * R) / (2.0 * R * w);
        double u = ulo <= 0.0 && uhi >= 0.0 ? 0.0 : fmin(fabs(ulo), fabs(uhi));
        double th = tanh(u);
        return (double2)(h * (1.0 - th * th) * sqrt(rmax2) / (R * w) * sqrt(dd));
    }
    if (kind != GP_FIELD_GRID) return (double2)(0.0);
    float3 lo, hi;
    if (isnan(fs_grid_box_scan(grid, a, b, &lo, &hi).x)) return (double2)(INFINITY);
    /* index coordinates per unit t along d (the record's rows map world to index); dm/dt
     * = sum_i dm/du_i du_i/dt with dm/du_i in [lo_i, hi_i] */
    double3 du = (double3)(dot(convert_double3(grid->row0.xyz), d),
                           dot(convert_double3(grid->row1.xyz), d),
                           dot(convert_double3(grid->row2.xyz), d));
    double3 dl = convert_double3(lo) * du, dh = convert_double3(hi) * du;
    double3 top = fmax(dl, dh), bottom = fmin(dl, dh);
    return (double2)(fmax(-(bottom.x + bottom.y + bottom.z), 0.0),
                     fmax(top.x + top.y + top.z, 0.0));
}

/* How far along the segment [a, b] (a fraction c in [0, 1]) a grid field's largest rates
 * of rise and fall, over the cells the segment crosses up to c, keep it within `rise` and
 * `fall` of its value at a: c times the largest rate is at most the budget (or c is the
 * face of the cell that raised the rate past it). Per cell (GpCellWalk) the field's slope
 * along the segment lies in sum_i d_i [lo_i, hi_i] of the cell's edge differences (d the
 * segment in index units). fs_field_slope's bound over the segment's index box, but over
 * the cells the segment crosses: never shorter, longer wherever the box holds a steeper
 * cell than the ray meets before c. Rates, not the sum of the rises: fs_field_cap needs
 * sigma to move no faster than linearly at its largest rate over the try. c is also the
 * first face past a where the slope along the segment (the midpoint of a cell's range)
 * jumps by FS_FIELD_KINK `rise` or more: a kink there would bend f between the rule's
 * nodes (docs/design/grid-means.md, "Sigma fields along the ray"). -1 where the segment
 * starts or ends outside the sample box: the caller takes the box's bound. */
inline float fs_grid_field_reach(__global const MeanNode* n, float3 a, float3 b, float rise,
                                 float fall)
{
    GpCellWalk w;
    if (!gp_cell_walk_begin(n, a, b, &w)) return -1.0f;
    float3 d = gp_leaf_local(n, b) - gp_leaf_local(n, a);
    float up = 0.0f, down = 0.0f;       /* the largest rates so far, per unit fraction */
    float mid = NAN;                    /* the last cell's slope (its range's midpoint) */
    do {
        float2 r = gp_cell_slope_range(w.s, d);
        float a0 = r.y, a1 = r.x;
        float m = 0.5f * (a0 + a1);
        /* a kink: the slope's jump at this face bends f by up to jump x e (FS_FIELD_KINK) */
        if (w.t > 0.0f && fabs(m - mid) >= (float)FS_FIELD_KINK * rise) return w.t;
        mid = m;
        up = max(up, a0);
        down = max(down, -a1);
        float c = gp_lesser(up > 0.0f ? rise / up : INFINITY, down > 0.0f ? fall / down : INFINITY);
        if (c < w.tout) return max(c, w.t);
    } while (gp_cell_walk_next(&w));
    return w.tend >= 1.0f ? 1.0f : -1.0f;
}

inline void fs_store_fields(FsScratch S, int i, GpFieldsAt f)
{
    __global double* q = S.fields + 8 * i;
    q[0] = f.ms;
    vstore3(f.gs, 0, q + 1);
    q[4] = f.ml;
    vstore3(f.gl, 0, q + 5);
}

inline GpFieldsAt fs_row_fields(FsScratch S, int i)
{
    __global const double* q = S.fields + 8 * i;
    GpFieldsAt f = {q[0], q[4], vload3(0, q + 1), vload3(0, q + 5)};
    return f;
}

/* v = L^-1 k(X, target) (forward substitution), and the mean correction k(target, X) alpha;
 * fx: the fields at the target x. */
inline double fs_post_solve(GpKernel p, __global const MeanNode* mean, FsPost P, double3 x,
                            double3 u, int kind, GpFieldsAt fx, __global double* v)
{
    double corr = 0.0;
    int ns = gp_kernel_nonstationary(p);
    for (int j = 0; j < P.n; ++j) {
        __global const FsObs* o = P.obs + j;
        double3 xo = fs_pos(o);
        double k = gp_cov_at(p, xo, fs_dir(o), o->kind, ns ? fs_fields(p, mean, xo) : fx,
                             x, u, kind, fx);
        v[j] = k;
        corr += k * P.alpha[j];
    }
    for (int i = 0; i < P.n; ++i) {
        __global const double* Li = P.L + fs_tri(i);
        double s = v[i];
        for (int j = 0; j < i; ++j) s -= Li[j] * v[j];
        v[i] = s / Li[i];
    }
    return corr;
}

inline double fs_post_dot(__global const double* a, __global const double* b, int n)
{
    double s = 0.0;
    for (int j = 0; j < n; ++j) s += a[j] * b[j];
    return s;
}

/* Mean and variance (posterior if any) of one value or derivative at x; row slot `slot`'s
 * v is the work space (its row is refactored before it is used again). */
inline double fs_mean_var(GpKernel p, __global const MeanNode* mean, int mc, FsScratch S,
                          double3 x, double3 u, int kind, int slot, double* var)
{
    double m = fs_prior_mean(mean, mc, x, u, kind);
    GpFieldsAt fx = fs_fields(p, mean, x);
    double k = gp_cov_at(p, x, u, kind, fx, x, u, kind, fx);
    if (S.post.n) {
        __global double* v = fs_post_v(S, slot);
        m += fs_post_solve(p, mean, S.post, x, u, kind, fx, v);
        k -= fs_post_dot(v, v, S.post.n);
    }
    *var = fmax(k, 0.0);
    return m;
}

/* Row i's own numbers: its prior mean (posterior-corrected), the posterior solve v and
 * the kernel's field multipliers at it. They belong to the observation, not to its place
 * in a system, so a row moved or copied into another system (same prior and posterior)
 * takes them along (fs_row_copy) instead of evaluating the mean program, the fields and
 * an O(observations^2) solve again. */
inline void fs_row_prep(GpKernel p, __global const MeanNode* mean, int mc, FsScratch S, int i)
{
    __global const FsObs* ri = S.rows + i;
    double3 xi = fs_pos(ri), ui = fs_dir(ri);
    GpFieldsAt fi = fs_fields(p, mean, xi);
    if (gp_kernel_nonstationary(p)) fs_store_fields(S, i, fi);
    S.mu[i] = fs_prior_mean(mean, mc, xi, ui, ri->kind);
    if (S.post.n) S.mu[i] += fs_post_solve(p, mean, S.post, xi, ui, ri->kind, fi,
                                           fs_post_v(S, i));
}

/* Row k of S, with its own numbers (fs_row_prep), becomes row i of D (D may be S: a
 * move to a lower index); D's factor row i is left to fs_factor_known. */
inline void fs_row_copy(GpKernel p, FsScratch S, int k, FsScratch D, int i)
{
    D.rows[i] = S.rows[k];
    D.mu[i] = S.mu[k];
    if (gp_kernel_nonstationary(p)) fs_store_fields(D, i, fs_row_fields(S, k));
    for (int j = 0; j < S.post.n; ++j) fs_post_v(D, i)[j] = fs_post_v(S, k)[j];
}

/* The stationary kernel's jets at x - (row j's position) for rows j0 .. j0 + FS_LANES - 1
 * of S: a radial
 * kernel's exps are taken in one double4, which PoCL's CPU runs several times faster than
 * as scalars, and these exps were the largest single cost of a function-space flight.
 * 4 lanes, not 8: adaptive flights hold few rows (memory + a few samples). Used where
 * rows are factored (fs_factor_known); the step rule's small system (fs_moments) gained
 * nothing from it (docs/design/function-space-march.md, 'Vector jets'). The same
 * operations as gp_kernel_jet lane by lane; the vector exp may round differently from the
 * scalar one (images moved by <= 1e-6 on the room, none on the SE sphere). */
#define FS_LANES 4
inline void fs_jets(GpKernel p, FsScratch S, int j0, double3 x, GpJet* J)
{
    double3 r[FS_LANES];
    for (int l = 0; l < FS_LANES; ++l) r[l] = x - fs_pos(S.rows + j0 + l);
    if (gp_kernel_is_product(p)) {
        for (int l = 0; l < FS_LANES; ++l) J[l] = gp_kernel_jet(p, r[l]);
        return;
    }
    double3 A = gp_aniso(p);
    double s[FS_LANES], a[FS_LANES], e[FS_LANES];
    for (int l = 0; l < FS_LANES; ++l) {
        s[l] = dot(A * r[l], r[l]);
        a[l] = gp_radial_arg(p, s[l]);
    }
    vstore4(exp(vload4(0, a)), 0, e);
    for (int l = 0; l < FS_LANES; ++l) J[l] = gp_radial_jet(p, r[l], s[l], e[l]);
}

/* Covariance rows and factor of rows [from, n), whose own numbers are in place. */
inline int fs_factor_known(GpKernel p, __global const MeanNode* mean, FsScratch S, int from,
                           int n)
{
    int np = S.post.n, ns = gp_kernel_nonstationary(p);
    for (int i = from; i < n; ++i) {
        __global const FsObs* ri = S.rows + i;
        double3 xi = fs_pos(ri), ui = fs_dir(ri);
        __global double* Li = S.L + fs_tri(i);
        if (ns) {
            GpFieldsAt fi = fs_row_fields(S, i);
            int j0 = 0;
            /* a sigma field alone: the base kernel's jets in vector lanes, as below */
            for (; !p.ls_field && j0 + FS_LANES <= i + 1; j0 += FS_LANES) {
                GpJet J[FS_LANES];
                fs_jets(p, S, j0, xi, J);
                for (int l = 0; l < FS_LANES; ++l) {
                    __global const FsObs* rj = S.rows + j0 + l;
                    Li[j0 + l] = gp_cov_sigma_jet(J[l], fs_dir(rj), rj->kind,
                                                  fs_row_fields(S, j0 + l), ui, ri->kind, fi);
                }
            }
            for (int j = j0; j <= i; ++j) {
                __global const FsObs* rj = S.rows + j;
                Li[j] = gp_cov_at(p, fs_pos(rj), fs_dir(rj), rj->kind, fs_row_fields(S, j),
                                  xi, ui, ri->kind, fi);
            }
        } else {
            /* stationary: gp_cov's k(x_i - x_j) jets, FS_LANES at a time (fs_jets), the
             * last < FS_LANES one by one (a part-filled vector cost more than it saved) */
            int j0 = 0;
            for (; j0 + FS_LANES <= i + 1; j0 += FS_LANES) {
                GpJet J[FS_LANES];
                fs_jets(p, S, j0, xi, J);
                for (int l = 0; l < FS_LANES; ++l) {
                    __global const FsObs* rj = S.rows + j0 + l;
                    Li[j0 + l] = gp_jet_cov(J[l], fs_dir(rj), rj->kind, ui, ri->kind);
                }
            }
            for (int j = j0; j <= i; ++j) {
                __global const FsObs* rj = S.rows + j;
                Li[j] = gp_cov(p, fs_pos(rj), fs_dir(rj), rj->kind, xi, ui, ri->kind);
            }
        }
        for (int j = 0; np && j <= i; ++j)
            Li[j] -= fs_post_dot(fs_post_v(S, j), fs_post_v(S, i), np);
    }
    return fs_cholesky(S.L, from, n, 0);
}

/* Means, covariance rows and factor of rows [from, n) (posterior if S.post.n). */
inline int fs_factor(GpKernel p, __global const MeanNode* mean, int mc, FsScratch S,
                     int from, int n)
{
    for (int i = from; i < n; ++i) fs_row_prep(p, mean, mc, S, i);
    return fs_factor_known(p, mean, S, from, n);
}

/* Append one row at index i, conditioned on rows [0, i): sampled (returns the draw) or,
 * if `observed`, whitened at `value`. */
inline double fs_append(GpKernel p, __global const MeanNode* mean, int mc, FsScratch S,
                        int i, FsObs o, int observed, double z, int* status)
{
    S.rows[i] = o;
    int st = fs_factor(p, mean, mc, S, i, i + 1);
    if (st) { *status = st; return NAN; }
    if (observed) { fs_whiten_row(S.L, S.e, i, o.value, S.mu[i]); return o.value; }
    double v = fs_sample_row(S.L, S.e, i, S.mu[i], z);
    S.rows[i].value = v;
    return v;
}

inline void fs_frame(double3 n, double3* t, double3* b)   /* Duff et al. 2017 */
{
    double sign = copysign(1.0, n.z), a = -1.0 / (sign + n.z), c = n.x * n.y * a;
    *t = (double3)(1.0 + sign * n.x * n.x * a, sign * c, -sign * n.x);
    *b = (double3)(c, sign + n.y * n.y * a, -n.y);
}

inline int fs_isotropic_radial(GpKernel p)
{
    /* sigma(x), l(x) correlate d_T f(x_h) with the ray's values: no closed form */
    return !gp_kernel_nonstationary(p)
        && GP_KERNEL_IS_RADIAL(p.kind)
        && p.aniso.x == p.aniso.y && p.aniso.y == p.aniso.z;
}

