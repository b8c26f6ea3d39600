/* A spherical area light, p0 = (centre, radius), sampled by the cone it subtends
 * (light interface: lights.h). */

/* 1 - cos of the half-angle of the cone a sphere of radius r subtends at distance^2 d2
 * (> r^2): 1 - sqrt(1 - s) = s / (1 + sqrt(1 - s)) with s = r^2 / d2, no cancellation. */
inline float sphere_cone_omc(float r, float d2)
{
    float s = fmin(r * r / d2, 1.0f);
    return s / (1.0f + sqrt(1.0f - s));
}

inline float3 sphere_sample(__global const Light* l, EnvMap m, float3 x, float2 u,
                            float3* wi, float* dist, float* pdf)
{
    *dist = T_INFINITY;
    *pdf = 0.0f;
    float3 oc = l->p0.xyz - x;
    float d2 = dot(oc, oc), r = l->p0.w;
    if (d2 <= r * r) return (float3)(0.0f);  /* inside the light: no sample */
    float omc = sphere_cone_omc(r, d2);
    float3 axis = oc / sqrt(d2);
    *wi = uniform_cone(u, axis, omc);
    /* distance to the near intersection with the sphere */
    float b = dot(oc, *wi);
    *dist = b - sqrt(fmax(0.0f, b * b - d2 + r * r));
    *pdf = cone_pdf(omc);
    return l->radiance.xyz;
}

inline float3 sphere_area_radiance(__global const Light* l, float3 from, float3 x, float3 n,
                                   float3 d, float* pdf)
{
    *pdf = 0.0f;
    float cos_l = -dot(n, d);
    float3 oc = l->p0.xyz - from;
    float d2 = dot(oc, oc), r = l->p0.w;
    if (d2 > r * r) *pdf = cone_pdf(sphere_cone_omc(r, d2));
    return (cos_l > 0.0f) ? l->radiance.xyz : (float3)(0.0f);
}

/* uniform over the whole sphere: a manifold NEE point (lib/caustics.h) may see any of it */
inline void sphere_sample_point(__global const Light* l, float2 u, float3* y, float3* n,
                                float* pdf_area)
{
    float z = 1.0f - 2.0f * u.x, s = sqrt(fmax(0.0f, 1.0f - z * z));
    float phi = 2.0f * PI_F * u.y;
    float r = l->p0.w;
    *n = (float3)(s * cos(phi), s * sin(phi), z);
    *y = l->p0.xyz + r * *n;
    *pdf_area = 1.0f / (4.0f * PI_F * r * r);
}
