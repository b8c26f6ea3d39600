/* Diffuse (Lambertian) BSDF, two-sided: n is the shading normal on the side of wo.
 * The material interface every non-pass-through kind implements (the generated
 * material_eval / material_sample dispatch calls it; docs/extending.md):
 *   <kind>_eval(mat, albedo, n, wo, l, &pdf)    f(l) |cos| and the sampling pdf of l
 *   <kind>_sample(mat, albedo, n, wo, u, &l, &pdf)  l ~ pdf, returns f |cos| / pdf
 * wo is the incoming ray direction (towards the surface), albedo the material's albedo
 * times the object's colour field; pdf 0 marks a delta direction. */

inline float3 cosine_hemisphere(float2 u, float3 n, float* pdf)
{
    float r = sqrt(u.x), phi = 2.0f * PI_F * u.y;
    float z = sqrt(fmax(0.0f, 1.0f - u.x));
    float3 t, b;
    make_frame(n, &t, &b);
    *pdf = z * INV_PI_F;
    return normalize(r * cos(phi) * t + r * sin(phi) * b + z * n);
}

inline float3 diffuse_eval(__global const Material* mat, float3 albedo, float3 n, float3 wo,
                           float3 l, float* pdf)
{
    float c = dot(n, l);
    *pdf = fmax(c, 0.0f) * INV_PI_F;
    return albedo * (fmax(c, 0.0f) * INV_PI_F);
}

/* cosine-weighted: f cos / pdf = albedo */
inline float3 diffuse_sample(__global const Material* mat, float3 albedo, float3 n,
                             float3 wo, float2 u, float3* l, float* pdf)
{
    *l = cosine_hemisphere(u, n, pdf);
    return albedo;
}
