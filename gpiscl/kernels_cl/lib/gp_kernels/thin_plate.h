/* Thin plate k = sigma^2 (R - rho)^2 (2 rho + R) for rho = sqrt(s) < R, 0 beyond
 * (gp/kernels.py ThinPlate): no exp, and no spectral density. */
#ifdef GP_KERNEL_PART_COVARIANCE
inline GP_REAL thin_plate_radial_arg(GpKernel p, GP_REAL s) { return 0; }

inline void thin_plate_radial_of(GpKernel p, GP_REAL s, GP_REAL e, GP_REAL* k, GP_REAL* dk2,
                                 GP_REAL* ddk4)
{
    GP_REAL v = (GP_REAL)p.sigma2;
    GP_REAL R = (GP_REAL)p.radius, rho = sqrt(s);
    if (rho >= R) { *k = 0; *dk2 = 0; *ddk4 = 0; return; }  /* C^1 zero extension */
    /* factored 2 rho^3 - 3 R rho^2 + R^3: no cancellation near rho = R */
    *k = v * (R - rho) * (R - rho) * (2 * rho + R);
    *dk2 = 6 * v * (rho - R);
    /* 6 sigma^2 / rho multiplies (u.Ar)(v.Ar) = O(rho^2): the limit at rho = 0 is 0 */
    *ddk4 = rho > 0 ? 6 * v / rho : (GP_REAL)0;
}
#endif
