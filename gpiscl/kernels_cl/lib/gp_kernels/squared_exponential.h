/* Squared exponential k = sigma^2 exp(-s / (2 l^2)) (gp/kernels.py SquaredExponential). */
#ifdef GP_KERNEL_PART_COVARIANCE
inline GP_REAL squared_exponential_radial_arg(GpKernel p, GP_REAL s)
{
    GP_REAL l2 = (GP_REAL)p.length_scale * (GP_REAL)p.length_scale;
    return -s / (2 * l2);
}

inline void squared_exponential_radial_of(GpKernel p, GP_REAL s, GP_REAL e, GP_REAL* k,
                                          GP_REAL* dk2, GP_REAL* ddk4)
{
    GP_REAL v = (GP_REAL)p.sigma2;
    GP_REAL l2 = (GP_REAL)p.length_scale * (GP_REAL)p.length_scale;
    *k = v * e;
    *dk2 = -*k / l2;
    *ddk4 = *k / (l2 * l2);
}

/* corr(t) = exp(-t^2 dad / (2 l^2)) = c */
inline double squared_exponential_corr_lag(GpKernel p, double dad, double c)
{
    double l = p.length_scale;
    return l * sqrt(-2.0 * log(c) / dad);
}

/* Paciorek-Schervish: exp(psi), psi = -s / S with S = l(a)^2 + l(b)^2 */
inline GP_REAL squared_exponential_ps_exponent(GpKernel p, GP_REAL s, GP_REAL S, GP_REAL* beta)
{
    *beta = 0;
    return -s / S;
}
#endif
#ifdef GP_KERNEL_PART_SPECTRAL
/* N(0, A / l^2) */
inline wsf squared_exponential_ws_scale(GpKernel k, uint2 key, int object, wsi idx)
{
    return (wsf)(1.0f / k.length_scale);
}

inline float squared_exponential_ws_lambda2(GpKernel k, float s)
{
    return s / (k.length_scale * k.length_scale);
}
#endif
