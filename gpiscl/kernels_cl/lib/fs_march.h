/* Function-space free flight: online conditional sampling along a ray with an adaptive
 * step whose chance of skipping a crossing is bounded. Needs fs_sampling.h (conditioning
 * rows, start conditions, memory models, random numbers, the normal at a hit).
 * Derivations, measurements and rejected options: docs/design/function-space-march.md.
 *
 * Contract of fs_free_flight:
 *  - Values. Each sample f(t_i) is drawn from its exact law given the memory rows and the
 *    ray's last FS_WINDOW (per object: FsParams.window) samples, so the law of every value
 *    is the GP's at whatever points the march chooses.
 *  - Step rule. A step from t to t + h is accepted when the expected number of crossings
 *    it could skip, Rice's up- (outside) or down-crossing (inside) rate of the conditional
 *    process integrated by the three-point Gauss-Radau rule (fixed node at t, nu(t) = 0),
 *    is at most miss_tolerance * h / l_d. Hence a ray's expected misses are at most
 *    tol * length / l_d. Steps grow by 2, 1.5 or 1.1, are capped at FS_H_MAX l_d, at the
 *    ray's end and at fs_mean_step (the prior mean must not change faster than the nodes
 *    see), and halve on rejection down to FS_H_MIN l_d. A try that fs_mean_step certifies
 *    by the prior mean alone (|mean| >= FS_MEAN_Z sd, or monotone with slope >= FS_MONO_R
 *    g, on all of it) is taken without the rule: the prior's expected crossings there are
 *    far below the tolerance (fs_mean_step). The rule's moments come from a
 *    small system (FS_RULE_MEMORY memory rows, the last FS_RULE_SAMPLES samples): only
 *    the step length, never a value's law, depends on it.
 *  - Hit. The first sample below 0 after one at or above 0 brackets the crossing; points
 *    drawn in the bracket from their exact conditionals (regula falsi moved toward the
 *    midpoint, at most bisection's count + FS_ROOT_SLACK) narrow it below FS_ROOT_WIDTH
 *    l_d and at least `refine` times; the slope along the ray is drawn from its Kac-Rice
 *    down-crossing law (negative: no normal faces away), the tangential components from
 *    their conditional law, returned with the hit for fs_normal_pdf.h.
 *  - FsParams.step_corr > 0 replaces the rule by the uniform step of fs_step (the
 *    benchmarks' baseline; scenes cannot select it).
 *  - Random numbers: the step index is fs_uniform2's segment (16 bits, hence
 *    FS_MAX_STEPS; a longer ray is counted as failed); fixed slots per draw. */
#define FS_MAX_STEPS 65535
#define FS_MEAN_HOPS 8             /* fs_mean_step */
/* Work counters (FsResult.prof, layout/records.py FS_PROFILE_COUNTERS), compiled in only
 * with FS_PROFILE (tools/profile_grid_scenes.py): off, no code and no argument at all. */
#ifdef FS_PROFILE
#define FS_PROF_ADD(k, v) (prof[FS_PROF_##k] += (v))
#define FS_PROF_PARAM , int* prof
#define FS_PROF_PASS , res.prof
#define FS_PROF_FWD , prof
#else
#define FS_PROF_ADD(k, v)
#define FS_PROF_PARAM
#define FS_PROF_PASS
#define FS_PROF_FWD
#endif
/* FS_WINDOW, FS_H_MAX, FS_H_MIN, FS_ELL_CORR and the step rule's Gauss-Radau quadrature
 * FS_RULE_NODE* / FS_RULE_WEIGHT* (the node nearer the end first, so that most rejected
 * tries stop after one, see "Step rule"): layout/constants.py */

typedef struct { double m, m1, s, r, g; } FsMoments;   /* v = s^2, c = r s, g as above */

/* Conditional moments of f and its slope along dn at ray parameter t given rows [0, n):
 * factoring rows n (value) and n + 1 (slope) is the forward solve and Schur complement.
 * A stationary prior takes both rows' covariances from one kernel jet per row (one exp,
 * gp_jet_cov: the expressions gp_cov uses) and the prior mean and its gradient from one
 * evaluation, so the factor is fs_factor's. */
