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
