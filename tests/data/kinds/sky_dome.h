/* A toy light kind (tests/test_kinds_materials.py, docs/extending.md): uniform radiance
 * from the upper hemisphere (d.y > 0), black below; at infinity, sampled uniformly over
 * the dome. The light interface: kernels_cl/lib/lights.h. */

inline float3 sky_dome_sample(__global const Light* l, EnvMap m, float3 x, float2 u,
                              float3* wi, float* dist, float* pdf)
{
    float y = u.x, r = sqrt(fmax(0.0f, 1.0f - y * y)), phi = 2.0f * PI_F * u.y;
    *wi = (float3)(r * cos(phi), y, r * sin(phi));
    *dist = T_INFINITY;
    *pdf = 1.0f / (2.0f * PI_F);
    return l->radiance.xyz;
}

inline float3 sky_dome_radiance(__global const Light* l, EnvMap m, float3 d, float* pdf)
{
    *pdf = d.y > 0.0f ? 1.0f / (2.0f * PI_F) : 0.0f;
    return d.y > 0.0f ? l->radiance.xyz : (float3)(0.0f);
}
