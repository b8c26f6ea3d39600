/* The classical participating-medium counterpart of a function-space GPIS ("classical":
 * "medium" on a gpis shape; docs/design/classical-limits.md, Sec. 2): free flights whose
 * extinction is Rice's entry rate sigma_t = nu / Phi(mu / sigma) (Eqs. 2-3), and at a
 * collision the gradient of a fresh down-crossing (Rice-weighted slope along the ray,
 * Gaussian tangential part given it), so the micro-BSDF scatters like a cloud of spheres
 * (or of ellipsoids where the mean slopes). It remembers nothing (the vertex record is
 * ignored).
 *
 * A constant mean with a stationary isotropic kernel is homogeneous: exponential flights
 * (fs_classical_homogeneous_flight). Everything else is tracked against a majorant
 * (fs_classical_tracked_flight): Sec. 4.1 of the note derives the bound. */

/* The homogeneous medium: exponential flights with the rate at the mean where the
 * flight starts (exact: the mean is constant). */
inline FsResult fs_classical_homogeneous_flight(GpKernel p, __global const MeanNode* mean,
                                                int mc, FsRay ray, FsRng rng)
{
    FsResult res = {0};
    res.t = ray.t1;
    double dlen = length(ray.d);
    double3 dn = ray.d / dlen, x = ray.o + ray.t0 * ray.d, T, B;
    double sigma = sqrt(gp_cov(p, x, dn, 0, x, dn, 0));
    double lam2 = gp_cov(p, x, dn, 1, x, dn, 1);
    double z = (double)gp_mean_value(mean, mc, convert_float3(x)) / sigma;
    /* nu / P(f > 0): Rice's down-crossings per unit length over the outside fraction */
    double rate = exp(-0.5 * z * z) * sqrt(lam2) / (2.0 * M_PI * sigma)
                  / (0.5 * erfc(-z * M_SQRT1_2));
    double t = ray.t0 - log1p(-fs_uniform2(rng, 0u, FS_U_GRID).x) / (rate * dlen);
    if (!(t < ray.t1)) return res;
    res.hit = 1;
    res.t = t;
    fs_frame(dn, &T, &B);
    double l1 = sqrt(gp_cov(p, x, T, 1, x, T, 1)), l2 = sqrt(gp_cov(p, x, B, 1, x, B, 1));
    double q1 = l1 * fs_normal(rng, 0u, FS_SLOT_NORMAL);
    double q2 = l2 * fs_normal(rng, 0u, FS_SLOT_NORMAL + 1);
    double s = fs_downcrossing_slope(0.0, sqrt(lam2), fs_uniform2(rng, 0u, FS_U_SLOPE));
    res.law_s = fmin(s, -1e-5 * sqrt(q1 * q1 + q2 * q2));   /* as fs_march.h's hit */
    res.grad = T * q1 + B * q2 + dn * res.law_s;
    res.law_m = (double3)(0.0);
    res.law_a = T / l1;
    res.law_b = B / l2;
    return res;
}

/* phi(z) / Phi(z), decreasing in z; below z = -35 Phi underflows toward phi's range, and
 * the Mills-ratio series phi / Phi = |z| / (1 - z^-2 + 3 z^-4) holds to ~1e-7. */
inline double fs_cl_hazard(double z)
{
    if (z > -35.0) return fs_phi(z) / (0.5 * erfc(-z * M_SQRT1_2));
    double iz2 = 1.0 / (z * z);
    return -z / (1.0 - iz2 + 3.0 * iz2 * iz2);
}

/* E[(-X)^+] / s for X ~ N(m, s^2) as a function of a = m / s: phi(a) - a Phi(-a),
 * decreasing in a (its derivative is -Phi(-a)). */
inline double fs_cl_negative_part(double a) { return fs_phi(a) - a * 0.5 * erfc(a * M_SQRT1_2); }

/* What Rice's rate needs of the kernel along the unit direction d: sigma without a field,
 * sqrt(d' Lambda d) of the stationary base (a field's multipliers scale both locally). */
typedef struct { double sigma0, slope0; } FsClKernel;

inline FsClKernel fs_cl_kernel(GpKernel p, double3 d)
{
    GpKernel base = p;
    base.sigma_field = base.ls_field = GP_FIELD_NONE;
    double3 o = (double3)(0.0);
    FsClKernel k = {sqrt((double)p.sigma2), sqrt(gp_cov(base, o, d, 1, o, d, 1))};
    return k;
}

/* sigma_t at a point (Eq. 3 with Eq. 2) where the mean is mu with slope m along the ray
 * and the fields' multipliers are ms (sigma) and ml (l): with local stationarity sigma =
 * ms sigma0, s = ms slope0 / ml, and nu / Phi = (1 / sigma) h(mu / sigma) s psi(m / s). */
inline double fs_cl_rate(FsClKernel k, double mu, double m, double ms, double ml)
{
    double sigma = ms * k.sigma0, s = ms * k.slope0 / ml;
    return fs_cl_hazard(mu / sigma) * s * fs_cl_negative_part(m / s) / sigma;
}

