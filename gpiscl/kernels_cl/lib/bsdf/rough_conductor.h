/* Rough conductor (kinds/materials.py rough_conductor; material interface: bsdf/diffuse.h).
 * Beckmann microfacets D(m) = exp(-tan^2 theta_m / a^2) / (pi a^2 cos^4 theta_m), the
 * exact unpolarised Fresnel term of eta + i k, height-correlated Smith masking
 * G2 = 1 / (1 + Lambda(v) + Lambda(l)) (Heitz 2014), with v = -wo towards the viewer and
 * l the outgoing direction on the side of n:
 *   f cos(l) = albedo F(v.m) D(m) G2 / (4 cos v),   m = normalize(v + l).
 * Sampling draws m from D(m) cos theta_m (Walter et al. 2007) and reflects v about it:
 *   pdf(l) = D(m) cos theta_m / (4 v.m),  weight = albedo F G2 (v.m) / (cos v cos theta_m);
 * reflections below the surface end the path (weight 0), which is how a single-scattering
 * microfacet model loses energy. fresnel_conductor: bsdf/fresnel.h. Numpy twin:
 * gpiscl/testing/reference/rough_conductor.py. */

/* Smith's Lambda for Beckmann at a direction of cosine c to the normal: with
 * q = c / (alpha sin), (exp(-q^2) / (q sqrt(pi)) - erfc(q)) / 2 (no cancellation) */
inline float beckmann_lambda(float c, float alpha)
{
    float s = sqrt(fmax(1.0f - c * c, 0.0f));
    if (s <= 0.0f) return 0.0f;
    float q = c / (alpha * s);
    return 0.5f * (exp(-q * q) / (q * 1.7724538509f) - erfc(q));
}

inline float beckmann_d(float cm, float alpha)
{
    float c2 = cm * cm, a2 = alpha * alpha;
    return exp(-(1.0f - c2) / (c2 * a2)) / (PI_F * a2 * c2 * c2);
}

/* f(v, l) cos(l) and the sampling pdf of l; 0 when l or the half vector is below n */
inline float3 beckmann_conductor_eval(float3 albedo, float3 eta, float3 k, float alpha,
                                      float3 n, float3 v, float3 l, float* pdf)
{
    float cv = dot(n, v), cl = dot(n, l);
    *pdf = 0.0f;
    if (!(cv > 0.0f && cl > 0.0f)) return (float3)(0.0f);
    float3 m = normalize(v + l);
    float cm = dot(n, m), vm = dot(v, m);
    if (!(cm > 0.0f && vm > 0.0f)) return (float3)(0.0f);
    float D = beckmann_d(cm, alpha);
    float G = 1.0f / (1.0f + beckmann_lambda(cv, alpha) + beckmann_lambda(cl, alpha));
    *pdf = D * cm / (4.0f * vm);
    return albedo * fresnel_conductor(vm, eta, k) * (D * G / (4.0f * cv));
}

/* l ~ pdf (returns f cos / pdf; 0 if the reflection leaves below the surface) */
inline float3 beckmann_conductor_sample(float3 albedo, float3 eta, float3 k, float alpha,
                                        float3 n, float3 v, float2 u, float3* l, float* pdf)
{
    float tan2 = -alpha * alpha * log(1.0f - u.x), phi = 2.0f * PI_F * u.y;
    float cm = 1.0f / sqrt(1.0f + tan2), sm = sqrt(fmax(1.0f - cm * cm, 0.0f));
    float3 t, b;
    make_frame(n, &t, &b);
    float3 m = sm * cos(phi) * t + sm * sin(phi) * b + cm * n;
    float vm = dot(v, m);
    *l = 2.0f * vm * m - v;
    float cv = dot(n, v), cl = dot(n, *l);
    *pdf = 0.0f;
    if (!(vm > 0.0f && cl > 0.0f && cv > 0.0f)) return (float3)(0.0f);
    *pdf = beckmann_d(cm, alpha) * cm / (4.0f * vm);
    float G = 1.0f / (1.0f + beckmann_lambda(cv, alpha) + beckmann_lambda(cl, alpha));
    return albedo * fresnel_conductor(vm, eta, k) * (G * vm / (cv * cm));
}

/* the material interface (v = -wo) */
inline float3 rough_conductor_eval(__global const Material* mat, float3 albedo, float3 n,
                                   float3 wo, float3 l, float* pdf)
{
    return beckmann_conductor_eval(albedo, mat->eta.xyz, mat->k.xyz, mat->roughness, n, -wo,
                                   l, pdf);
}

inline float3 rough_conductor_sample(__global const Material* mat, float3 albedo, float3 n,
                                     float3 wo, float2 u, float3* l, float* pdf)
{
    return beckmann_conductor_sample(albedo, mat->eta.xyz, mat->k.xyz, mat->roughness, n,
                                     -wo, u, l, pdf);
}
