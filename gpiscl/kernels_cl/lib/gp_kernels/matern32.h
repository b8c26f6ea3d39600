/* Matern nu = 3/2: k = sigma^2 (1 + c rho) e^(-c rho), c = sqrt(3) / l, rho = sqrt(s)
 * (gp/kernels.py Matern32); (f, f') along a ray is Markov (fs_markov.h). */
#ifdef GP_KERNEL_PART_COVARIANCE
inline GP_REAL matern32_c(GpKernel p)
{
    return (GP_REAL)1.7320508075688772 / (GP_REAL)p.length_scale;
}

inline GP_REAL matern32_radial_arg(GpKernel p, GP_REAL s) { return -matern32_c(p) * sqrt(s); }

inline void matern32_radial_of(GpKernel p, GP_REAL s, GP_REAL e, GP_REAL* k, GP_REAL* dk2,
                               GP_REAL* ddk4)
{
    GP_REAL v = (GP_REAL)p.sigma2;
    GP_REAL rho = sqrt(s);
    GP_REAL c = matern32_c(p);
    *k = v * (1 + c * rho) * e;
    *dk2 = -v * c * c * e;
    /* c^3 e / rho multiplies (u.Ar)(v.Ar) = O(rho^2): the limit at rho = 0 is 0 */
    *ddk4 = rho > 0 ? v * c * c * c * e / rho : (GP_REAL)0;
}
#endif
#ifdef GP_KERNEL_PART_SPECTRAL
/* multivariate Student-t, 2 nu degrees of freedom: sqrt(nu / G) / l, G ~ Gamma(nu, 1)
 * (gp/spectral.py derives it) */
inline wsf matern32_ws_scale(GpKernel k, uint2 key, int object, wsi idx)
{
    float nu = 1.5f;
    return sqrt(nu / ws_gamma(nu, key, object, idx)) / k.length_scale;
}

/* E[nu / G] = nu / (nu - 1) = 3 for G ~ Gamma(nu, 1) */
inline float matern32_ws_lambda2(GpKernel k, float s)
{
    float v = s / (k.length_scale * k.length_scale);
    v *= 3.0f;
    return v;
}
#endif
