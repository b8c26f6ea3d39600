/* Surface BSDFs. Diffuse and mirror are two-sided: the shading normal is flipped to
 * the side the ray arrives from. The mirror is a delta BSDF (pdf 0 marks it). */

inline float3 cosine_hemisphere(float2 u, float3 n, float* pdf)
{
    float r = sqrt(u.x), phi = 2.0f * PI_F * u.y;
    float z = sqrt(fmax(0.0f, 1.0f - u.x));
    float3 t, b;
    make_frame(n, &t, &b);
    *pdf = z * INV_PI_F;
    return normalize(r * cos(phi) * t + r * sin(phi) * b + z * n);
}

/* f(wi) * |cos| for a diffuse surface with normal n on the side of wo. */
inline float3 diffuse_eval(float3 albedo, float3 n, float3 wi, float* pdf)
{
    float c = dot(n, wi);
    *pdf = fmax(c, 0.0f) * INV_PI_F;
    return albedo * (fmax(c, 0.0f) * INV_PI_F);
}