/* The longest stretch from a along unit d over which the bounds stay tight: the mean
 * moves by at most FS_CL_STRETCH sigma (slope bound lip), a linear field by that fraction
 * of itself, and a grid field's index point by at most one voxel (fs_cl_grid_range). */
inline double fs_cl_field_stretch(int kind, __global const MeanNode* grid, double m,
                                  double3 grad, double3 d)
{
    if (kind == GP_FIELD_LINEAR && length(grad) > 0.0) return FS_CL_STRETCH * m / length(grad);
    if (kind != GP_FIELD_GRID) return INFINITY;
    float3 fd = convert_float3(d);
    float3 v = (float3)(dot(grid->row0.xyz, fd), dot(grid->row1.xyz, fd), dot(grid->row2.xyz, fd));
    return 1.0 / (double)length(v);
}

/* The gradient at a collision of the tracked medium: density proportional to
 * (-d . G)^+ N(G; grad mu, Lambda(x)) with Lambda = (ms / ml)^2 Lambda0 (Sec. 2.3): the
 * slope along d Rice-weighted about d . grad mu, then the tangential part given it, with
 * the same law_* record as fs_march.h's hit. */
inline void fs_cl_collision_law(GpKernel p, FsClKernel k, double3 grad_mu, GpFieldsAt f,
                                double3 dn, FsRng rng, FsResult* res)
{
    GpKernel base = p;
    base.sigma_field = base.ls_field = GP_FIELD_NONE;
    double3 o = (double3)(0.0), T, B;
    fs_frame(dn, &T, &B);
    double c = (f.ms / f.ml) * (f.ms / f.ml);
    double sdd = c * k.slope0 * k.slope0;
    double sTd = c * gp_cov(base, o, T, 1, o, dn, 1), sBd = c * gp_cov(base, o, B, 1, o, dn, 1);
    double sTT = c * gp_cov(base, o, T, 1, o, T, 1), sBB = c * gp_cov(base, o, B, 1, o, B, 1);
    double sTB = c * gp_cov(base, o, T, 1, o, B, 1);
    double m = dot(grad_mu, dn);
    double s = fs_downcrossing_slope(m, sqrt(sdd), fs_uniform2(rng, 0u, FS_U_SLOPE));
    double r = (s - m) / sdd;
    double m1 = dot(grad_mu, T) + sTd * r, m2 = dot(grad_mu, B) + sBd * r;
    double l11 = sqrt(sTT - sTd * sTd / sdd);
    double l21 = (sTB - sTd * sBd / sdd) / l11;
    double l22 = sqrt(sBB - sBd * sBd / sdd - l21 * l21);
    double z1 = fs_normal(rng, 0u, FS_SLOT_NORMAL), z2 = fs_normal(rng, 0u, FS_SLOT_NORMAL + 1);
    double q1 = m1 + l11 * z1, q2 = m2 + l21 * z1 + l22 * z2;
    res->law_s = fmin(s, -1e-5 * sqrt(q1 * q1 + q2 * q2));   /* as fs_march.h's hit */
    res->grad = T * q1 + B * q2 + dn * res->law_s;
    res->law_m = T * m1 + B * m2;
    res->law_a = T / l11;
    res->law_b = (B - (l21 / l11) * T) / l22;
}

/* The tracked medium (any mean the sampler takes, sigma and l fields, anisotropy): delta
 * tracking against a majorant that bounds sigma_t on each stretch [a, b] of the ray,
 *   maj = slope0 / (sigma0 ml_lo) h(z_lo) psi(-lip / s_lo),
 * since sigma_t = slope0 / (sigma0 ml) h(mu / sigma) psi(m / s), h and psi decrease, and on
 * the stretch mu >= mu(a) - lip |b - a|, |m| <= lip, s >= s_lo (Sec. 4.1 of the note). The
 * optical depth left at a stretch's end carries over to the next (memorylessness), so
 * tentative collision k draws block FS_U_TRACK + k: x its optical depth, y its
 * acceptance. More than FS_TRACK_CAP tentative collisions or stretches: status
 * FS_STATUS_TRACK_CAP, and a rate above its majorant (a bound that failed) is
 * FS_STATUS_MAJORANT: fs_object_flight counts either as a failed flight. res.samples
 * counts tentative collisions, res.evals stretches. */
