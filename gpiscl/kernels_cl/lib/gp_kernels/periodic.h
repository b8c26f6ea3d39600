/* Periodic: the product over axes of 1-D periodic kernels, k = sigma^2 exp(-h),
 * h = (2 / l^2) sum_i sin^2(pi w sqrt(A_ii) r_i) (gp/kernels.py Periodic). */
#ifdef GP_KERNEL_PART_COVARIANCE
inline GP_REAL periodic_log_terms(GpKernel p, GP_REAL3 r, GP_REAL3* dh, GP_REAL3* hh)
{
    GP_REAL3 A = gp_aniso(p);
    GP_REAL l2 = (GP_REAL)p.length_scale * (GP_REAL)p.length_scale;
    GP_REAL3 c = GP_PI * (GP_REAL)p.w * sqrt(A);
    GP_REAL3 cr = c * r;
    GP_REAL3 sn = sin(cr), cs = cos(cr);
    /* sin^2, not (1 - cos)/2: no cancellation at small lags */
    GP_REAL h = (2 / l2) * dot(sn, sn);
    *dh = (4 / l2) * c * sn * cs;
    *hh = (4 / l2) * c * c * (cs * cs - sn * sn);
    return h;
}
#endif
#ifdef GP_KERNEL_PART_SPECTRAL
/* only the periodic orders (ws_features: the periodic_orders trait) */
inline wsf periodic_ws_scale(GpKernel k, uint2 key, int object, wsi idx) { return (wsf)0.0f; }

/* per axis E[n^2] = 1/l^2: n is Skellam(z/2, z/2) with z = 1/l^2 */
inline float periodic_ws_lambda2(GpKernel k, float s)
{
    float c = WS_TWO_PI * k.w / k.length_scale;
    float v = c * c * s;
    return v;
}
#endif
