/* Function-space free flight: online conditional sampling along a ray with an adaptive
 * step whose chance of skipping a crossing is bounded. Needs fs_sampling.h (the
 * conditioning rows, start conditions, memory models, random numbers and the normal at a
 * hit are defined there); gpiscl/host/gp/function_space.py is its numpy reference.
 *
 * Online sampling. Each new value f(t_{i+1}) is drawn from its law given the memory rows
 * (fs_begin: the vertex record or the start value) and the ray's previous samples: one
 * row is appended to the packed factor (fs_factor on one row: k(X, x), a forward solve,
 * the Schur complement, O(n^2)), then fs_sample_row. A window keeps the last FS_WINDOW
 * samples besides the memory rows: when it is full the older half is dropped and the
 * newer half refactored once (amortised O(n^2) per step, n = memory + window). Why 16
 * (so at least 8 kept): the next value's conditional variance given the last 8 samples
 * against 40 (numpy, tools/bench_adaptive_marching.py's docstring has the table): SE at
 * spacing 0.8 l (typical steps) +0.7%, at 1.2 l +3e-6; at 0.5 l +63% but of a variance
 * that is 0.7% of sigma^2 (given 16: +7%); RQ alpha = 1: +2% at 0.3 l, +4e-4 at 0.5 l.
 * Rice's crossing rate with it (tests/test_fs_adaptive.py --long): SE within 0.4% at
 * mu/sigma = 0, 1. The rational quadratic (correlation ~ 1/t^2) counted +0.45 +- 0.15%
 * at mu = sigma with 16, where the adaptive step packs samples near the level and 16
 * span too little ray; it takes 32 (compile/gpis.py sampler_window has the numbers):
 * FsParams.window per object, FS_WINDOW the default. All memory models condition
 * on the window inside a ray; they differ only at a vertex (fs_begin). Segments, their N
 * and the 256 cap are gone.
 *
 * Step rule. Given f(t) >= 0 (the ray is outside), a step to t + h misses a crossing
 * only if the path crosses down and back up inside it, so it needs an up-crossing:
 *   P(miss) <= E[# up-crossings in (t, t + h)] = int_t^{t+h} nu+(s) ds,
 * the expected number by Rice's formula for the non-stationary Gaussian process f given
 * the rows so far. With the conditional moments at s, m = E f, m1 = E f', v = Var f,
 * c = Cov(f, f'), w = Var f' (derivatives per unit length along the ray):
 *   nu+(s) = phi(m / sqrt v) / sqrt v * [g phi(b / g) + b Phi(b / g)],
 *   b = m1 - (c / v) m   (the slope's mean given f(s) = 0),
 *   g^2 = w - c^2 / v    (its variance given f(s) = 0).
 * Inside (after an up-crossing has been seen, or a ray starting inside) the missed event
 * is up-then-down, bounded by the down-crossings: the same with m, m1 -> -m, -m1. The
 * integral is the three-point Gauss-Radau rule with its fixed node at t, where nu(t) = 0
 * because f(t) is a row: h [w0 nu(t + u0 h) + w1 nu(t + u1 h)], u = (6 -+ sqrt 6) / 10,
 * exact for degree 4; the node nearer the end is evaluated first and a try stops as soon
 * as the sum exceeds the bound (2.8-2.9 evaluations a step in the numpy twin). Why two
 * nodes: nu is largest where f is least pinned, toward the step's end, and climbs there
 * steeply when the conditional mean heads for 0; the one-node Radau rule used before,
 * (3h/4) nu(t + 2h/3) (exact for quadratics, ~1.7 evaluations a step), underestimated
 * exactly those steps: on dense realizations at the default tolerance it skipped 2.3e-4
 * crossings per l at mu = 0 (100x the tolerance; 0.13% of the crossings) and 0.84% of
 * them at mu = 2.5 sigma, each inside a step whose end value landed near 0 with the dip
 * in the last third, and the device's Rice count was low by 0.17 +- 0.05% and 1.3 +-
 * 0.4% (the crossing-rate tests' tolerances could not see it). This rule skipped 1 of
 * 10356 at mu = 0 and none of 906 at 2.5 sigma; Simpson's (h/6)(4 nu(h/2) + nu(h)) 4 of
 * 10356, three-point Gauss-Legendre none at 5.6 evaluations a step (numpy twin,
 * tests/test_fs_adaptive.py). A step is
 * accepted when the bound is at most tol h / l_d, i.e. the mean miss rate over the step
 * is at most `miss_tolerance` expected misses per along-ray length scale l_d (SE: l /
 * sqrt(d'Ad); others: the lag of correlation e^-1/2, fs_step with an l(x) field's
 * smallest l on the ray). The first try grows the last step by 2, 1.5 or 1.1 as its
 * bound was below 5%, 30% or 100% of the tolerance (capped at FS_H_MAX l_d and at the
 * ray's end, and at fs_mean_step: the prior mean must not change faster than the node
 * can see; on the knob every step was that cap's, fs_mean_step has the numbers); a
 * rejected try halves (floor FS_H_MIN l_d). fs_markov.h's step predictor (each try aimed at
 * ratio 2^-3 from the first node's z, a and gam) was tried here in the numpy twin (SE,
 * dense paths, mu / sigma = 0, 1, 2, the default tolerance): 2.35-2.45 evaluations a step
 * instead of 2.83-2.87, but 7-13% more steps (it aims below the bound), so evaluations per
 * length fell only 7-10% and steps + evaluations / 2 per length stayed within 1%; targets
 * 2^-1..2^-5 the same; not ported. So a ray's expected misses are
 * at most tol * (its length / l_d), and the crossing rate's relative bias at most
 * tol / (l_d * Rice's rate) = 2 pi tol e^(mu^2 / 2 sigma^2) for SE: the default 2e-6
 * gives <= 0.11% for mu / sigma <= 3 (1e-5, the earlier default, allowed 0.57% there).
 * The bound is small where the mean heads down (a likely crossing is bracketed anyway)
 * and large where f hovers near 0 with an uncertain slope (grazing pairs), which is
 * exactly the event to control.
 * The rule's own system. The moments come from a small system R (fs_rule_build): the
 * FS_RULE_MEMORY memory rows nearest the ray ahead and the ray's last FS_RULE_SAMPLES
 * samples, each later sample appended as one row until R holds 2 FS_RULE_SAMPLES of them
 * (then rebuilt). The value at the accepted end is drawn from the full system (memory +
 * window), so only the step length, never the law of a value, depends on R. Why 4: in
 * the numpy twin (SE, dense realizations, tol 1e-5 and 1e-3, mu / sigma = 0, 1, 2) the
 * steps per length given the last 4 samples are within 1-7% of those given 16, with
 * the same misses (none), while an evaluation costs O(|R|^2) instead of O((memory +
 * window)^2). Cost per step: one row of the full system (the value) and ~2.9 evaluations
 * of R (each a (value, slope) pair: one kernel jet per row of R); steps are ~0.6-0.9 l_d,
 * against 0.46 l_d (c = 0.9) and 0.14 l_d (c = 0.99) for the uniform grid. A row's
 * prior mean, field multipliers and posterior solve are computed once, when it is
 * drawn (fs_row_prep), and travel with it into R, into the slid window and into the
 * next step's mean cap (fs_row_copy, fs_start_mean): before, each sample's mean
 * program and posterior solve ran up to four times (its row, R's append, R's rebuild,
 * the cap at the next step's start) and each slid row's once more.
 * A posteriori bridge check (the second half): not done. A one-node bridge
 * bound (the midpoint given both ends, ends' rates 0) missed 8e-3 crossings per l at
 * tol 1e-3 in the numpy twin (the dip sits near an end where the midpoint cannot see
 * it), so it would need 2-3 nodes per step on top of the up-front rule's.
 * FsParams.step_corr > 0 replaces the rule by the fixed step of fs_step (correlation c
 * between neighbours, first step u dt, u uniform in (0, 1]): the old uniform grid, kept
 * as the benchmarks' baseline only (scenes cannot select it).
 *
 * Hit. The first sample f < 0 after f >= 0 brackets the crossing. The root search draws
 * points in the bracket, each conditioned on everything, until the bracket is below
 * FS_ROOT_WIDTH = 1e-2 l_d (and at least `refine` of them), so the linear root is off by
 * ~1e-5 sigma, the jitter's size, and every `refine` gives the same laws (refine only
 * adds points). Each point is chosen from values already drawn (fs_root_point: the
 * bracket's regula falsi point, moved FS_ROOT_OFFSET = 0.45 root widths toward the
 * midpoint, projected as ITP does so that no bracket needs more than bisection's count
 * plus FS_ROOT_SLACK = 2), and the value there is drawn from its exact conditional, so
 * the law of the values is the GP's at whatever points are chosen: the choice changes
 * the cost, not the law. Points per hit from a 0.45 l_d bracket (numpy twin, SE,
 * conditional draws): bisection 6.0, this 2.8 / 3.0 / 3.3 at mu / sigma = 0 / 1 / 2
 * (regula falsi without the offset stalls at one end; offset 0.25 / 0.6 widths, inverse
 * quadratic interpolation or ITP's own w^2 offset took 0.0-0.5 more). On the device
 * (tools/bench_free_flight.py, fresh rays, SE): 2.9 / 3.1 / 3.3 / 3.6 per hit at mu /
 * sigma = 0 / 1 / 2 / 3 after adaptive steps, 2.2 after the 0.14 l_d steps of the
 * uniform 0.99 grid, where bisection took 6 (the old default refine) or 5.5 (refine 0).
 * The slope along the ray at x_h is drawn from its exact law at a
 * down-crossing given all rows and f(x_h) = 0: s < 0 with density |s| N(s; b, g^2)
 * (Kac-Rice: crossings are met in proportion to |f'|), by inverting its CDF
 * (fs_downcrossing_slope). Negative by construction, so no normal faces away under any
 * memory model. Why the narrow bracket: at a wide one (refine 0-2 alone) the linear root
 * is off by O(width^2 f''), and conditioning the slope on f = 0 there biased it (E[-s]
 * +8-25% at refine 2, measured); sampling the root's location from the conditional
 * crossing density on a fixed grid of cells did worse where the density peaks at a
 * bracket end (f(ta) ~ 0). The old secant slope's jitter noise (tilted normals at
 * refine >= 12) is gone too: s is drawn from the jittered model's own conditional.
 * The tangential components follow given f(x_h) = 0 and s (fs_sampling.h's closed form
 * for isotropic kernels without a posterior or global memory, else two appended rows);
 * their law given s (mean and 2x2 factor, the appended rows' before they are drawn) is
 * returned with the hit (FsResult.law_*): the normal's density, fs_normal_pdf.h.
 * The global ring keeps this ray's rows: values, bisection points, f(x_h) = 0, s and the
 * tangential components.
 *
 * Random numbers: the step index takes fs_uniform2's segment field (16 bits, hence
 * FS_MAX_STEPS; a ray needing more is counted as failed): block 0 the value at the
 * step, the bisection and normal slots of fs_sampling.h at the hit's step, FS_U_SLOPE
 * its slope. */
