/* A rectangular area light: corner p0, edges p1 and p2, p2.w = 1 if two-sided, sampled
 * uniformly by area (light interface: lights.h). */

inline float3 rectangle_sample(__global const Light* l, EnvMap m, float3 x, float2 u,
                               float3* wi, float* dist, float* pdf)
{
    *pdf = 0.0f;
    float3 p = l->p0.xyz + u.x * l->p1.xyz + u.y * l->p2.xyz;
    float3 n = normalize(cross(l->p1.xyz, l->p2.xyz));
    float3 v = p - x;
    float d2 = dot(v, v);
    *dist = sqrt(d2);
    *wi = v / *dist;
    float cos_l = -dot(n, *wi);
    if (cos_l <= 0.0f && l->p2.w == 0.0f) return (float3)(0.0f);
    *pdf = d2 / (l->area * fabs(cos_l));
    return l->radiance.xyz;
}

inline float3 rectangle_area_radiance(__global const Light* l, float3 from, float3 x,
                                      float3 n, float3 d, float* pdf)
{
    *pdf = 0.0f;
    float cos_l = -dot(n, d);
    if (cos_l <= 0.0f && l->p2.w == 0.0f) return (float3)(0.0f);
    float3 v = x - from;
    *pdf = dot(v, v) / (l->area * fabs(cos_l));
    return l->radiance.xyz;
}

inline void rectangle_sample_point(__global const Light* l, float2 u, float3* y, float3* n,
                                   float* pdf_area)
{
    *y = l->p0.xyz + u.x * l->p1.xyz + u.y * l->p2.xyz;
    *n = normalize(cross(l->p1.xyz, l->p2.xyz));
    *pdf_area = 1.0f / l->area;
}
