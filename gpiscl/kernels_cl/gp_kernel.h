/* GP covariance kernels from a packed GpKernel (gpiscl/host/gp/kernels.py is the
 * reference; its docstring derives every formula used here).
 *
 * Conventions: r = b - a for k(a, b), A = diag(aniso), s = r^T A r,
 * SE k = sigma^2 exp(-s / (2 l^2)). The periodic kernel is the product over axes of 1-D
 * periodic kernels (the Euclidean-distance form is not positive definite in 3-D).
 *
 * Precision: GP_REAL defaults to float, which is enough to build covariances of a few
 * dozen observations. Conditioning a dense ray segment (function space, up to hundreds of
 * strongly correlated values) loses ~log10(condition number) digits in the Cholesky
 * factorisation, so build that program with -DGP_REAL=double: every function below then
 * computes in double (and needs cl_khr_fp64, which compat.h enables).
 *
 * The local jet of k in r, Hess k = alpha g g^T + diag(D), gives all covariances:
 *   cov(f(a), f(b)) = k,  cov(d_u f(a), f(b)) = -u.G,  cov(f(a), d_v f(b)) = v.G,
 *   cov(d_u f(a), d_v f(b)) = -(alpha (u.g)(v.g) + u.D.v)
 */
#ifndef GP_REAL
#define GP_REAL float
#endif
#define GP_CAT_(a, b) a##b
#define GP_CAT(a, b) GP_CAT_(a, b)
#define GP_REAL3 GP_CAT(GP_REAL, 3)
#define GP_PI ((GP_REAL)3.14159265358979323846)

typedef struct {
    GP_REAL k;
    GP_REAL alpha;
    GP_REAL3 G;
    GP_REAL3 g;
    GP_REAL3 D;
} GpJet;

inline GP_REAL3 gp_aniso(GpKernel p)
{
    return (GP_REAL3)((GP_REAL)p.aniso.x, (GP_REAL)p.aniso.y, (GP_REAL)p.aniso.z);
}

/* Radial kernels of s alone: value, 2 k'(s), 4 k''(s). */
inline void gp_radial(GpKernel p, GP_REAL s, GP_REAL* k, GP_REAL* dk2, GP_REAL* ddk4)
{
    GP_REAL v = (GP_REAL)p.sigma2;
    if (p.kind == GP_KERNEL_THIN_PLATE) {
        GP_REAL R = (GP_REAL)p.radius, rho = sqrt(s);
        if (rho >= R) { *k = 0; *dk2 = 0; *ddk4 = 0; return; }  /* C^1 zero extension */
        /* factored 2 rho^3 - 3 R rho^2 + R^3: no cancellation near rho = R */
        *k = v * (R - rho) * (R - rho) * (2 * rho + R);
        *dk2 = 6 * v * (rho - R);
        /* 6 sigma^2 / rho multiplies (u.Ar)(v.Ar) = O(rho^2): the limit at rho = 0 is 0 */
        *ddk4 = rho > 0 ? 6 * v / rho : (GP_REAL)0;
        return;
    }
    GP_REAL l2 = (GP_REAL)p.length_scale * (GP_REAL)p.length_scale;
    if (p.kind == GP_KERNEL_RATIONAL_QUADRATIC) {
        GP_REAL a = (GP_REAL)p.alpha, x = s / (2 * a * l2), base = 1 + x;
        *k = v * exp(-a * log1p(x));   /* log1p: accurate towards the SE limit */
        *dk2 = -*k / (l2 * base);
        *ddk4 = *k * (a + 1) / (a * l2 * l2 * base * base);
        return;
    }
    *k = v * exp(-s / (2 * l2));
    *dk2 = -*k / l2;
    *ddk4 = *k / (l2 * l2);
}

/* Product kernels k = sigma^2 exp(-h): h, grad h and diag Hess h (h is separable). */
inline GP_REAL gp_log_terms(GpKernel p, GP_REAL3 r, GP_REAL3* dh, GP_REAL3* hh)
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
    if (p.kind == GP_KERNEL_LOCALLY_PERIODIC) {
        GP_REAL L2 = (GP_REAL)p.se_length_scale * (GP_REAL)p.se_length_scale;
        h += dot(A * r, r) / (2 * L2);
        *dh += A * r / L2;
        *hh += A / L2;
    }
    return h;
}

inline int gp_kernel_is_product(GpKernel p)
{
    return p.kind == GP_KERNEL_PERIODIC || p.kind == GP_KERNEL_LOCALLY_PERIODIC;
}

inline GP_REAL gp_kernel_value(GpKernel p, GP_REAL3 r)
{
    if (gp_kernel_is_product(p)) {
        GP_REAL3 dh, hh;
        return (GP_REAL)p.sigma2 * exp(-gp_log_terms(p, r, &dh, &hh));
    }
    GP_REAL k, dk2, ddk4;
    gp_radial(p, dot(gp_aniso(p) * r, r), &k, &dk2, &ddk4);
    return k;
}

inline GpJet gp_kernel_jet(GpKernel p, GP_REAL3 r)
{
    GpJet j;
    if (gp_kernel_is_product(p)) {
        GP_REAL3 dh, hh;
        j.k = (GP_REAL)p.sigma2 * exp(-gp_log_terms(p, r, &dh, &hh));
        j.G = -j.k * dh;
        j.alpha = j.k;
        j.g = dh;
        j.D = -j.k * hh;
        return j;
    }
    GP_REAL3 A = gp_aniso(p);
    GP_REAL3 ar = A * r;
    GP_REAL dk2, ddk4;
    gp_radial(p, dot(ar, r), &j.k, &dk2, &ddk4);
    j.G = dk2 * ar;
    j.alpha = ddk4;
    j.g = ar;
    j.D = dk2 * A;
    return j;
}

/* cov(f(a), f(b)) */
inline GP_REAL gp_cov_vv(GpKernel p, GP_REAL3 a, GP_REAL3 b)
{
    return gp_kernel_value(p, b - a);
}

/* cov(d_u f(a), f(b)) */
inline GP_REAL gp_cov_dv(GpKernel p, GP_REAL3 a, GP_REAL3 u, GP_REAL3 b)
{
    return -dot(u, gp_kernel_jet(p, b - a).G);
}

/* cov(f(a), d_v f(b)) */
inline GP_REAL gp_cov_vd(GpKernel p, GP_REAL3 a, GP_REAL3 b, GP_REAL3 v)
{
    return dot(v, gp_kernel_jet(p, b - a).G);
}

/* cov(d_u f(a), d_v f(b)) */
inline GP_REAL gp_cov_dd(GpKernel p, GP_REAL3 a, GP_REAL3 u, GP_REAL3 b, GP_REAL3 v)
{
    GpJet j = gp_kernel_jet(p, b - a);
    return -(j.alpha * dot(u, j.g) * dot(v, j.g) + dot(u * j.D, v));
}

/* One entry of a joint covariance matrix: observation x is a value (dx == 0) or the
 * derivative along u (dx != 0). */
inline GP_REAL gp_cov(GpKernel p, GP_REAL3 a, GP_REAL3 u, int da,
                      GP_REAL3 b, GP_REAL3 v, int db)
{
    if (!da && !db) return gp_kernel_value(p, b - a);
    GpJet j = gp_kernel_jet(p, b - a);
    if (da && db) return -(j.alpha * dot(u, j.g) * dot(v, j.g) + dot(u * j.D, v));
    return da ? -dot(u, j.G) : dot(v, j.G);
}
