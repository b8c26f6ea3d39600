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
 *
 * A kernel with a sigma(x) or l(x) field (GpKernel.sigma_field / ls_field, gp_cov_ns at
 * the end) is no function of b - a: gp_kernel_value and gp_kernel_jet then give only its
 * stationary base, so callers go through gp_cov*, which dispatch on the fields.
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

/* Radial kernels of s alone: value, 2 k'(s), 4 k''(s), in two halves so that a caller with
 * many lags can take the exps in vector lanes (fs_sampling.h fs_jets: PoCL's vector double
 * exp is much faster than its scalar one): gp_radial_arg is the exponent x whose exp the
 * kernel takes (0 for a kernel that takes none), gp_radial_of the three numbers given
 * e = exp(x). gp_radial is the two in a row: the same operations as one function.
 * Product kernels k = sigma^2 exp(-h) give h, grad h and diag Hess h (gp_log_terms).
 * Each kernel's maths is in lib/gp_kernels/<name>.h; the dispatch below is generated
 * from gpiscl/host/kinds/gp_kernels.py. */
/* @kinds gp_kernels covariance */
inline GP_REAL gp_radial_arg(GpKernel p, GP_REAL s) { return gp_kernel_radial_arg(p.kind, p, s); }

inline void gp_radial_of(GpKernel p, GP_REAL s, GP_REAL e, GP_REAL* k, GP_REAL* dk2,
                         GP_REAL* ddk4)
{
    gp_kernel_radial_of(p.kind, p, s, e, k, dk2, ddk4);
}

inline void gp_radial(GpKernel p, GP_REAL s, GP_REAL* k, GP_REAL* dk2, GP_REAL* ddk4)
{
    gp_radial_of(p, s, exp(gp_radial_arg(p, s)), k, dk2, ddk4);
}

inline GP_REAL gp_log_terms(GpKernel p, GP_REAL3 r, GP_REAL3* dh, GP_REAL3* hh)
{
    return gp_kernel_log_terms(p.kind, p, r, dh, hh);
}

inline int gp_kernel_is_product(GpKernel p) { return !GP_KERNEL_IS_RADIAL(p.kind); }

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

/* The jet of a radial kernel at r with s = r'Ar and e = exp(gp_radial_arg(p, s)) */
inline GpJet gp_radial_jet(GpKernel p, GP_REAL3 r, GP_REAL s, GP_REAL e)
{
    GpJet j;
    GP_REAL3 A = gp_aniso(p), ar = A * r;
    GP_REAL dk2, ddk4;
    gp_radial_of(p, s, e, &j.k, &dk2, &ddk4);
    j.G = dk2 * ar;
    j.alpha = ddk4;
    j.g = ar;
    j.D = dk2 * A;
    return j;
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
    GP_REAL s = dot(A * r, r);
    return gp_radial_jet(p, r, s, exp(gp_radial_arg(p, s)));
}

/* Spatially varying sigma(x) = sigma m_s(x) and (SE, RQ) l(x) = l m_l(x): kernels.py
 * (NonStationary) derives every term. A kernel with either field is not a function of
 * b - a, so gp_kernel_value/gp_kernel_jet do not apply to it; gp_cov* dispatch. */
inline int gp_kernel_nonstationary(GpKernel p) { return p.sigma_field | p.ls_field; }

/* A field multiplier m(x) and its gradient (linear or radial blend). A grid field's
 * samples live in global memory, which a by-value GpKernel cannot reach: its callers
 * evaluate it (fs_sampling.h fs_fields) and pass GpFieldsAt; here it is NaN, so a
 * caller that forgot it fails loudly. */
inline GP_REAL gp_field(int kind, float4 p0, float4 p1, GP_REAL3 x, GP_REAL3* grad)
{
    GP_REAL3 c = (GP_REAL3)((GP_REAL)p0.x, (GP_REAL)p0.y, (GP_REAL)p0.z);
    GP_REAL3 o = (GP_REAL3)((GP_REAL)p1.x, (GP_REAL)p1.y, (GP_REAL)p1.z);
    if (kind == GP_FIELD_LINEAR) {
        *grad = c;
        return (GP_REAL)p0.w + dot(c, x - o);
    }
    if (kind == GP_FIELD_RADIAL) {
        /* tanh of (|q|^2 - R^2) / (2 R w), not of |q| - R: smooth at the centre */
        GP_REAL3 q = x - c;
        GP_REAL R = (GP_REAL)p0.w, w = (GP_REAL)p1.z, h = (GP_REAL)0.5 * (o.y - o.x);
        GP_REAL th = tanh((dot(q, q) - R * R) / (2 * R * w));
        *grad = (h * (1 - th * th) / (R * w)) * q;
        return o.x + h * (1 + th);
    }
    *grad = (GP_REAL3)(0);
    return kind == GP_FIELD_NONE ? (GP_REAL)1 : (GP_REAL)NAN;
}

