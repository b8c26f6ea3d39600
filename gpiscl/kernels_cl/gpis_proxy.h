/* GPIS proxies are analytic (box or sphere) and clipped here, not traced in the BVH:
 * a GPIS stage needs the interval a ray spends inside, not a surface to shade. */

/* Clip [t0, t1] to the part of the ray inside the proxy; false if empty. */
inline int gpis_proxy_clip(__global const GpisObject* g, float3 o, float3 d, float* t0,
                           float* t1)
{
    float enter, leave;
    if (g->proxy_kind == GPIS_PROXY_BOX) {
        float3 inv = 1.0f / d;
        float3 a = (g->proxy_p0.xyz - o) * inv, b = (g->proxy_p1.xyz - o) * inv;
        float3 lo = fmin(a, b), hi = fmax(a, b);
        enter = max3(lo);
        leave = fmin(hi.x, fmin(hi.y, hi.z));
    } else {
        float3 oc = o - g->proxy_p0.xyz;
        float r = g->proxy_p0.w;
        float b = dot(oc, d), c = dot(oc, oc) - r * r;
        float disc = b * b - c;
        if (disc < 0.0f) return 0;
        float s = sqrt(disc);
        enter = -b - s;
        leave = -b + s;
    }
    *t0 = fmax(*t0, enter);
    *t1 = fmin(*t1, leave);
    return *t0 < *t1;
}

/* The realization a path sees: its own (pixel, sample) mixed with the seed, or one fixed
 * realization R for every path. The top bit stays clear for path keys, so they never
 * equal the fixed key (R, 0xffffffff). */
inline uint2 gpis_realization_key(__constant RenderParams* params, int pixel, int sample)
{
    if (params->realization >= 0) return (uint2)((uint)params->realization, 0xffffffffu);
    return (uint2)((uint)pixel, ((uint)sample ^ (params->seed * 0x9e3779b9u)) & 0x7fffffffu);
}
