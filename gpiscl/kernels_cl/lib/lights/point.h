/* A point light of intensity `radiance` at p0 (a delta light; interface: lights.h). */

inline float3 point_sample(__global const Light* l, EnvMap m, float3 x, float2 u, float3* wi,
                           float* dist, float* pdf)
{
    *pdf = 0.0f;
    float3 v = l->p0.xyz - x;
    float d2 = dot(v, v);
    *dist = sqrt(d2);
    *wi = v / *dist;
    return l->radiance.xyz / d2;
}
