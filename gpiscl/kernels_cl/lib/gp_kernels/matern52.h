/* Matern nu = 5/2: k = sigma^2 (1 + c rho + c^2 rho^2 / 3) e^(-c rho), c = sqrt(5) / l
 * (gp/kernels.py Matern52); (f, f', f'') along a ray is Markov (fs_markov.h). */
#ifdef GP_KERNEL_PART_COVARIANCE
inline GP_REAL matern52_c(GpKernel p)
{
    return (GP_REAL)2.23606797749979 / (GP_REAL)p.length_scale;
}

inline GP_REAL matern52_radial_arg(GpKernel p, GP_REAL s) { return -matern52_c(p) * sqrt(s); }

inline void matern52_radial_of(GpKernel p, GP_REAL s, GP_REAL e, GP_REAL* k, GP_REAL* dk2,
                               GP_REAL* ddk4)
{
    GP_REAL v = (GP_REAL)p.sigma2;
    GP_REAL rho = sqrt(s);
    GP_REAL c = matern52_c(p);
    GP_REAL cr = c * rho;
    *k = v * (1 + cr + cr * cr / 3) * e;
    *dk2 = -v * c * c * (1 + cr) * e / 3;
    *ddk4 = v * c * c * c * c * e / 3;
}
#endif
#ifdef GP_KERNEL_PART_SPECTRAL
/* multivariate Student-t, 2 nu degrees of freedom (matern32.h) */
inline wsf matern52_ws_scale(GpKernel k, uint2 key, int object, wsi idx)
{
    float nu = 2.5f;
    return sqrt(nu / ws_gamma(nu, key, object, idx)) / k.length_scale;
}

/* E[nu / G] = nu / (nu - 1) = 5/3 */
inline float matern52_ws_lambda2(GpKernel k, float s)
{
    float v = s / (k.length_scale * k.length_scale);
    v *= 5.0f / 3.0f;
    return v;
}
#endif
