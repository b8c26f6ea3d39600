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
    /* capped after the division too: at a nearly grazing h (|c| ~ 1e-30) the quotient
     * overflowed to inf, and the power heuristic's inf / inf made emission.cl's weight
     * NaN (2-40 non-finite paths in 6e4 under a small light, renewal memory) */
    return fmin(fs_normal_pdf(L, d, *h) / (4.0f * -c), FS_PDF_MAX);
}

/* The gradient normal h implies (h . d < 0): same slope along d. */
inline float3 fs_implied_gradient(FsNormalLaw L, float3 d, float3 h)
{
    return (L.s / dot(h, d)) * h;
}

/* --- Rough conductor at a function-space hit ------------------------------------------
 * The direct light at the vertex is the double integral over the GPIS normal n and the
 * light direction l of F(n, l) = p_Omega(n) fcos(n; v, l) Le(l) V(l | g(n)), with fcos the
 * Beckmann conductor of bsdf/rough_conductor.h about n (Fresnel at the microfacet half vector
 * m = normalize(v + l), not at n). The density of the whole direction, the convolution
 * of p_Omega with the conductor's lobe, has no closed form, so the strategies work on
 * pairs (n, l), where every density is closed:
 *   A  the hit's sampled normal n0 and a light sample: p_A = p_Omega(n) p_L(l);
 *   B  a light sample, then n around the half vector h = normalize(v + l) with the
 *      Beckmann microfacet density q(n | l) = D(n.h) (n.h) (the lobe's own shape turned
 *      around: n where fcos(n; v, l) peaks): p_B = p_L(l) q(n | l); its shadow ray
 *      conditions on the gradient n implies, as the mirror's does (B is the mirror's
 *      NEE blurred by the lobe: alpha -> 0 gives it back);
 *   C  BSDF sampling: n0, then l from the lobe about n0: p_C = p_Omega(n) p_c(l | n).
 * A is good where the GPIS normal is sharp and the lobe wide, B where the normal is
 * spread and the lobe narrow (a glossy GPIS under a small light: A alone only catches
 * the light when n0 happens to point at it). Next-event estimation picks A or B with
 * probability 1/2 (one shadow ray per vertex), so its pairs have the mixture density
 * p_AB = (p_A + p_B) / 2, and the power heuristic weighs p_AB against p_C: neither A
 * nor B dominates where it is poor (p_AB >= p_A / 2 and >= p_B / 2). Dividing every
 * density by p_Omega(n0) (common to A and C at n0), C's weight at a light needs only
 *   p_AB / p_Omega(n0) = p_L(l) (1 + q(n0 | l) / p_Omega(n0)) / 2,
 * which fs_conductor_light_pdf gives emission.cl and escaped_rays.cl from the path's
 * prev_n (n0, p_Omega(n0)) and prev_v (v, alpha). Delta lights (p_L = 0) use A alone:
 * B cannot sample them and C never hits them. */

/* q(n | l): Beckmann density D(n.h) (n.h) of n about the half vector h, per steradian */
inline float fs_lobe_normal_pdf(float3 n, float3 h, float alpha)
{
    float c = dot(n, h);
    return c > 0.0f ? beckmann_d(c, alpha) * c : 0.0f;
}

/* n ~ q(. | l) about h from two uniforms (the microfacet sampling of bsdf/rough_conductor.h) */
inline float3 fs_lobe_normal_sample(float3 h, float alpha, float2 u)
{
    float tan2 = -alpha * alpha * log(1.0f - u.x), phi = 2.0f * PI_F * u.y;
    float cm = 1.0f / sqrt(1.0f + tan2), sm = sqrt(fmax(1.0f - cm * cm, 0.0f));
    float3 t, b;
    make_frame(h, &t, &b);
    return normalize(sm * cos(phi) * t + sm * sin(phi) * b + cm * h);
}

/* The light strategy's density relative to p_Omega(n0) for C's MIS weight: pdf_light
 * (per light, already divided by the light count) unchanged unless the path's previous
 * vertex was a function-space rough conductor (prev_n.w = p_Omega(n0) > 0). */
inline float fs_conductor_light_pdf(float pdf_light, float4 prev_n, float4 prev_v, float3 l)
{
    if (!(prev_n.w > 0.0f) || !(pdf_light > 0.0f)) return pdf_light;   /* 0 * inf */
    float3 h = normalize(prev_v.xyz + l);
    return pdf_light * 0.5f * (1.0f + fs_lobe_normal_pdf(prev_n.xyz, h, prev_v.w) / prev_n.w);
}