/* Both multipliers at one point: m_s, grad m_s, m_l, grad m_l (1 and 0 where a field is
 * absent). Only values and gradients at the two points of a covariance enter it, so a
 * caller with many covariances among few points evaluates them once per point. */
typedef struct { GP_REAL ms, ml; GP_REAL3 gs, gl; } GpFieldsAt;

inline GpFieldsAt gp_fields_analytic(GpKernel p, GP_REAL3 x)
{
    GpFieldsAt f;
    f.ms = gp_field(p.sigma_field, p.sigma_p0, p.sigma_p1, x, &f.gs);
    f.ml = gp_field(p.ls_field, p.ls_p0, p.ls_p1, x, &f.gl);
    return f;
}

/* Paciorek-Schervish SE/RQ with Sigma(x) = l(x)^2 A^-1: k0 and its derivative
 * covariances cov0(d_u f(a), f(b)), cov0(f(a), d_v f(b)), cov0(d_u f(a), d_v f(b)). */
inline GP_REAL gp_ps_terms(GpKernel p, GP_REAL3 a, GP_REAL3 u, GpFieldsAt fa,
                           GP_REAL3 b, GP_REAL3 v, GpFieldsAt fb,
                           GP_REAL* dv, GP_REAL* vd, GP_REAL* dd)
{
    GP_REAL3 A = gp_aniso(p), ar = A * (b - a);
    GP_REAL s = dot(ar, b - a), l = (GP_REAL)p.length_scale;
    GP_REAL la = l * fa.ml, lb = l * fb.ml;
    GP_REAL3 gla = l * fa.gl, glb = l * fb.gl;
    GP_REAL S = la * la + lb * lb, beta;
    GP_REAL psi = gp_kernel_ps_exponent(p.kind, p, s, S, &beta);
    GP_REAL P = 2 * la * lb / S;
    GP_REAL k0 = (GP_REAL)p.sigma2 * P * sqrt(P) * exp(psi);
    GP_REAL D = S + beta * s, iD2 = 1 / (D * D), h = (GP_REAL)1.5;
    GP_REAL G_s = -1 / D, G_ss = beta * iD2, G_sS = iD2;
    GP_REAL G_S = s / (S * D) - h / S;
    GP_REAL G_SS = -s * (D + S) * iD2 / (S * S) + h / (S * S);
    GP_REAL3 gSa = (2 * la) * gla, gSb = (2 * lb) * glb;
    GP_REAL3 Fa = (h / la) * gla - (2 * G_s) * ar + G_S * gSa;
    GP_REAL3 Fb = (h / lb) * glb + (2 * G_s) * ar + G_S * gSb;
    GP_REAL uFa = dot(u, Fa), vFb = dot(v, Fb), uAr = dot(u, ar), vAr = dot(v, ar);
    GP_REAL uS = dot(u, gSa), vS = dot(v, gSb);
    GP_REAL uHv = -2 * G_s * dot(u * A, v) + 2 * vAr * (-2 * G_ss * uAr + G_sS * uS)
                + vS * (-2 * G_sS * uAr + G_SS * uS);
    *dv = k0 * uFa;
    *vd = k0 * vFb;
    *dd = k0 * (uFa * vFb + uHv);
    return k0;
}

/* The product rule for m_s(a) m_s(b) around the base kernel's k0 and its derivative
 * covariances cov0(d_u f(a), f(b)) = dv, cov0(f(a), d_v f(b)) = vd and dd. */
inline GP_REAL gp_sigma_product(GP_REAL k0, GP_REAL dv, GP_REAL vd, GP_REAL dd, GP_REAL3 u,
                                int da, GpFieldsAt fa, GP_REAL3 v, int db, GpFieldsAt fb)
{
    GP_REAL ma = fa.ms, mb = fb.ms;
    GP_REAL ua = da ? dot(u, fa.gs) : (GP_REAL)0, vb = db ? dot(v, fb.gs) : (GP_REAL)0;
    if (!da && !db) return ma * mb * k0;
    if (!db) return mb * (ua * k0 + ma * dv);
    if (!da) return ma * (vb * k0 + mb * vd);
    return ua * vb * k0 + ua * mb * vd + ma * vb * dv + ma * mb * dd;
}

