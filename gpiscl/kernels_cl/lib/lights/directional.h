/* A light at infinity in the cone about p0.xyz with 1 - cos(radius) = p0.w: a sun of
 * uniform in-cone radiance, or a delta light of irradiance `radiance` when p0.w = 0
 * (light interface: lights.h). */

inline float3 directional_sample(__global const Light* l, EnvMap m, float3 x, float2 u,
                                 float3* wi, float* dist, float* pdf)
{
    *dist = T_INFINITY;
    *pdf = 0.0f;
    if (l->p0.w <= 0.0f) {
        *wi = l->p0.xyz;
        return l->radiance.xyz;
    }
    *wi = uniform_cone(u, l->p0.xyz, l->p0.w);
    *pdf = cone_pdf(l->p0.w);
    return l->radiance.xyz;
}

inline float3 directional_radiance(__global const Light* l, EnvMap m, float3 d, float* pdf)
{
    *pdf = 0.0f;
    if (l->p0.w > 0.0f) {
        if (in_cone(d, l->p0.xyz, l->p0.w)) {
            *pdf = cone_pdf(l->p0.w);
            return l->radiance.xyz;
        }
    }
    return (float3)(0.0f);
}