inline FsResult fs_classical_tracked_flight(GpKernel p, __global const MeanNode* mean,
                                            int mc, FsRay ray, FsRng rng)
{
    FsResult res = {0};
    res.t = ray.t1;
    double dlen = length(ray.d);
    double3 dn = ray.d / dlen;
    FsClKernel k = fs_cl_kernel(p, dn);
    __global const MeanNode* sgrid = mean + p.sigma_grid;
    __global const MeanNode* lgrid = mean + p.ls_grid;
    float lip_all = gp_mean_lipschitz(mean, mc);
    int grid_mean = gp_mean_has_grid(mean, mc);
    double2 u = fs_uniform2(rng, 0u, FS_U_TRACK);
    double tau = -log1p(-u.x), t = ray.t0;
    for (res.evals = 0; t < ray.t1; ++res.evals) {
        if (res.evals >= FS_TRACK_CAP) { res.status = FS_STATUS_TRACK_CAP; return res; }
        double3 a = ray.o + t * ray.d;
        GpFieldsAt fa = fs_fields(p, mean, a);
        float3 ga;
        double mu = (double)gp_mean_eval(mean, mc, convert_float3(a), &ga);
        /* the ray's and the fields' limit, then the mean's */
        double room = fmin((ray.t1 - t) * dlen,
                           fmin(fs_cl_field_stretch(p.sigma_field, sgrid, fa.ms, fa.gs, dn),
                                fs_cl_field_stretch(p.ls_field, lgrid, fa.ml, fa.gl, dn)));
        /* tight where the rate matters; far outside (mu >> sigma: h(z) ~ e^{-z^2 / 2}) as
         * long as mu may halve, which keeps the majorant negligible and the stretches
         * few (a small sigma(x) took thousands of tight ones) */
        double tight = fmax(FS_CL_STRETCH * k.sigma0 * fa.ms, FS_CL_FAR * mu);
        double lip = lip_all, L = room;
        if (lip > 0.0) L = fmin(L, tight / lip);
        if (grid_mean && lip > 0.0) {
            /* the bound over the stretch only, and a longer stretch where it is smaller */
            lip = gp_mean_lipschitz_on(mean, mc, convert_float3(a), convert_float3(a + L * dn));
            double longer = fmin(room, tight / fmax(lip, (double)FLT_MIN));
            if (longer > L) {
                L = longer;
                lip = gp_mean_lipschitz_on(mean, mc, convert_float3(a),
                                           convert_float3(a + L * dn));
            }
        }
        double3 b = a + L * dn;
        double2 ms = fs_field_range(p.sigma_field, p.sigma_p0, p.sigma_p1, sgrid, a, b);
        double2 ml = fs_field_range(p.ls_field, p.ls_p0, p.ls_p1, lgrid, a, b);
        /* the mean in float: its rounding, ~1e-7 relative, is padded */
        double mu_lo = mu - lip * L - 1e-6 * (1.0 + fabs(mu));
        double z_lo = mu_lo / (k.sigma0 * (mu_lo >= 0.0 ? ms.y : ms.x));
        double s_lo = ms.x * k.slope0 / ml.y;
        double maj = k.slope0 / (k.sigma0 * ml.x) * fs_cl_hazard(z_lo)
                     * fs_cl_negative_part(-lip / s_lo);
        maj *= 1.0 + 1e-5;   /* float means and grid fields round by ~1e-7 */
        if (!(maj >= 0.0) || isinf(maj) || !(L > 0.0)) { res.status = FS_STATUS_NAN; return res; }
        double t_end = L >= (ray.t1 - t) * dlen ? ray.t1 : t + L / dlen;
        for (;;) {
            double left = (t_end - t) * dlen;
            if (!(tau < maj * left)) {   /* the stretch ends first: its depth carries over */
                tau -= maj * left;
                t = t_end;
                break;
            }
            t += tau / (maj * dlen);
            double3 x = ray.o + t * ray.d;
            GpFieldsAt fx = fs_fields(p, mean, x);
            float3 gx;
            double mx = (double)gp_mean_eval(mean, mc, convert_float3(x), &gx);
            double rate = fs_cl_rate(k, mx, dot(convert_double3(gx), dn), fx.ms, fx.ml);
            if (!(rate <= maj)) { res.status = FS_STATUS_MAJORANT; return res; }
            if (u.y * maj < rate) {
                res.hit = 1;
                res.t = t;
                ++res.samples;
                ++res.evals;
                fs_cl_collision_law(p, k, convert_double3(gx), fx, dn, rng, &res);
                return res;
            }
            if (++res.samples >= FS_TRACK_CAP) { res.status = FS_STATUS_TRACK_CAP; return res; }
            u = fs_uniform2(rng, 0u, FS_U_TRACK + (uint)res.samples);
            tau = -log1p(-u.x);
        }
    }
    return res;
}

/* The homogeneous flight where it is exact (a constant mean: slope bound 0; a stationary
 * isotropic kernel), else the tracked one. */
inline FsResult fs_classical_flight(GpKernel p, __global const MeanNode* mean, int mc,
                                    FsRay ray, FsRng rng)
{
    int homogeneous = gp_mean_lipschitz(mean, mc) == 0.0f && !gp_kernel_nonstationary(p)
                      && p.aniso.x == p.aniso.y && p.aniso.y == p.aniso.z;
    return homogeneous ? fs_classical_homogeneous_flight(p, mean, mc, ray, rng)
                       : fs_classical_tracked_flight(p, mean, mc, ray, rng);
}
