/* Locally periodic: periodic(l, w) times the envelope exp(-s / (2 l_se^2)), one sigma^2
 * (gp/kernels.py LocallyPeriodic). Builds on periodic.h. */
#ifdef GP_KERNEL_PART_COVARIANCE
inline GP_REAL locally_periodic_log_terms(GpKernel p, GP_REAL3 r, GP_REAL3* dh, GP_REAL3* hh)
{
    GP_REAL h = periodic_log_terms(p, r, dh, hh);
    GP_REAL3 A = gp_aniso(p);
    GP_REAL L2 = (GP_REAL)p.se_length_scale * (GP_REAL)p.se_length_scale;
    h += dot(A * r, r) / (2 * L2);
    *dh += A * r / L2;
    *hh += A / L2;
    return h;
}
#endif
#ifdef GP_KERNEL_PART_SPECTRAL
/* the envelope's N(0, A / l_se^2), convolved with the periodic orders */
inline wsf locally_periodic_ws_scale(GpKernel k, uint2 key, int object, wsi idx)
{
    return (wsf)(1.0f / k.se_length_scale);
}

inline float locally_periodic_ws_lambda2(GpKernel k, float s)
{
    float v = periodic_ws_lambda2(k, s);
    v += s / (k.se_length_scale * k.se_length_scale);
    return v;
}
#endif