#ifndef FS_WINDOW
#define FS_WINDOW 16
#endif
#define FS_MAX_STEPS 65535
#ifndef FS_H_MAX
#define FS_H_MAX 2.0               /* l_d */
#endif
#ifndef FS_MEAN_KAPPA
#define FS_MEAN_KAPPA 6.0          /* fs_mean_step */
#endif
#define FS_MEAN_Z 6.0
#define FS_MEAN_HOPS 8             /* fs_mean_step */
/* the three-point Gauss-Radau rule on [0, 1] with its fixed node at 0 (where nu = 0, so
 * its weight 1/9 drops out) and free nodes (6 -+ sqrt 6) / 10: exact for degree 4, two
 * evaluations per accepted try; the node nearer the end first, so that most rejected
 * tries stop after one (see "Step rule") */
#define FS_RULE_NODE0 0.8449489742783178   /* (6 + sqrt 6) / 10 */
#define FS_RULE_WEIGHT0 0.37640306270046727  /* (16 - sqrt 6) / 36 */
#define FS_RULE_NODE1 0.3550510257216822   /* (6 - sqrt 6) / 10 */
#define FS_RULE_WEIGHT1 0.5124858261884216   /* (16 + sqrt 6) / 36 */
#define FS_H_MIN 1e-3              /* l_d: a floor for degenerate starts (f = 0 exactly) */
#define FS_ELL_CORR 0.6065306597126334   /* e^-1/2: SE's lag is exactly l / sqrt(d'Ad) */
#define FS_U_SLOPE 1100

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
    if (S.post.n || gp_kernel_nonstationary(p)) {
        st = fs_factor(p, mean, mc, S, n, n + 2);
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
 * double exp and erfc made this function 40% of an evaluation (measured). A deep
 * Gaussian tail underflows to a rate of 0, which is what it is next to any tolerance. */
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

/* The longest step the prior mean allows: the rule sees the process only at its nodes
 * (t + 0.355 h and t + 0.845 h; one node at t + 2h/3 when this cap was set) and the
 * samples at the step's ends, so a mean that dips to 0 between them (a
 * feature thinner than the step, with sigma << l: the knob's l = 1.4, sigma = 0.01) hides
 * the rate's peak, and steps of 2 l_d went through such features (the knob 6% too
 * bright). With the mean's Lipschitz bound `lip` (per unit t) the mean moves by at most
 * FS_MEAN_KAPPA = 6 sd over a step near its zero set, so t, the node and t + h are at
 * most 4 sd of mean apart: a mean that dips to 0 between two of them has a node or a
 * sample within 2 sd of its dip, whose rate rejects the step or whose value is likely
 * below 0 (with Simpson's nodes, 3 sd: the knob's brightness was the same at kappa 1, 2,
 * 3 and 6 and with steps capped to 0.035 l, while the cost fell from 21 to 8 samples per
 * flight; with the two nodes of "Step rule" the gaps are at most 0.49 h, so kappa 8 would
 * keep "4 sd apart", but paired renders of the knob (24^2, 2048 spp, the same seeds, only
 * kappa changed) read 1.27031 at kappa 3, +0.014% at 4.5, +0.055% at 6 and +0.11% at 8
 * (two seeds agreed on 6 -> 8 to 1e-5) for 3.94 -> 3.54 samples and 6.95 -> 6.08
 * evaluations a flight (6 -> 8, ~3% faster): a small bias that grows with kappa, so 6
 * stays), and far from it the step is the sphere-tracing distance to |mean| = FS_MEAN_Z
 * sd (a crossing there needs a residual of that size: rate ~ e^{-Z^2/2} / l, far below
 * any tolerance). m and sd are the prior's at x(ta) (sigma(x) fields and a posterior
 * included; fs_start_mean); a posterior's mean correction varies on the kernel's scale,
 * which the l_d cap covers. Returns the first try's length: hg (the growth ladder's),
 * or less where the mean needs it.
 * On the knob every step was this cap's (24^2 render: 6.6 steps a flight, all capped,
 * none rejected; most flights are fresh rays entering the occupancy shell at |mean| ~
 * 24 sd, gpis_proxy.h). Two ways to a longer step with the argument above unchanged (a
 * rejected try's half keeps both, being inside the certified stretch):
 *  - the slope bound of a grid mean over the try's stretch [ta, ta + hg] only
 *    (gp_mean_lipschitz_on, the bricks it crosses) instead of over the whole ray's
 *    (the knob's rays: 1.34 on average; steps a flight 6.6 -> 5.4);
 *  - far from the zero set, sphere tracing continued from ball to ball (up to
 *    FS_MEAN_HOPS prior-mean evaluations, no GP rows): each ball's edge starts the next,
 *    so |mean| >= FS_MEAN_Z sd on the whole union, the far case above, which the start's
 *    ball alone certified only up to (|m| - FS_MEAN_Z sd) / lip (a fresh ray took ~3
 *    GP steps to close in from 24 sd; steps a flight -> 3.5 with the first). Stationary
 *    priors without a posterior only, where sd is the same all along and the prior
 *    mean is the mean. */
inline double fs_mean_step(GpKernel p, __global const MeanNode* mean, int mc, FsScratch S,
                           FsRay ray, double3 dn, double ta, double hg, double m, double sd,
                           double lip, int grid)
{
    if (!(lip > 0.0)) return hg;
    double reach = fmax(FS_MEAN_KAPPA * sd, fabs(m) - FS_MEAN_Z * sd), cap = reach / lip;
    /* a try past t1 is clipped to it (then any cap >= he takes the same step as hg) */
    double he = fmin(hg, ray.t1 - ta);
    if (cap >= he) return hg;
    if (grid) {
        lip = (double)gp_mean_lipschitz_on(mean, mc, convert_float3(ray.o + ta * ray.d),
                                           convert_float3(ray.o + (ta + he) * ray.d))
              * length(ray.d);
        if (!(lip > 0.0)) return hg;
        cap = reach / lip;
        if (cap >= he) return hg;
    }
    if (fabs(m) > FS_MEAN_Z * sd && !S.post.n && !gp_kernel_nonstationary(p)) {
        /* sphere tracing on, from ball to ball: each ends where the next starts, so
         * |mean| >= FS_MEAN_Z sd (one sign) on all of [ta, ta + s] */
        double s = 0.0, mz = fabs(m);
        for (int k = 0; k < FS_MEAN_HOPS; ++k) {
            double hop = (mz - FS_MEAN_Z * sd) / lip;
            s += hop;
            if (s >= he) return hg;
            /* converging onto the near zone, or out of hops */
            if (hop < 0.25 * FS_MEAN_KAPPA * sd / lip || k + 1 == FS_MEAN_HOPS) break;
            double mk = fs_prior_mean(mean, mc, ray.o + (ta + s) * ray.d, dn, FS_OBS_VALUE);
            if (!(mk * m > 0.0) || !(fabs(mk) > FS_MEAN_Z * sd)) break;
            mz = fabs(mk);
        }
        cap = fmax(cap, s);
    }
    return cap;
}

/* The prior mean and sd at x(ta) for fs_mean_step. A value row of S at exactly that point
 * (the last sample; at the first step a fresh start's row or a vertex's value row) has
 * its own numbers (fs_row_prep), so neither the mean program nor the O(observations^2)
 * solve runs again: the same numbers as fs_mean_var's, bit for bit (the same operations
 * on the same point); else fs_mean_var (slot n as its work space). */
inline double fs_start_mean(GpKernel p, __global const MeanNode* mean, int mc, FsScratch S,
                            int fixed, int n, double3 x, double3 dn, double* sd)
{
    int k = n - 1;
    if (n == fixed) {
        for (k = fixed - 1; k >= 0; --k) {
            __global const FsObs* o = S.rows + k;
            if (o->kind == FS_OBS_VALUE && o->px == x.x && o->py == x.y && o->pz == x.z) break;
        }
    }
    if (k < 0) {
        double var, m = fs_mean_var(p, mean, mc, S, x, dn, FS_OBS_VALUE, n, &var);
        *sd = sqrt(var);
        return m;
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
                ? fs_start_mean(p, mean, mc, S, fixed, n, ray.o + ta * ray.d, dn, &sd0) : 0.0;
            h = fs_mean_step(p, mean, mc, S, ray, dn, ta, fmin(grow * h, FS_H_MAX * ell),
                             m0, sd0, lip, grid);
            if (r_new > FS_RULE_SAMPLES) {
                nr = fs_rule_build(p, mean, mc, S, R, fixed, n, ray, ta,
                                   FS_H_MAX * ell, ell, &st);
                r_new = 0;
            }
            for (; !st;) {
                int clipped = ta + h >= ray.t1;
                double hs = clipped ? ray.t1 - ta : h;
                /* Gauss-Radau with nu(ta) = 0: the mean rate over the step (per length)
                 * times l_d (per t), relative to the tolerance; the try stops at the
                 * first node that takes the sum past 1 */
                double r = 0.0;
                for (int q = 0; q < 2 && r <= 1.0; ++q) {
                    FsMoments M;
                    st = fs_moments(p, mean, mc, R, nr, ray, dn,
                                    ta + (q ? FS_RULE_NODE1 : FS_RULE_NODE0) * hs, &M);
                    if (st) break;
                    res.evals++;
                    r += (q ? FS_RULE_WEIGHT1 : FS_RULE_WEIGHT0) * fs_return_rate(M, outside)
                         * dlen * ell / tol;
                }
                if (st) break;
                if (r <= 1.0 || h <= FS_H_MIN * ell) {
                    tb = clipped ? ray.t1 : ta + hs;
                    /* the next step's first try: grow where the bound is slack */
                    grow = r < 0.05 ? 2.0 : (r < 0.3 ? 1.5 : 1.1);
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
    if (fs_isotropic_radial(p) && !S.post.n && prm.memory != GPIS_MEMORY_GLOBAL) {
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
