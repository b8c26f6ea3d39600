/* A toy material kind (tests/test_kinds_materials.py, docs/extending.md): a diffuse BSDF
 * whose albedo is the material's tint, as one file would add any micro-BSDF. The
 * material interface: kernels_cl/lib/bsdf/diffuse.h. */

inline float3 tinted_diffuse_eval(__global const Material* mat, float3 albedo, float3 n,
                                  float3 wo, float3 l, float* pdf)
{
    float c = fmax(dot(n, l), 0.0f);
    *pdf = c * INV_PI_F;
    return albedo * (c * INV_PI_F);
}

inline float3 tinted_diffuse_sample(__global const Material* mat, float3 albedo, float3 n,
                                    float3 wo, float2 u, float3* l, float* pdf)
{
    *l = cosine_hemisphere(u, n, pdf);
    return albedo;
}
