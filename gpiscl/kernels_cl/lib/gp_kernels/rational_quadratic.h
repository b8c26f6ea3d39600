/* Rational quadratic k = sigma^2 (1 + s / (2 a l^2))^-a (gp/kernels.py RationalQuadratic). */
#ifdef GP_KERNEL_PART_COVARIANCE
inline GP_REAL rational_quadratic_radial_arg(GpKernel p, GP_REAL s)
{
    GP_REAL l2 = (GP_REAL)p.length_scale * (GP_REAL)p.length_scale;
    GP_REAL a = (GP_REAL)p.alpha;
    return -a * log1p(s / (2 * a * l2));   /* log1p: accurate towards the SE limit */
}

inline void rational_quadratic_radial_of(GpKernel p, GP_REAL s, GP_REAL e, GP_REAL* k,
                                         GP_REAL* dk2, GP_REAL* ddk4)
{
    GP_REAL v = (GP_REAL)p.sigma2;
    GP_REAL l2 = (GP_REAL)p.length_scale * (GP_REAL)p.length_scale;
    *k = v * e;
    GP_REAL a = (GP_REAL)p.alpha, base = 1 + s / (2 * a * l2);
    *dk2 = -*k / (l2 * base);
    *ddk4 = *k * (a + 1) / (a * l2 * l2 * base * base);
}

/* corr(t) = (1 + t^2 dad / (2 a l^2))^-a = c */
inline double rational_quadratic_corr_lag(GpKernel p, double dad, double c)
{
    double l = p.length_scale;
    double a = p.alpha;
    return l * sqrt(2.0 * a * (pow(c, -1.0 / a) - 1.0) / dad);
}

/* Paciorek-Schervish: exp(psi), psi = -a log(1 + s / (a S)), S = l(a)^2 + l(b)^2 */
inline GP_REAL rational_quadratic_ps_exponent(GpKernel p, GP_REAL s, GP_REAL S, GP_REAL* beta)
{
    GP_REAL al = (GP_REAL)p.alpha;
    *beta = 1 / al;
    return -al * log1p(s / (al * S));
}
#endif
#ifdef GP_KERNEL_PART_SPECTRAL
/* sqrt(tau) with tau ~ Gamma(a, rate a l^2) (gp/spectral.py) */
inline wsf rational_quadratic_ws_scale(GpKernel k, uint2 key, int object, wsi idx)
{
    return sqrt(ws_gamma(k.alpha, key, object, idx) / (k.alpha * k.length_scale * k.length_scale));
}

/* E[tau] = 1 / l^2, as SE */
inline float rational_quadratic_ws_lambda2(GpKernel k, float s)
{
    return s / (k.length_scale * k.length_scale);
}
#endif
