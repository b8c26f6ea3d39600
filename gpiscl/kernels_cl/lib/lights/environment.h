/* A uniform environment: radiance from every direction (light interface: lights.h). */

inline float3 uniform_sphere(float2 u)
{
    float z = 1.0f - 2.0f * u.x;
    float r = sqrt(fmax(0.0f, 1.0f - z * z));
    float phi = 2.0f * PI_F * u.y;
    return (float3)(r * cos(phi), r * sin(phi), z);
}

inline float3 environment_sample(__global const Light* l, EnvMap m, float3 x, float2 u,
                                 float3* wi, float* dist, float* pdf)
{
    *dist = T_INFINITY;
    *wi = uniform_sphere(u);
    *pdf = 1.0f / (4.0f * PI_F);
    return l->radiance.xyz;
}

inline float3 environment_radiance(__global const Light* l, EnvMap m, float3 d, float* pdf)
{
    *pdf = 1.0f / (4.0f * PI_F);
    return l->radiance.xyz;
}

/* At a vertex whose BSDF vanishes below its normal n (ENV_NEE_ABOVE, lights.h): the
 * cosine-weighted hemisphere about n. Half the uniform sphere's samples would fall below
 * the surface; this density spends none there and, for a diffuse BSDF, follows f |cos|
 * exactly (docs/design/light-sampling.md). */
inline float environment_pdf_above(float3 n, float3 d)
{
    return fmax(dot(n, d), 0.0f) * INV_PI_F;
}

inline float3 environment_sample_above(__global const Light* l, float3 n, float2 u,
                                       float3* wi, float* dist, float* pdf)
{
    float r = sqrt(u.x), phi = 2.0f * PI_F * u.y;
    float z = sqrt(fmax(0.0f, 1.0f - u.x));
    float3 t, b;
    make_frame(n, &t, &b);
    *wi = normalize(r * cos(phi) * t + r * sin(phi) * b + z * n);
    *dist = T_INFINITY;
    *pdf = environment_pdf_above(n, *wi);
    return (*pdf > 0.0f) ? l->radiance.xyz : (float3)(0.0f);
}
