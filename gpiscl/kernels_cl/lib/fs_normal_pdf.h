/* The density of the normal drawn at a function-space GPIS hit, and the mirror's
 * direction density built on it: what next-event estimation and MIS at function-space
 * vertices need (scatter.cl). Float, in the stage program; the law comes from
 * fs_march.h ("Hit") through the ray queue (hit_law_m/a/b; FsResult.law_*).
 *
 * The law. With d the unit ray direction, the hit stage draws the slope along d first,
 * s = d . grad f < 0 (its down-crossing law), then the tangential components
 * q = (T . g, B . g) ~ N2(m_q, S_q) given s and everything the ray saw (T, B = fs_frame(d)):
 *   g = s d + q1 T + q2 B,    n = g / |g|.
 * This holds for every case the sampler has: isotropic stationary kernels (m_q = the
 * prior mean's tangential gradient, S_q = -2 k'(0) I: the closed form) and the general
 * conditional (anisotropic kernels, sigma(x)/l(x) fields, posteriors, global memory):
 * there the slope is still drawn first and pinned, and (q1, q2) given it is still a
 * 2-D Gaussian, the conditional of the two appended rows (fs_march.h keeps its mean and
 * factor). So the density is the pinned-slope one below in all cases; the fully random
 * 3-D projected normal (NEXT-ALGORITHMS 3.1) is never needed: the sampler never draws
 * the slope jointly with q.
 *
 * Derivation. For fixed s the map q -> n sends the plane {s d + q1 T + q2 B} to the
 * hemisphere n . d < 0 one to one (a gnomonic projection from the origin onto the plane
 * at distance |s| along d). Its inverse: the point of the plane along n is g = lambda n
 * with lambda = s / (n . d) > 0, so q(n) = lambda (n . T, n . B). A plane element dA seen
 * from the origin at distance lambda with |cos| = |n . d| between its normal d and the
 * line of sight subtends dOmega = dA |n . d| / lambda^2, hence
 *   dA / dOmega = lambda^2 / |n . d| = s^2 / |n . d|^3,
 *   p_Omega(n) = N2(q(n); m_q, S_q) s^2 / |n . d|^3          (0 where n . d >= 0).
 * (NEXT-ALGORITHMS 3.2; the supplemental's Eq. 27 misses this Jacobian.) It integrates to
 * 1 over the hemisphere and matches sampled normals: tests/test_fs_nee.py (quadrature,
 * and 1/p-weighted cell counts of device-sampled normals, isotropic, anisotropic and
 * global memory).
 * In world vectors (no frame needed here): with S_q = L L^T, r = g_t - m (g_t = g - s d,
 * m = m_q in world space) and a, b the rows of L^-1 in world space, z = (a . r, b . r) is
 * standard normal and N2 = phi(z1) phi(z2) / det L, det L = 1 / |a x b|.
 *
 * Mirror. The normal that reflects the incoming -d into wl is the half vector
 * h = normalize(-d + wl); reflection maps normals to directions with
 * dOmega_wl / dOmega_h = 4 |d . h| (the usual microfacet Jacobian), so
 *   p(wl) = p_Omega(h) / (4 |d . h|),
 * and h . d < 0 holds for every wl but the forward direction (pdf 0 there). The mirror's
 * f (no cosine: a micro-BSDF in a volume-like medium) is albedo p(wl): a BSDF-sampled
 * continuation carries weight albedo and pdf p(wi) for MIS.
 *
 * Implied gradient. A light sample that chose normal h also chose the gradient
 * g(h) = lambda(h) h, lambda = s / (h . d): same slope s, tangential part lambda h_t. The
 * shadow ray conditions on it (renewal_plus: its slope along the shadow ray; global: the
 * ring's tangential rows, fs_sampling.h fs_begin; renewal and none use no gradient). */

typedef struct { float3 m, a, b; float s; } FsNormalLaw;

inline FsNormalLaw fs_normal_law(float4 lm, float4 la, float4 lb)
{
    FsNormalLaw L = {lm.xyz, la.xyz, lb.xyz, lm.w};
    return L;
}

/* p_Omega(n) per steradian for unit n and unit ray direction d. Evaluated as a log so
 * that s^2 / |n.d|^3 at grazing n (1e9 and more) and the Gaussian's underflow meet
 * before rounding; capped at FS_PDF_MAX so squares in the power heuristic stay finite. */
#define FS_PDF_MAX 1e18f
inline float fs_normal_pdf(FsNormalLaw L, float3 d, float3 n)
{
    float c = dot(n, d);
    if (!(c < 0.0f) || !(L.s < 0.0f)) return 0.0f;
    float lam = L.s / c;
    float3 r = lam * (n - c * d) - L.m;
    float z1 = dot(L.a, r), z2 = dot(L.b, r);
    float inv_det = length(cross(L.a, L.b));
    float lp = -0.5f * (z1 * z1 + z2 * z2) + log(inv_det * (0.5f * INV_PI_F))
             + 2.0f * log(-L.s) - 3.0f * log(-c);
    return fmin(exp(lp), FS_PDF_MAX);
}

/* The mirror's density of the outgoing direction wl (unit) for a ray along d. */
inline float fs_mirror_pdf(FsNormalLaw L, float3 d, float3 wl, float3* h)
{
    float3 v = wl - d;
    float len = length(v);
    if (!(len > 0.0f)) return 0.0f;
    *h = v / len;
    float c = dot(*h, d);
    if (!(c < 0.0f)) return 0.0f;
    return fs_normal_pdf(L, d, *h) / (4.0f * -c);
}

/* The gradient normal h implies (h . d < 0): same slope along d. */
inline float3 fs_implied_gradient(FsNormalLaw L, float3 d, float3 h)
{
    return (L.s / dot(h, d)) * h;
}
