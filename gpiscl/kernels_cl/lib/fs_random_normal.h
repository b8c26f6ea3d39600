/* A micro-BSDF at a normal drawn from the GP's law: how next-event estimation and MIS
 * use a function-space GPIS hit's normal law (fs_normal_pdf.h) for a material kind. The
 * kind's trait random_normal (gpiscl/host/kinds/materials.py) picks the mode:
 *   RANDOM_NORMAL_SAMPLED      the BSDF at the sampled normal, as on any surface;
 *   RANDOM_NORMAL_HALF_VECTOR  a delta reflector gets the direction density of the
 *                              normal through the half vector (fs_mirror_pdf), hence NEE
 *                              and MIS; its light sampling leaves environments to BSDF
 *                              sampling, which keeps its white furnace exactly 1 per path;
 *   RANDOM_NORMAL_PAIRS        a lobe about the normal (a Beckmann of alpha = the
 *                              material's roughness): NEE samples (normal, light) pairs by
 *                              strategies A and B (fs_normal_pdf.h), C is BSDF sampling.
 * Weight space has no such law (the realization fixes the normal), and neither has a
 * function-space hit whose sampler reports none: both are mode SAMPLED. */

inline int fs_random_normal_mode(int kind, int fs_hit)
{
    return fs_hit ? MATERIAL_RANDOM_NORMAL(kind) : RANDOM_NORMAL_SAMPLED;
}

/* whether the vertex gets next-event estimation: a density for the light's direction */
inline int fs_random_normal_has_density(int kind, int mode)
{
    return !MATERIAL_IS_DELTA(kind) || mode != RANDOM_NORMAL_SAMPLED;
}

/* whether the vertex's light sampling covers environment lights too */
inline int fs_random_normal_env_nee(int mode) { return mode != RANDOM_NORMAL_HALF_VECTOR; }

/* f |cos| and density of light direction wl; grad: the gradient a light-picked normal
 * implies, which the shadow ray conditions on (left alone for the sampled normal) */
inline float3 fs_random_normal_eval(int mode, __global const Material* mat, FsNormalLaw law,
                                    float3 albedo, float3 n, float3 wo, float3 wl,
                                    float* pdf_f, float4* grad)
{
    if (mode == RANDOM_NORMAL_HALF_VECTOR) {
        /* the light sample picks the normal: the half vector h, where the delta
         * reflector's own sample gives its reflectance (a mirror's Fresnel term) */
        float3 h, l;
        float pdf_delta;
        *pdf_f = fs_mirror_pdf(law, wo, wl, &h);
        if (!(*pdf_f > 0.0f)) return (float3)(0.0f);
        *grad = (float4)(fs_implied_gradient(law, wo, h), 1.0f);
        return material_sample(mat->kind, mat, albedo, h, wo, (float2)(0.0f), &l, &pdf_delta)
               * *pdf_f;
    }
    return material_eval(mat->kind, mat, albedo, n, wo, wl, pdf_f);
}

/* Russian roulette on a light sample's shadow ray where the light sample picks the normal
 * (modes HALF_VECTOR and PAIRS): that ray is a function-space flight through the GPIS,
 * and with normals spread by a few degrees most light samples carry a tiny weight. The
 * ray survives with q = min(1, |c| / (t |c_ref|)) and then carries c / q (unbiased);
 * c_ref is the same light sample at a white Lambertian vertex facing the light (the path's
 * throughput times Le / (pi p_L sel)), the scale of the pixels this light makes: a ray
 * that may be lost adds c (t |c_ref| - c) <= (t |c_ref|)^2 / 4 to its pixel's variance,
 * small beside theirs. t <= 0 turns it off; docs/design/light-sampling.md measures t. */
inline float fs_random_normal_shadow_survival(int mode, float3 c, float3 c_ref, float t)
{
    if (mode == RANDOM_NORMAL_SAMPLED || !(t > 0.0f)) return 1.0f;
    return fmin(1.0f, max3(c) / (t * max3(c_ref)));
}

/* RANDOM_NORMAL_PAIRS with a light of density pl (> 0, per light and already divided by
 * the light count): strategy A (the sampled normal) or B (a normal about the half vector),
 * each with probability 1/2; all densities relative to the light's, i.e.
 * p_AB / p_L = (p_Omega(nn) + q(nn | l)) / 2. Returns F / p_AB with F = p_Omega(nn) fcos;
 * w is its MIS weight from p_AB against p_C = p_Omega(nn) p_c(l | nn). */
inline float3 fs_random_normal_pairs(__global const Material* mat, FsNormalLaw law,
                                     float3 albedo, float3 n, float3 wo, float3 wl, float pl,
                                     float u_strategy, float2 u_normal, float* pdf_f,
                                     float4* grad, float* w)
{
    float3 v = -wo, h = normalize(v + wl), nn = n;
    if (u_strategy >= 0.5f) {
        nn = fs_lobe_normal_sample(h, mat->roughness, u_normal);
        if (dot(nn, wo) < 0.0f)
            *grad = (float4)(fs_implied_gradient(law, wo, nn), 1.0f);
    }
    float p_nn = fs_normal_pdf(law, wo, nn);
    float3 f = material_eval(mat->kind, mat, albedo, nn, wo, wl, pdf_f);
    float p_ab = 0.5f * (p_nn + fs_lobe_normal_pdf(nn, h, mat->roughness));
    *w = (p_ab > 0.0f) ? power_heuristic(pl * p_ab, p_nn * *pdf_f) : 0.0f;
    f *= (p_ab > 0.0f) ? p_nn / p_ab : 0.0f;
    return f;
}

/* The BSDF-sampled continuation: the kind's sample at the sampled normal; a half-vector
 * kind's direction gets the law's density for MIS (FLT_MIN where it underflows: there
 * light sampling takes it all); a pairs kind records p_Omega(n0) for strategy C's MIS
 * weight at a light (fs_conductor_light_pdf). */
inline float3 fs_random_normal_sample(int mode, __global const Material* mat, FsNormalLaw law,
                                      float3 albedo, float3 n, float3 wo, float2 u,
                                      float3* wi, float* pdf, float* p_n0)
{
    float3 weight = material_sample(mat->kind, mat, albedo, n, wo, u, wi, pdf);
    if (mode == RANDOM_NORMAL_HALF_VECTOR) {
        float3 h;
        *pdf = fmax(fs_mirror_pdf(law, wo, *wi, &h), FLT_MIN);
    }
    if (mode == RANDOM_NORMAL_PAIRS) *p_n0 = fmax(fs_normal_pdf(law, wo, n), FLT_MIN);
    return weight;
}