inline int fs_moments(GpKernel p, __global const MeanNode* mean, int mc, FsScratch S,
                      int n, FsRay ray, double3 dn, double t, FsMoments* M)
{
    double3 x = ray.o + t * ray.d;
    S.rows[n] = fs_obs(x, dn, FS_OBS_VALUE, t);
    S.rows[n + 1] = fs_obs(x, dn, FS_OBS_DERIV, 0.0);
    int st;
    if (!S.post.n && p.sigma_field && !p.ls_field) {
        /* a sigma field alone: as the stationary branch below, one base-kernel jet per row
         * for both entries (gp_cov_sigma_jet, the expressions gp_cov_at uses), FS_LANES
         * rows' jets at a time (fs_jets) */
        GpFieldsAt fx = fs_fields(p, mean, x);
        fs_store_fields(S, n, fx);
        fs_store_fields(S, n + 1, fx);
        float3 gm;
        S.mu[n] = (double)gp_mean_eval(mean, mc, convert_float3(x), &gm);
        S.mu[n + 1] = dot(convert_double3(gm), dn);
        __global double* L0 = S.L + fs_tri(n);
        __global double* L1 = S.L + fs_tri(n + 1);
        for (int j0 = 0; j0 < n; j0 += FS_LANES) {
            GpJet J[FS_LANES];
            int lanes = min(FS_LANES, n - j0);
            if (lanes == FS_LANES) fs_jets(p, S, j0, x, J);
            else for (int l = 0; l < lanes; ++l) J[l] = gp_kernel_jet(p, x - fs_pos(S.rows + j0 + l));
            for (int l = 0; l < lanes; ++l) {
                __global const FsObs* rj = S.rows + j0 + l;
                GpFieldsAt fj = fs_row_fields(S, j0 + l);
                L0[j0 + l] = gp_cov_sigma_jet(J[l], fs_dir(rj), rj->kind, fj, dn, 0, fx);
                L1[j0 + l] = gp_cov_sigma_jet(J[l], fs_dir(rj), rj->kind, fj, dn, 1, fx);
            }
        }
        GpJet J0 = gp_kernel_jet(p, (double3)(0.0));
        L0[n] = gp_cov_sigma_jet(J0, dn, 0, fx, dn, 0, fx);
        L1[n] = gp_cov_sigma_jet(J0, dn, 0, fx, dn, 1, fx);
        L1[n + 1] = gp_cov_sigma_jet(J0, dn, 1, fx, dn, 1, fx);
        st = fs_cholesky(S.L, n, n + 2, 0);
    } else if (S.post.n || gp_kernel_nonstationary(p)) {
        /* fs_factor's fs_row_prep for both rows, sharing what the point shares: one
         * mean-program run (value and gradient) and one field evaluation, the same numbers
         * as two fs_row_prep calls (csg_baked's cubic mean and sigma grid: 2 -> 1 each) */
        GpFieldsAt fx = fs_fields(p, mean, x);
        if (gp_kernel_nonstationary(p)) {
            fs_store_fields(S, n, fx);
            fs_store_fields(S, n + 1, fx);
        }
        float3 gm;
        S.mu[n] = (double)gp_mean_eval(mean, mc, convert_float3(x), &gm);
        S.mu[n + 1] = dot(convert_double3(gm), dn);
        for (int i = n; S.post.n && i < n + 2; ++i)
            S.mu[i] += fs_post_solve(p, mean, S.post, x, dn, S.rows[i].kind, fx,
                                     fs_post_v(S, i));
        st = fs_factor_known(p, mean, S, n, n + 2);
    } else {
        float3 gm;
        S.mu[n] = (double)gp_mean_eval(mean, mc, convert_float3(x), &gm);
        S.mu[n + 1] = dot(convert_double3(gm), dn);
        __global double* L0 = S.L + fs_tri(n);
        __global double* L1 = S.L + fs_tri(n + 1);
        for (int j = 0; j < n; ++j) {
            __global const FsObs* rj = S.rows + j;
            GpJet J = gp_kernel_jet(p, x - fs_pos(rj));
            int dj = rj->kind == FS_OBS_DERIV;
            L0[j] = gp_jet_cov(J, fs_dir(rj), dj, dn, 0);
            L1[j] = gp_jet_cov(J, fs_dir(rj), dj, dn, 1);
        }
        GpJet J0 = gp_kernel_jet(p, (double3)(0.0));
        L0[n] = J0.k;
        L1[n] = gp_jet_cov(J0, dn, 0, dn, 1);
        L1[n + 1] = gp_jet_cov(J0, dn, 1, dn, 1);
        st = fs_cholesky(S.L, n, n + 2, 0);
    }
    if (st) return st;
    __global const double* L1 = S.L + fs_tri(n + 1);
    M->m = S.mu[n] + fs_row_dot(S.L, n, S.e, n);
    M->m1 = S.mu[n + 1] + fs_row_dot(S.L, n + 1, S.e, n);
    M->s = fs_diag(S.L, n);
    M->r = L1[n];
    M->g = L1[n + 1];
    return FS_STATUS_OK;
}

/* The step rule's own system (rows [FS_MAX_ROWS - FS_RULE_ROWS, FS_MAX_ROWS) of the
 * scratch slice, packed from 0): its triangle fits in the space of those rows of the
 * main one, which the main system never reaches (max_rows reserves them). */
inline FsScratch fs_rule_scratch(FsScratch S)
{
    int b = FS_MAX_ROWS - FS_RULE_ROWS;
    FsScratch R = S;
    R.rows = S.rows + b;
    R.L = S.L + fs_tri(b);
    R.e = S.e + b;
    R.mu = S.mu + b;
    R.fields = S.fields + 8 * b;
    R.v = S.v + (size_t)b * S.post.n;
    return R;
}

/* Build the rule's system: the FS_RULE_MEMORY memory rows (main rows [0, fixed)) nearest
 * to the segment x(ta) .. x(ta + reach) in the kernel's metric (within 4 length scales;
 * value rows before derivative rows at equal distance, so the row that pins f(ta) is
 * kept), then the ray's last FS_RULE_SAMPLES samples (main rows [fixed, n)); factored
 * and whitened at their values. Returns its row count; later samples are appended one
 * row each until it holds 2 FS_RULE_SAMPLES samples (rebuilt at the next step). Rows
 * come with their means, fields and posterior solves (fs_row_copy): only covariances
 * are computed. */
inline int fs_rule_build(GpKernel p, __global const MeanNode* mean, int mc, FsScratch S,
                         FsScratch R, int fixed, int n, FsRay ray, double ta, double reach,
                         double ell, int* status)
{
    double3 a = ray.o + ta * ray.d, seg = reach * ray.d;
    double seg2 = dot(seg, seg);
    double3 A = convert_double3(gp_aniso(p)), dn = ray.d / length(ray.d);
    /* the kernel's length scale in the metric A, from the along-ray lag ell (per unit t):
     * any kernel kind, the l(x) field's smallest l on the ray included */
    double l2 = ell * ell * dot(ray.d, ray.d) * dot(A * dn, dn);
    int pick[FS_RULE_MEMORY];
    double key[FS_RULE_MEMORY];
    int np = 0;
    for (int i = 0; i < fixed; ++i) {
        double3 x = fs_pos(S.rows + i);
        double u = seg2 > 0.0 ? clamp(dot(x - a, seg) / seg2, 0.0, 1.0) : 0.0;
        double3 r = x - (a + u * seg);
        double k = dot(A * r, r) / l2;
        if (!(k <= 16.0)) continue;
        k += S.rows[i].kind == FS_OBS_DERIV ? 1e-9 : 0.0;
        /* insertion into the sorted list of the nearest FS_RULE_MEMORY */
        int j = np < FS_RULE_MEMORY ? np++ : FS_RULE_MEMORY;
        while (j > 0 && key[j - 1] > k) {
            if (j < FS_RULE_MEMORY) { key[j] = key[j - 1]; pick[j] = pick[j - 1]; }
            --j;
        }
        if (j < FS_RULE_MEMORY) { key[j] = k; pick[j] = i; }
    }
    int m = 0;   /* rows come with their own numbers (fs_row_copy) */
    for (int j = 0; j < np; ++j) fs_row_copy(p, S, pick[j], R, m++);
    for (int i = max(fixed, n - FS_RULE_SAMPLES); i < n; ++i) fs_row_copy(p, S, i, R, m++);
    int st = fs_factor_known(p, mean, R, 0, m);
    if (st) { *status = st; return 0; }
    for (int i = 0; i < m; ++i) fs_whiten_row(R.L, R.e, i, R.rows[i].value, R.mu[i]);
    return m;
}

