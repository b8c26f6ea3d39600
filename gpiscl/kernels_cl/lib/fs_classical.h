/* The classical participating-medium counterpart of a function-space GPIS ("classical":
 * "medium" on a gpis shape; docs/design/classical-limits.md, Sec. 2): exponential free
 * flights with Rice's entry rate at the mean's level where the flight starts (exact for
 * the constant means compile/classical.py admits), and at a hit the gradient of a fresh
 * down-crossing of a stationary isotropic GP (Rice-weighted slope along the ray, Gaussian
 * tangential part): the visible normals of a sphere, so the micro-BSDF scatters like a
 * cloud of spheres. It remembers nothing (the vertex record is ignored). */
inline FsResult fs_classical_flight(GpKernel p, __global const MeanNode* mean, int mc,
                                    FsRay ray, FsRng rng)
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