/* One entry of a kernel with a sigma field only, from the base (stationary) kernel's jet
 * at b - a (fs_jets takes several in vector lanes). */
inline GP_REAL gp_cov_sigma_jet(GpJet j, GP_REAL3 u, int da, GpFieldsAt fa, GP_REAL3 v,
                                int db, GpFieldsAt fb)
{
    return gp_sigma_product(j.k, -dot(u, j.G), dot(v, j.G),
                            -(j.alpha * dot(u, j.g) * dot(v, j.g) + dot(u * j.D, v)),
                            u, da, fa, v, db, fb);
}

/* One joint-covariance entry of a non-stationary kernel with the fields at a and b
 * given: the base (stationary or Paciorek-Schervish) terms, then the product rule for
 * m_s(a) m_s(b). */
inline GP_REAL gp_cov_ns_at(GpKernel p, GP_REAL3 a, GP_REAL3 u, int da, GpFieldsAt fa,
                            GP_REAL3 b, GP_REAL3 v, int db, GpFieldsAt fb)
{
    if (!p.ls_field) return gp_cov_sigma_jet(gp_kernel_jet(p, b - a), u, da, fa, v, db, fb);
    GP_REAL dv, vd, dd, k0 = gp_ps_terms(p, a, u, fa, b, v, fb, &dv, &vd, &dd);
    return gp_sigma_product(k0, dv, vd, dd, u, da, fa, v, db, fb);
}

inline GP_REAL gp_cov_ns(GpKernel p, GP_REAL3 a, GP_REAL3 u, int da,
                         GP_REAL3 b, GP_REAL3 v, int db)
{
    return gp_cov_ns_at(p, a, u, da, gp_fields_analytic(p, a), b, v, db,
                        gp_fields_analytic(p, b));
}

/* The entry of a stationary kernel between observation a (a value if !da, else the
 * derivative along u) and b (likewise along v), from the jet at b - a: callers that need
 * several entries at one lag evaluate the jet (one exp) once. */
inline GP_REAL gp_jet_cov(GpJet j, GP_REAL3 u, int da, GP_REAL3 v, int db)
{
    if (!da && !db) return j.k;
    if (da && db) return -(j.alpha * dot(u, j.g) * dot(v, j.g) + dot(u * j.D, v));
    return da ? -dot(u, j.G) : dot(v, j.G);
}

/* One entry of a joint covariance matrix: observation x is a value (dx == 0) or the
 * derivative along u (dx != 0). */
inline GP_REAL gp_cov(GpKernel p, GP_REAL3 a, GP_REAL3 u, int da,
                      GP_REAL3 b, GP_REAL3 v, int db)
{
    if (gp_kernel_nonstationary(p)) return gp_cov_ns(p, a, u, da, b, v, db);
    if (!da && !db) return gp_kernel_value(p, b - a);
    return gp_jet_cov(gp_kernel_jet(p, b - a), u, da, v, db);
}

/* The four kinds of entry by name (tests/test_gp_device.py) */
inline GP_REAL gp_cov_vv(GpKernel p, GP_REAL3 a, GP_REAL3 b) { return gp_cov(p, a, a, 0, b, b, 0); }
inline GP_REAL gp_cov_dv(GpKernel p, GP_REAL3 a, GP_REAL3 u, GP_REAL3 b)
{
    return gp_cov(p, a, u, 1, b, u, 0);
}
inline GP_REAL gp_cov_vd(GpKernel p, GP_REAL3 a, GP_REAL3 b, GP_REAL3 v)
{
    return gp_cov(p, a, v, 0, b, v, 1);
}
inline GP_REAL gp_cov_dd(GpKernel p, GP_REAL3 a, GP_REAL3 u, GP_REAL3 b, GP_REAL3 v)
{
    return gp_cov(p, a, u, 1, b, v, 1);
}

/* gp_cov with the fields at a and b given (ignored by stationary kernels) */
inline GP_REAL gp_cov_at(GpKernel p, GP_REAL3 a, GP_REAL3 u, int da, GpFieldsAt fa,
                         GP_REAL3 b, GP_REAL3 v, int db, GpFieldsAt fb)
{
    if (gp_kernel_nonstationary(p)) return gp_cov_ns_at(p, a, u, da, fa, b, v, db, fb);
    return gp_cov(p, a, u, da, b, v, db);
}