/* Append the main system's row k (a sample just drawn) to R as its row i, whitened at
 * its value: its own numbers come along (fs_row_copy), so the same numbers as
 * fs_append(R, i, S.rows[k], observed), bit for bit, without evaluating the mean, the
 * fields and the posterior solve at that point a second time. */
inline int fs_rule_append(GpKernel p, __global const MeanNode* mean, FsScratch S, int k,
                          FsScratch R, int i)
{
    fs_row_copy(p, S, k, R, i);
    int st = fs_factor_known(p, mean, R, i, i + 1);
    if (!st) fs_whiten_row(R.L, R.e, i, R.rows[i].value, R.mu[i]);
    return st;
}

inline double fs_phi(double x) { return 0.3989422804014327 * exp(-0.5 * x * x); }

/* Rice's rate (per unit length) of crossings from the side `outside` says back across 0:
 * up-crossings when outside, down-crossings inside. In float: the rate only decides a
 * step against a tolerance, where 1e-6 relative is far below what matters, and PoCL's
 * double exp and erfc made this function much of an evaluation
 * (docs/design/function-space-march.md, 'The step rule: a bound on missed crossings').
 * A deep Gaussian tail underflows to a rate of 0, which is what it is next to any
 * tolerance. */
inline float fs_phif(float x) { return 0.39894228f * exp(-0.5f * x * x); }

inline double fs_return_rate(FsMoments M, int outside)
{
    if (!(M.s > 0.0) || !(M.g > 0.0)) return 0.0;
    double m = outside ? M.m : -M.m, m1 = outside ? M.m1 : -M.m1;
    float z = (float)(m / M.s), a = (float)((m1 - M.r / M.s * m) / M.g);
    /* phi(a) + a Phi(a) cancels for a << 0: its asymptotic phi(a) / a^2 (1 - 3 / a^2) */
    float e = a < -8.0f ? fs_phif(a) / (a * a) * (1.0f - 3.0f / (a * a))
                        : fs_phif(a) + a * 0.5f * erfc(-a * 0.70710678f);
    return (double)(fs_phif(z) * e) * (M.g / M.s);
}

/* The slope at a down-crossing: s < 0 with density proportional to |s| N(s; mean, sd^2).
 * In y = -s / sd, a = mean / sd the density is y phi(y + a) on y > 0, with tail
 * S(y) = phi(y + a) - a Q(y + a); y solves S(y) = u S(0) by bisection in double (S
 * loses ~2 log10(a) digits to cancellation, a few at a <= 30). Beyond a = 30 (a slope
 * mean 30 sd on the wrong side: a grazing hit) y phi(y + a) ~ y e^{-a y}: Gamma(2, 1/a). */
inline double fs_crossing_tail(double x, double a) { return fs_phi(x) - a * fs_q(x); }

inline double fs_downcrossing_slope(double mean, double sd, double2 u)
{
    if (!(sd > 0.0)) return fmin(mean, -DBL_MIN);
    double a = mean / sd;
    if (a > 30.0) return sd * log((1.0 - u.x) * (1.0 - u.y)) / a;
    double target = (1.0 - u.x) * fs_crossing_tail(a, a);   /* (1 - u) in (0, 1] */
    /* Newton on S(y) = target (S' = -y phi(y + a), the same phi as S's) inside the
     * bisection bracket, a bisection step wherever Newton would leave it, from the
     * density's mode (1/y = y + a), which lies near the median. Ends when Newton's own
     * step is below 1e-13 (1 + y): testing the step taken instead ran on by bisection
     * for ~15 evaluations whenever the converged Newton step rounded onto a bracket end
     * (17-24 evaluations of S a draw at a in [-300, 0], now 5.3-5.6, numpy replica). */
    double lo = 0.0, hi = fmax(-a, 0.0) + 12.0, y = 0.5 * (sqrt(a * a + 4.0) - a);
    for (int k = 0; k < 100; ++k) {
        double ph = fs_phi(y + a), r = ph - a * fs_q(y + a) - target, d = y * ph;
        if (r > 0.0) lo = y; else hi = y;
        double step = d > 0.0 ? r / d : -INFINITY;
        if (fabs(step) <= 1e-13 * (1.0 + y)) { y += step; break; }
        double yn = y + step;
        if (!(yn > lo && yn < hi)) yn = 0.5 * (lo + hi);
        int done = hi - lo <= 1e-13 * (1.0 + y);
        y = yn;
        if (done) break;
    }
    return -sd * fmax(y, DBL_MIN);
}

/* An upper bound of the prior sd on [ta, tb] of the ray, for fs_mean_step's far balls:
 * sd itself without a sigma(x) field (sd is the same all along), else sigma times the
 * field's largest value there (fs_field_range; a grid field's cells only up to
 * FS_SD_BOX_SAMPLES samples, past that GpKernel.sigma_top, the largest over the proxy,
 * which the scene compiler sets: 0, unset, bounds nothing). */
inline double fs_sd_over(GpKernel p, __global const MeanNode* mean, FsRay ray, double ta,
                         double tb, double sd)
{
    if (!p.sigma_field) return sd;
    double top = p.sigma_top > 0.0f ? (double)p.sigma_top : INFINITY;
    __global const MeanNode* grid = mean + p.sigma_grid;
    double3 a = ray.o + ta * ray.d, b = ray.o + tb * ray.d;
    if (p.sigma_field == GP_FIELD_GRID && fs_grid_box_samples(grid, a, b) > FS_SD_BOX_SAMPLES)
        return top;
    return fmin(top, sqrt((double)p.sigma2)
                     * fs_field_range(p.sigma_field, p.sigma_p0, p.sigma_p1, grid, a, b).y);
}

