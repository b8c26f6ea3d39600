/* A lat-long environment map times a scale, rotated about +y by p0.x (light interface:
 * lights.h); its importance-sampling tables come from gpiscl/host/compile/envmap.py. */

/* lat-long: theta from +y, phi = atan2(z, x) */
inline float3 env_to_map(float3 d, float rot)
{
    float c = cos(rot), s = sin(rot);
    return (float3)(c * d.x + s * d.z, d.y, -s * d.x + c * d.z);
}

inline float3 env_from_map(float3 d, float rot) { return env_to_map(d, -rot); }

inline int env_pixel(EnvMap m, float3 dm, float* sin_theta, int* row, int* col)
{
    float theta = acos(clamp(dm.y, -1.0f, 1.0f));
    float phi = atan2(dm.z, dm.x);
    if (phi < 0.0f) phi += 2.0f * PI_F;
    *row = clamp((int)(theta * INV_PI_F * m.height), 0, m.height - 1);
    *col = clamp((int)(phi * 0.5f * INV_PI_F * m.width), 0, m.width - 1);
    *sin_theta = sin(theta);
    return (*row) * m.width + (*col);
}

inline float env_pixel_prob(EnvMap m, int row, int col)
{
    __global const float* c = m.conditional + row * (m.width + 1);
    return (m.marginal[row + 1] - m.marginal[row]) * (c[col + 1] - c[col]);
}

inline float env_pdf(EnvMap m, float3 dm)
{
    float s; int row, col;
    env_pixel(m, dm, &s, &row, &col);
    if (s <= 0.0f) return 0.0f;
    return env_pixel_prob(m, row, col) * m.width * m.height / (2.0f * PI_F * PI_F * s);
}

/* Largest index i in [0, n) with cdf[i] <= u (cdf has n+1 entries from 0 to 1). */
inline int cdf_search(__global const float* cdf, int n, float u, float* frac)
{
    int lo = 0, hi = n;
    while (hi - lo > 1) {
        int mid = (lo + hi) / 2;
        if (cdf[mid] <= u) lo = mid; else hi = mid;
    }
    float w = cdf[lo + 1] - cdf[lo];
    *frac = (w > 0.0f) ? clamp((u - cdf[lo]) / w, 0.0f, 1.0f) : 0.5f;
    return lo;
}

inline float3 env_sample(EnvMap m, float2 u, float* pdf)
{
    float fr, fc;
    int row = cdf_search(m.marginal, m.height, u.x, &fr);
    int col = cdf_search(m.conditional + row * (m.width + 1), m.width, u.y, &fc);
    float theta = PI_F * (row + fr) / m.height;
    float phi = 2.0f * PI_F * (col + fc) / m.width;
    float s = sin(theta);
    *pdf = (s > 0.0f) ? env_pixel_prob(m, row, col) * m.width * m.height
                        / (2.0f * PI_F * PI_F * s) : 0.0f;
    return (float3)(s * cos(phi), cos(theta), s * sin(phi));
}

inline float3 environment_map_sample(__global const Light* l, EnvMap m, float3 x, float2 u,
                                     float3* wi, float* dist, float* pdf)
{
    *dist = T_INFINITY;
    float3 dm = env_sample(m, u, pdf);
    *wi = env_from_map(dm, l->p0.x);
    float s; int row, col;
    return l->radiance.xyz * m.texels[env_pixel(m, dm, &s, &row, &col)].xyz;
}

inline float3 environment_map_radiance(__global const Light* l, EnvMap m, float3 d,
                                       float* pdf)
{
    float3 dm = env_to_map(d, l->p0.x);
    float s; int row, col;
    int idx = env_pixel(m, dm, &s, &row, &col);
    *pdf = env_pdf(m, dm);
    return l->radiance.xyz * m.texels[idx].xyz;
}
