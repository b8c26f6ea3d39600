/* Mirror: a delta BSDF, two-sided (material interface: bsdf/diffuse.h). With a conductor
 * (mat->fresnel) it reflects F(cos) of mat->eta + i mat->k (bsdf/fresnel.h), else all of
 * the albedo. At a function-space GPIS hit its random normal gives it a density instead
 * (fs_random_normal.h, trait random_normal = half_vector), which takes the reflectance
 * from mirror_sample at the half vector. */

inline float3 mirror_eval(__global const Material* mat, float3 albedo, float3 n, float3 wo,
                          float3 l, float* pdf)
{
    *pdf = 0.0f;
    return (float3)(0.0f);
}

inline float3 mirror_sample(__global const Material* mat, float3 albedo, float3 n,
                            float3 wo, float2 u, float3* l, float* pdf)
{
    *l = wo - 2.0f * dot(wo, n) * n;
    *pdf = 0.0f;
    if (mat->fresnel) return albedo * fresnel_conductor(-dot(wo, n), mat->eta.xyz, mat->k.xyz);
    return albedo;
}