/* The longest step the prior mean allows: the rule sees the process only at its nodes
 * and at the step's ends, so a mean that dips to 0 between them (a feature thinner than
 * the step, with sigma << l: the knob) would hide the rate's peak. With the mean's
 * Lipschitz bound `lip` (per unit t) the mean moves by at most FS_MEAN_KAPPA sd over a step
 * near its zero set, so a dip to 0 between two of them has a node or a sample within a few
 * sd of it, whose rate rejects the step or whose value is likely below 0; far from the zero
 * set the step is the sphere-tracing distance to |mean| = FS_MEAN_Z sd (a crossing there
 * needs a residual of that size: rate ~ e^{-Z^2/2} / l, far below any tolerance). m and sd
 * are the prior's at x(ta) (sigma(x) fields and a posterior included; fs_start_mean); a
 * posterior's mean correction varies on the kernel's scale, which the l_d cap covers.
 * Where the mean is one trilinear grid, lip times the length is also bounded cell by cell
 * along the ray (gp_mean_variation_reach), which reaches further on oblique rays.
 * A mean certified monotone with |slope| >= FS_MONO_R g (g: the prior slope's sd along
 * dn, > 0 only for stationary priors without a posterior; gp_mean_monotone_reach) cannot
 * dip and come back, and the crossings it could hide are negligible: the cap extends to
 * the end of that stretch (after the far one sphere tracing certified). Returns the first
 * try's length: hg (the growth ladder's), or less where the mean needs it; *certified
 * when the far and monotone stretches cover the whole try. Such a try needs no rule: every
 * certified stretch lies in a set fixed by the ray and the prior alone (|mean| >=
 * FS_MEAN_Z sd, or monotone with |slope| >= FS_MONO_R g), whose expected crossings under
 * the prior bound the chance of any miss there: ~2e-9 per l_d and psi(8) / 8 = 1e-17 per
 * monotone piece, against the rule's 2e-6 per l_d (the rule accepted every such try of
 * the example scenes with r < 0.05, so the steps, and the images, stayed the same). Why kappa is
 * 6, with the paired renders that chose it: docs/design/function-space-march.md, "The
 * mean cap"; the monotone stretch: docs/design/grid-means.md. */
inline double fs_mean_cap(GpKernel p, __global const MeanNode* mean, int mc, FsScratch S,
                          FsRay ray, double3 dn, double ta, double hg, double m, double sd,
                          double lip, int grid, double g, int* certified, double* far_out
                          FS_PROF_PARAM)
{
    *certified = 0;
    *far_out = 0.0;
    /* a try past t1 is clipped to it (then any cap >= he takes the same step as hg) */
    double he = fmin(hg, ray.t1 - ta);
    if (!(lip > 0.0)) return hg;
    /* the sd's bound over the try (sd itself without a sigma(x) field) */
    double sdh = fs_sd_over(p, mean, ray, ta, ta + he, sd);
    /* the far balls trace the prior mean, which a posterior's is not: none there */
    int balls = !S.post.n;
    double reach = fmax(FS_MEAN_KAPPA * sd, fabs(m) - FS_MEAN_Z * sdh), cap = reach / lip;
    /* the start's ball alone covers the try: certified */
    if (cap >= he) {
        *certified = balls && fabs(m) - FS_MEAN_Z * sdh >= he * lip;
        return hg;
    }
    if (grid) {
        FS_PROF_ADD(LIP_SCANS, 1);
        lip = (double)gp_mean_lipschitz_on(mean, mc, convert_float3(ray.o + ta * ray.d),
                                           convert_float3(ray.o + (ta + he) * ray.d))
              * length(ray.d);
        if (!(lip > 0.0)) {           /* a constant mean on the try */
            *certified = balls && fabs(m) > FS_MEAN_Z * sdh;
            return hg;
        }
        cap = reach / lip;
        if (cap >= he) {
            *certified = balls && fabs(m) - FS_MEAN_Z * sdh >= he * lip;
            return hg;
        }
        /* one trilinear grid: the bound of its variation along the ray itself, longer
         * than lip times the length where the ray runs along the surface; not where the
         * monotone stretch is taken (g > 0), which certifies most of those tries at less
         * cost (docs/design/grid-means.md, "The variation walk") */
        if (!(g > 0.0) && gp_mean_is_trilinear_grid(mean, mc)) {
            FS_PROF_ADD(VAR_WALKS, 1);
            double vr = (double)gp_mean_variation_reach(
                mean, convert_float3(ray.o + ta * ray.d),
                convert_float3(ray.o + (ta + he) * ray.d), (float)reach) * he;
            if (vr >= he) {
                *certified = balls && fabs(m) - FS_MEAN_Z * sdh >= FS_MEAN_KAPPA * sd;
                return hg;
            }
            cap = fmax(cap, vr);
        }
    }
    double far = 0.0;
    if (balls && fabs(m) > FS_MEAN_Z * sd) {
        /* sphere tracing on, from ball to ball: each ends where the next starts, so
         * |mean| >= FS_MEAN_Z sd (one sign) on all of [ta, ta + s]; under a sigma(x)
         * field each ball is the one the last bound would give, cut to what the sd's
         * bound over that stretch allows (fs_sd_over: the bound holds on the stretch it
         * was taken over, so the ball never reaches past it) */
        double s = 0.0, mz = fabs(m), sdk = sd;
        for (int k = 0; k < FS_MEAN_HOPS; ++k) {
            double hop = (mz - FS_MEAN_Z * sdk) / lip;
            if (p.sigma_field) {
                if (!(hop > 0.0)) break;
                double seg = fmin(hop, he - s);
                sdk = fs_sd_over(p, mean, ray, ta + s, ta + s + seg, sdk);
                hop = fmin((mz - FS_MEAN_Z * sdk) / lip, seg);
                if (!(hop > 0.0)) break;
            }
            s += hop;
            if (s >= he) { *certified = 1; return hg; }
            /* converging onto the near zone, or out of hops */
            if (hop < 0.25 * FS_MEAN_KAPPA * sdk / lip || k + 1 == FS_MEAN_HOPS) break;
            double mk = fs_prior_mean(mean, mc, ray.o + (ta + s) * ray.d, dn, FS_OBS_VALUE);
            FS_PROF_ADD(HOPS, 1);
            if (!(mk * m > 0.0) || !(fabs(mk) > FS_MEAN_Z * sdk)) break;
            mz = fabs(mk);
        }
        far = s;
        *far_out = s;
        *certified = s >= cap;
        cap = fmax(cap, s);
    }
    if (g > 0.0) {
        /* the monotone stretch after the far one: a dip to 0 and back fits in neither */
        double ma = m;
        if (far > 0.0) {
            ma = fs_prior_mean(mean, mc, ray.o + (ta + far) * ray.d, dn, FS_OBS_VALUE);
            FS_PROF_ADD(HOPS, 1);
        }
        FS_PROF_ADD(MONO_SCANS, 1);
        double mono = (double)gp_mean_monotone_reach(
            mean, convert_float3(ray.o + (ta + far) * ray.d),
            convert_float3(ray.o + (ta + he) * ray.d), convert_float3(dn),
            (float)(FS_MONO_R * g), (float)ma, (float)(FS_MEAN_Z * sd));
        if (mono >= 1.0) {
            FS_PROF_ADD(MONO_STEPS, 1);
            *certified = 1;
            return hg;
        }
        double end = far + mono * (he - far);
        FS_PROF_ADD(MONO_STEPS, end > cap);
        *certified = end >= cap && end > 0.0;
        cap = fmax(cap, end);
        *far_out = fmax(far, end);     /* certified too: fs_mean_step's kinks start past it */
    }
    return cap;
}

/* The longest try a sigma(x) field allows: a crossing of f = mu + sigma e is one of the
 * unit process e across -mu / sigma, a threshold the rule sees only at its nodes. Over a
 * try sigma may rise to twice and fall to half its value at x(ta): a rise moves the
 * threshold toward 0 by at most half of |mu| / sigma, which is within FS_MEAN_KAPPA of
 * where it was (|mu| / sd <= 2 kappa) or leaves it past FS_MEAN_Z (the far zone); a fall
 * moves it away from 0, and the floor keeps the mean cap's FS_MEAN_KAPPA sd (taken at
 * x(ta)) within 2 kappa of the sd at the try's end. The budgets are spent at the field's
 * largest rates of fall and rise on the try, never faster, so sigma moves no more than
 * linearly at those rates: fs_field_slope's bounds (a grid's over at most
 * FS_SD_BOX_SAMPLES samples of the try's index box, the try halved until it fits), or for
 * a grid the largest rates over the cells the try crosses (fs_grid_field_reach). A cap
 * that let a grid's whole rise fall in the try's last cell missed 5% of test13's hits
 * (docs/design/grid-means.md, "Sigma fields along the ray"). Without any cap a rise of
 * sigma thinner than the step hid its crossings from the rule's nodes
 * (docs/design/grid-means.md, "Sigma fields"). Never
 * below FS_H_MIN l_d, the rule's own floor; INFINITY without a sigma field. */
inline double fs_field_cap(GpKernel p, __global const MeanNode* mean, FsScratch S,
                           FsRay ray, double ta, double he, double sd, double ell)
{
    if (!p.sigma_field || !(he > 0.0)) return INFINITY;
    __global const MeanNode* grid = mean + p.sigma_grid;
    double3 a = ray.o + ta * ray.d;
    /* sigma's multiplier at x(ta): the prior sd over sigma, or evaluated (a posterior) */
    double ms = S.post.n ? fs_fields(p, mean, a).ms : sd / sqrt((double)p.sigma2);
    if (p.sigma_field == GP_FIELD_GRID) {       /* along the ray's cells */
        float f = fs_grid_field_reach(grid, convert_float3(a),
                                      convert_float3(ray.o + (ta + he) * ray.d),
                                      (float)fabs(ms), (float)(0.5 * fabs(ms)));
        if (f >= 1.0f) return INFINITY;
        if (f >= 0.0f) return fmax((double)f * he, FS_H_MIN * ell);
    }
    double seg = 2.0 * he;
    double2 rate = (double2)(INFINITY);       /* (fall, rise) per unit t */
    for (int k = 0; k < 16 && isinf(rate.x); ++k) {
        seg *= 0.5;
        rate = fs_field_slope(p.sigma_field, p.sigma_p0, p.sigma_p1, grid, a,
                              ray.o + (ta + seg) * ray.d) / seg;
    }
    if (isinf(rate.x)) return FS_H_MIN * ell;
    double cap = fmin(rate.x > 0.0 ? 0.5 * fabs(ms) / rate.x : INFINITY,
                      rate.y > 0.0 ? fabs(ms) / rate.y : INFINITY);
    if (cap > seg && seg < he) cap = seg;      /* the bound holds on [ta, ta + seg] only */
    return fmax(cap, FS_H_MIN * ell);
}

/* fs_mean_cap's try, shortened by fs_field_cap where the far balls do not carry it */
inline double fs_mean_step(GpKernel p, __global const MeanNode* mean, int mc, FsScratch S,
                           FsRay ray, double3 dn, double ta, double hg, double m, double sd,
                           double lip, int grid, double g, double ell, int* certified
                           FS_PROF_PARAM)
{
    double far;
    double h = fs_mean_cap(p, mean, mc, S, ray, dn, ta, hg, m, sd, lip, grid, g, certified,
                           &far FS_PROF_FWD);
    if (*certified) return h;
    /* a trilinear mean's kinks: a try past the certified stretch (far balls, monotone
     * stretch: no dip fits there) ends at a face where the mean's slope jumps by
     * FS_MEAN_KINK sd over the try (gp_mean_kink_reach) */
    double e = fmin(h, ray.t1 - ta);
    if (grid && e > far && gp_mean_is_trilinear_grid(mean, mc)) {
        float k = gp_mean_kink_reach(mean, convert_float3(ray.o + (ta + far) * ray.d),
                                     convert_float3(ray.o + (ta + e) * ray.d),
                                     (float)(FS_MEAN_KINK * sd));
        if (k < 1.0f) h = fmax(far + (double)k * (e - far), FS_H_MIN * ell);
    }
    if (!p.sigma_field) return h;
    double fcap = fs_field_cap(p, mean, S, ray, ta, fmin(h, ray.t1 - ta), sd, ell);
    FS_PROF_ADD(CAP_FIELD, fcap < fmin(h, ray.t1 - ta) && fcap > far);
    return fmax(far, fmin(h, fcap));
}

/* The prior mean and sd at x(ta) for fs_mean_step. A value row of S at exactly that point
 * (the last sample; at the first step a fresh start's row or a vertex's value row) has
 * its own numbers (fs_row_prep), so neither the mean program nor the O(observations^2)
 * solve runs again: the same numbers as fs_mean_var's, bit for bit (the same operations
 * on the same point); else fs_mean_var (slot n as its work space). sd_flat >= 0: the
 * prior sd of a stationary kernel without a posterior, the same at every point (the
 * kernel at lag 0), taken once a flight instead of once a step. */
inline double fs_start_mean(GpKernel p, __global const MeanNode* mean, int mc, FsScratch S,
                            int fixed, int n, double3 x, double3 dn, double sd_flat,
                            double* sd FS_PROF_PARAM)
{
    int k = n - 1;
    if (n == fixed) {
        for (k = fixed - 1; k >= 0; --k) {
            __global const FsObs* o = S.rows + k;
            if (o->kind == FS_OBS_VALUE && o->px == x.x && o->py == x.y && o->pz == x.z) break;
        }
    }
    if (k < 0) {
        FS_PROF_ADD(MEAN_EVALS, 1);
        double var, m = fs_mean_var(p, mean, mc, S, x, dn, FS_OBS_VALUE, n, &var);
        *sd = sqrt(var);
        return m;
    }
    if (sd_flat >= 0.0) {
        *sd = sd_flat;
        return S.mu[k];
    }
    GpFieldsAt fx = gp_kernel_nonstationary(p) ? fs_row_fields(S, k) : fs_fields(p, mean, x);
    double var = gp_cov_at(p, x, dn, FS_OBS_VALUE, fx, x, dn, FS_OBS_VALUE, fx);
    if (S.post.n) var -= fs_post_dot(fs_post_v(S, k), fs_post_v(S, k), S.post.n);
    *sd = sqrt(fmax(var, 0.0));
    return S.mu[k];
}

/* Drop the older half of the window: rows [n - keep, n) move to [fixed, fixed + keep)
 * with their own numbers (fs_row_copy) and are refactored and whitened (their values are
 * known); returns the new row count. */
inline int fs_slide(GpKernel p, __global const MeanNode* mean, int mc, FsScratch S,
                    int fixed, int n, int keep, int* status)
{
    /* ascending: a row's source n - keep + i is never below its target fixed + i */
    for (int i = 0; i < keep; ++i) fs_row_copy(p, S, n - keep + i, S, fixed + i);
    int st = fs_factor_known(p, mean, S, fixed, fixed + keep);
    if (st) { *status = st; return n; }
    for (int i = fixed; i < fixed + keep; ++i)
        fs_whiten_row(S.L, S.e, i, S.rows[i].value, S.mu[i]);
    return fixed + keep;
}

/* The root search's next point in the bracket (ta, tb) (f(ta) = fa >= 0 > fb = f(tb)),
 * a function of values already drawn only (see "Hit"): the regula falsi point moved
 * FS_ROOT_OFFSET root widths toward the bracket's midpoint (so that the end the secant
 * approaches from is overshot and both ends close in), projected onto the interval
 * about the midpoint that keeps the bracket within bisection's worst case plus
 * FS_ROOT_SLACK points (ITP, Oliveira and Takahashi 2020): point k of kmax =
 * fs_root_budget(w0, width) leaves a bracket of at most width 2^(kmax - k - 1). */
inline int fs_root_budget(double w0, double width)
{
    return max((int)ceil(log2(w0 / width)), 0) + FS_ROOT_SLACK;
}

inline double fs_root_point(double ta, double tb, double fa, double fb, double width, int k,
                            int kmax)
{
    double w = tb - ta, mid = ta + 0.5 * w;
    double xf = ta + w * (fa / (fa - fb));
    double x = xf + copysign(fmin(FS_ROOT_OFFSET * width, fabs(mid - xf)), mid - xf);
    /* the radius of the projection; 1 - 1e-12: rounding must not leave the last bracket
     * an ulp above width */
    double r = fmax(0.5 * width * (1.0 - 1e-12) * ldexp(1.0, kmax - k) - 0.5 * w, 0.0);
    return fabs(x - mid) <= r ? x : mid + copysign(r, x - mid);
}

/* Free flight along [ray.t0, ray.t1] inside one GPIS object: the first crossing, or none.
 * Shadow rays and continuation rays alike; only the continuation then calls
 * fs_vertex_at_hit. ray.d need not be unit (t is the ray parameter). */
inline FsResult fs_free_flight(GpKernel p, __global const MeanNode* mean, int mc,
                               FsParams prm, FsRay ray, FsVertex v,
                               __global const FsObs* ring, FsRng rng, FsScratch S)
{
    FsResult res = {0};
#ifdef FS_PROFILE
    int* prof = res.prof;
#endif
    res.t = ray.t1;
    if (S.post.n > FS_POST_MAX) { res.status = FS_STATUS_ROWS; return res; }   /* no v cache */
    double fa;
    int outside, n_old;
    int fixed = fs_begin(p, mean, mc, prm, ray, v, ring, rng, S, &fa, &outside, &n_old);
    int window = clamp(prm.window > 0 ? prm.window : FS_WINDOW, 2, FS_MAX_WINDOW);
    double dlen = length(ray.d), ell = fs_step(p, ray, FS_ELL_CORR);
    double dt = prm.step_corr > 0.0 ? fs_step(p, ray, prm.step_corr) : 0.0;
    double3 dn = ray.d / dlen;
    if (!(ell > 0.0) || !isfinite(ell) || !isfinite(dt)) { res.status = FS_STATUS_NAN; return res; }
    if (fixed + window + max(prm.refine, FS_MIN_BISECT) + FS_HIT_ROWS + FS_RULE_ROWS
        > FS_MAX_ROWS) {
        res.status = FS_STATUS_ROWS;
        return res;
    }
    int st = fs_factor(p, mean, mc, S, 0, fixed);
    if (st) { res.status = st; return res; }
    for (int i = 0; i < fixed; ++i) fs_whiten_row(S.L, S.e, i, S.rows[i].value, S.mu[i]);
    int n = fixed;
    double ta = ray.t0, tb = 0.0, fb = 0.0;
    double h = dt > 0.0 ? (1.0 - fs_uniform2(rng, 0, FS_U_GRID).x) * dt : 0.5 * ell;
    double tol = (double)prm.miss_tol, grow = 1.0;
    /* the prior mean's slope bound along the ray, per unit t (fs_mean_step) */
    double lip = dt > 0.0 ? 0.0
        : (double)gp_mean_lipschitz_on(mean, mc, convert_float3(ray.o + ray.t0 * ray.d),
                                       convert_float3(ray.o + ray.t1 * ray.d)) * dlen;
    int grid = lip > 0.0 && gp_mean_has_grid(mean, mc);
    /* the prior slope's sd along dn where sd is constant on the ray (fs_mean_step's
     * monotone stretch); 0: no certificate */
    double3 o3 = (double3)(0.0);
    double gslope = grid && !S.post.n && !gp_kernel_nonstationary(p)
                    && gp_mean_is_trilinear_grid(mean, mc)
        ? sqrt(gp_cov(p, o3, dn, 1, o3, dn, 1)) : 0.0;
    FS_PROF_ADD(LIP_SCANS, dt > 0.0 ? 0 : 1);
    /* the prior sd where it is the same everywhere (fs_start_mean), else -1 */
    double sd_flat = -1.0;
    if (lip > 0.0 && !S.post.n && !gp_kernel_nonstationary(p)) {
        double3 x0 = ray.o + ray.t0 * ray.d;
        GpFieldsAt f0 = fs_fields(p, mean, x0);
        sd_flat = sqrt(fmax(gp_cov_at(p, x0, dn, FS_OBS_VALUE, f0, x0, dn, FS_OBS_VALUE, f0),
                            0.0));
    }
    FsScratch R = fs_rule_scratch(S);
    int nr = 0, r_new = FS_RULE_SAMPLES + 1;   /* rows of R; samples since it was built */
    int step = 0;
    for (;; ++step) {
        if (ta >= ray.t1) return res;
        if (step >= FS_MAX_STEPS) { res.status = FS_STATUS_STEPS; return res; }
        if (n - fixed >= window) {
            n = fs_slide(p, mean, mc, S, fixed, n, window / 2, &res.status);
            if (res.status) return res;
        }
        if (dt > 0.0) {                        /* uniform baseline: one row per step */
            tb = fmin(ta + h, ray.t1);
            h = dt;
        } else {
            /* the rule on its small system R (see "Step rule"): 1-2 nodes per try */
            /* the mean's cap; its numbers at ta are a row's (fs_start_mean) */
            double sd0 = 0.0, m0 = lip > 0.0
                ? fs_start_mean(p, mean, mc, S, fixed, n, ray.o + ta * ray.d, dn, sd_flat,
                                &sd0 FS_PROF_PASS) : 0.0;
            double hg = fmin(grow * h, FS_H_MAX * ell);
            int certified;
            h = fs_mean_step(p, mean, mc, S, ray, dn, ta, hg, m0, sd0, lip, grid, gslope,
                             ell, &certified FS_PROF_PASS);
#ifdef FS_PROFILE
            /* what set the first try: the ray's end, the mean cap, FS_H_MAX, the growth */
            if (ta + fmin(h, hg) >= ray.t1) res.prof[FS_PROF_CAP_END]++;
            else if (h < hg) res.prof[FS_PROF_CAP_MEAN]++;
            else if (hg == FS_H_MAX * ell) res.prof[FS_PROF_CAP_HMAX]++;
            else res.prof[FS_PROF_CAP_GROW]++;
            res.prof[FS_PROF_NEAR_STEPS] += lip > 0.0
                && fabs(m0) < (FS_MEAN_Z + FS_MEAN_KAPPA) * sd0;
#endif
            if (certified) {
                /* the prior mean alone bounds the try's crossings (fs_mean_step): no rule */
                tb = ta + h >= ray.t1 ? ray.t1 : ta + h;
                grow = 2.0;
                r_new = FS_RULE_SAMPLES + 1;     /* R is not kept up: rebuilt when needed */
                FS_PROF_ADD(STEPS, 1);
                FS_PROF_ADD(CERT_STEPS, 1);
            } else if (r_new > FS_RULE_SAMPLES) {
                nr = fs_rule_build(p, mean, mc, S, R, fixed, n, ray, ta,
                                   FS_H_MAX * ell, ell, &st);
                r_new = 0;
            }
            for (; !st && !certified;) {
                int clipped = ta + h >= ray.t1;
                double hs = clipped ? ray.t1 - ta : h;
                /* Gauss-Radau with nu(ta) = 0: the mean rate over the step (per length)
                 * times l_d (per t), relative to the tolerance; the try stops at the
                 * first node that takes the sum past 1 */
                double r = 0.0;
                FS_PROF_ADD(TRIES, 1);
                for (int q = 0; q < 2 && r <= 1.0; ++q) {
                    FsMoments M;
                    st = fs_moments(p, mean, mc, R, nr, ray, dn,
                                    ta + (q ? FS_RULE_NODE1 : FS_RULE_NODE0) * hs, &M);
                    if (st) break;
                    res.evals++;
                    FS_PROF_ADD(MEAN_EVALS, 1);
                    r += (q ? FS_RULE_WEIGHT1 : FS_RULE_WEIGHT0) * fs_return_rate(M, outside)
                         * dlen * ell / tol;
                }
                if (st) break;
                if (r <= 1.0 || h <= FS_H_MIN * ell) {
                    tb = clipped ? ray.t1 : ta + hs;
                    /* the next step's first try: grow where the bound is slack */
                    grow = r < 0.05 ? 2.0 : (r < 0.3 ? 1.5 : 1.1);
                    FS_PROF_ADD(STEPS, 1);
                    break;
                }
                h = 0.5 * hs;
            }
        }
        if (!st) {
            S.rows[n] = fs_obs(ray.o + tb * ray.d, dn, FS_OBS_VALUE, tb);
            st = fs_factor(p, mean, mc, S, n, n + 1);
        }
        if (st) { res.status = st; return res; }
        fb = fs_sample_row(S.L, S.e, n, S.mu[n], fs_normal(rng, step, 0));
        S.rows[n].value = fb;
        res.samples++;
        FS_PROF_ADD(MEAN_EVALS, 1);
        if (isnan(fb)) { res.status = FS_STATUS_NAN; return res; }
        ++n;
        if (outside && fb < 0.0) break;
        if (dt <= 0.0 && r_new < FS_RULE_SAMPLES) {   /* else rebuilt at the next step */
            st = fs_rule_append(p, mean, S, n - 1, R, nr++);
            if (st) { res.status = st; return res; }
        }
        r_new++;
        outside = fb >= 0.0;
        ta = tb;
        fa = fb;
    }

    /* a crossing in (ta, tb]: the root search (see "Hit"), every point drawn conditioned
     * on everything, until the bracket is below FS_ROOT_WIDTH l_d (and at least `refine`
     * points) */
    double width = FS_ROOT_WIDTH * ell;
    int kmax = fs_root_budget(tb - ta, width);
    for (int k = 0; (k < prm.refine || tb - ta > width)
                    && n + FS_HIT_ROWS + 2 <= FS_MAX_ROWS; ++k, ++n) {
        double tm = fs_root_point(ta, tb, fa, fb, width, k, kmax);
        double f = fs_append(p, mean, mc, S, n, fs_obs(ray.o + tm * ray.d, dn, FS_OBS_VALUE, 0.0),
                             0, fs_normal(rng, step, FS_SLOT_REFINE + k), &res.status);
        if (res.status) return res;
        res.samples++;
        res.roots++;
        if (f >= 0.0) { ta = tm; fa = f; } else { tb = tm; fb = f; }
    }
    res.hit = 1;
    res.t = ta + (tb - ta) * fa / (fa - fb);
    double3 x = ray.o + res.t * ray.d, T, B;
    /* the slope's law given the rows and f(x_h) = 0, at a down-crossing */
    fs_append(p, mean, mc, S, n, fs_obs(x, dn, FS_OBS_VALUE, 0.0), 1, 0.0, &res.status);
    if (res.status) return res;
    S.rows[n + 1] = fs_obs(x, dn, FS_OBS_DERIV, 0.0);
    st = fs_factor(p, mean, mc, S, n + 1, n + 2);
    if (st) { res.status = st; return res; }
    double sd = fs_downcrossing_slope(S.mu[n + 1] + fs_row_dot(S.L, n + 1, S.e, n + 1),
                                      fs_diag(S.L, n + 1), fs_uniform2(rng, step, FS_U_SLOPE));
    fs_whiten_row(S.L, S.e, n + 1, sd, S.mu[n + 1]);
    S.rows[n + 1].value = sd;
    fs_frame(dn, &T, &B);
    double z1 = fs_normal(rng, step, FS_SLOT_NORMAL), z2 = fs_normal(rng, step, FS_SLOT_NORMAL + 1);
    /* (q1, q2) = m + L z with the 2x2 lower factor L = [[l11, 0], [l21, l22]] of their
     * covariance given s: res.law_* keeps (m, L) for the normal's density */
    double q1, q2, m1, m2, l11, l21, l22;
    if (fs_isotropic_radial(p) && !S.post.n && fs_memory_markov_ok(prm)) {
        /* every row on the ray: d_T f(x_h) is independent of them (fs_sampling.h) */
        m1 = fs_prior_mean(mean, mc, x, T, FS_OBS_DERIV);
        m2 = fs_prior_mean(mean, mc, x, B, FS_OBS_DERIV);
        l11 = sqrt(gp_cov(p, x, T, 1, x, T, 1));
        l21 = 0.0;
        l22 = sqrt(gp_cov(p, x, B, 1, x, B, 1));
        q1 = m1 + l11 * z1;
        q2 = m2 + l22 * z2;
    } else {
        /* the general conditional (anisotropic, fields, posterior, global memory): two
         * appended rows, each given everything before it; their conditional mean given
         * the rows up to s and the trailing 2x2 block of the factor are its (m, L) */
        q1 = fs_append(p, mean, mc, S, n + 2, fs_obs(x, T, FS_OBS_DERIV, 0.0), 0, z1, &res.status);
        q2 = fs_append(p, mean, mc, S, n + 3, fs_obs(x, B, FS_OBS_DERIV, 0.0), 0, z2, &res.status);
        if (res.status) return res;
        m1 = S.mu[n + 2] + fs_row_dot(S.L, n + 2, S.e, n + 2);
        m2 = S.mu[n + 3] + fs_row_dot(S.L, n + 3, S.e, n + 2);
        l11 = fs_diag(S.L, n + 2);
        l21 = S.L[fs_tri(n + 3) + n + 2];
        l22 = fs_diag(S.L, n + 3);
    }
    /* s < 0 always; |s| below 1e-5 of the tangential part (probability ~1e-10: the law's
     * density vanishes like |s| at 0) is raised to it so that the normal still faces the
     * ray after rounding to float (the scatter stage kills a normal that does not) */
    res.law_s = fmin(sd, -1e-5 * sqrt(q1 * q1 + q2 * q2));
    res.grad = T * q1 + B * q2 + dn * res.law_s;
    res.law_m = T * m1 + B * m2;
    res.law_a = T / l11;
    res.law_b = (B - (l21 / l11) * T) / l22;
    /* global: the ring takes this ray's rows, f(x_h) = 0 included: x_h is a draw of the
     * root's location, so f(x_h) = 0 is an observation of the realization (the old
     * interpolated root contradicted the bracket values by O(width^2 f'')), and the next
     * ray's step rule needs f known at its start (the rule's nu(t) = 0) */
    res.new_first = n_old;
    res.new_end = n + 4;
    return res;
}
