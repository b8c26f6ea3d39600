/* Light sampling and evaluation. All pdfs are per unit solid angle at the receiving
 * point; delta lights (point, zero-radius sun) return pdf 0 and are never hit.
 *
 * Light records (see layouts.LIGHT):
 *   environment      radiance
 *   environment_map  radiance = scale, p0.x = rotation about +y (radians)
 *   point            radiance = intensity, p0 = position
 *   sphere           radiance, p0 = (centre, radius)
 *   rectangle        radiance, p0 = corner, p1/p2 = edges, p2.w = 1 if two-sided; area
 *   directional      radiance (in-cone radiance, or irradiance if delta), p0.xyz = unit
 *                    direction towards the light, p0.w = 1 - cos(angular radius), 0 if
 *                    delta (given as 2 sin^2(radius / 2): a float32 cos of a 0.1 degree
 *                    sun keeps one digit of 1 - cos, which made it 1.75 % too bright)
 *
 * Cones are described by 1 - cos(half-angle) throughout, for the same reason. */

typedef struct {
    __global const float4* texels;   /* H*W radiance */
    __global const float* marginal;  /* H+1 */
    __global const float* conditional; /* H*(W+1) */
    int width, height;
} EnvMap;

inline float3 uniform_sphere(float2 u)
{
    float z = 1.0f - 2.0f * u.x;
    float r = sqrt(fmax(0.0f, 1.0f - z * z));
    float phi = 2.0f * PI_F * u.y;
    return (float3)(r * cos(phi), r * sin(phi), z);
}

/* Direction in a cone around axis with 1 - cos(half-angle) = omc, uniform in solid angle.
 * h = 1 - cos(t) is uniform in [0, omc]; sin(t) = sqrt(h (2 - h)) keeps its digits where
 * sqrt(1 - cos^2) would not. */
inline float3 uniform_cone(float2 u, float3 axis, float omc)
{
    float h = u.x * omc;
    float cos_t = 1.0f - h;
    float sin_t = sqrt(fmax(0.0f, h * (2.0f - h)));
    float phi = 2.0f * PI_F * u.y;
    float3 t, b;
    make_frame(axis, &t, &b);
    return normalize(sin_t * cos(phi) * t + sin_t * sin(phi) * b + cos_t * axis);
}

inline float cone_pdf(float omc) { return 1.0f / (2.0f * PI_F * omc); }

/* 1 - cos of the half-angle of the cone a sphere of radius r subtends at distance^2 d2
 * (> r^2): 1 - sqrt(1 - s) = s / (1 + sqrt(1 - s)) with s = r^2 / d2, no cancellation. */
inline float sphere_cone_omc(float r, float d2)
{
    float s = fmin(r * r / d2, 1.0f);
    return s / (1.0f + sqrt(1.0f - s));
}

/* Is unit d inside the cone around unit axis with 1 - cos(half-angle) = omc?
 * |d - axis|^2 = 2 (1 - cos), which float32 resolves for tiny cones; a dot does not. */
inline bool in_cone(float3 d, float3 axis, float omc)
{
    float3 e = d - axis;
    return dot(e, e) <= 2.0f * omc;
}

/* --- environment map: lat-long, theta from +y, phi = atan2(z, x) (gpiscl/host/compile/envmap.py) */

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

/* --- radiance arriving along an escaped ray, and its light-sampling pdf ------------- */

inline float3 infinite_light_radiance(__global const Light* l, EnvMap m, float3 d, float* pdf)
{
    *pdf = 0.0f;
    if (l->kind == LIGHT_ENVIRONMENT) {
        *pdf = 1.0f / (4.0f * PI_F);
        return l->radiance.xyz;
    }
    if (l->kind == LIGHT_ENVIRONMENT_MAP) {
        float3 dm = env_to_map(d, l->p0.x);
        float s; int row, col;
        int idx = env_pixel(m, dm, &s, &row, &col);
        *pdf = env_pdf(m, dm);
        return l->radiance.xyz * m.texels[idx].xyz;
    }
    if (l->kind == LIGHT_DIRECTIONAL && l->p0.w > 0.0f) {
        if (in_cone(d, l->p0.xyz, l->p0.w)) {
            *pdf = cone_pdf(l->p0.w);
            return l->radiance.xyz;
        }
    }
    return (float3)(0.0f);
}

/* Radiance leaving an area light's surface point x towards -d, seen from `from`,
 * and the solid-angle pdf with which sample_light would have chosen it. */
inline float3 area_light_radiance(__global const Light* l, float3 from, float3 x, float3 n,
                                  float3 d, float* pdf)
{
    *pdf = 0.0f;
    float cos_l = -dot(n, d);
    if (l->kind == LIGHT_SPHERE) {
        float3 oc = l->p0.xyz - from;
        float d2 = dot(oc, oc), r = l->p0.w;
        if (d2 > r * r) *pdf = cone_pdf(sphere_cone_omc(r, d2));
        return (cos_l > 0.0f) ? l->radiance.xyz : (float3)(0.0f);
    }
    if (l->kind == LIGHT_RECTANGLE) {
        if (cos_l <= 0.0f && l->p2.w == 0.0f) return (float3)(0.0f);
        float3 v = x - from;
        *pdf = dot(v, v) / (l->area * fabs(cos_l));
        return l->radiance.xyz;
    }
    return (float3)(0.0f);
}

/* Sample incident light at point x. Returns radiance (or intensity/irradiance for
 * delta lights); wi is the unit direction to the light, dist the distance (T_INFINITY
 * for lights at infinity), pdf the solid-angle pdf (0 marks a delta light). */
inline float3 sample_light(__global const Light* l, EnvMap m, float3 x, float2 u,
                           float3* wi, float* dist, float* pdf)
{
    *dist = T_INFINITY;
    *pdf = 0.0f;
    if (l->kind == LIGHT_ENVIRONMENT) {
        *wi = uniform_sphere(u);
        *pdf = 1.0f / (4.0f * PI_F);
        return l->radiance.xyz;
    }
    if (l->kind == LIGHT_ENVIRONMENT_MAP) {
        float3 dm = env_sample(m, u, pdf);
        *wi = env_from_map(dm, l->p0.x);
        float s; int row, col;
        return l->radiance.xyz * m.texels[env_pixel(m, dm, &s, &row, &col)].xyz;
    }
    if (l->kind == LIGHT_POINT) {
        float3 v = l->p0.xyz - x;
        float d2 = dot(v, v);
        *dist = sqrt(d2);
        *wi = v / *dist;
        return l->radiance.xyz / d2;
    }
    if (l->kind == LIGHT_DIRECTIONAL) {
        if (l->p0.w <= 0.0f) {
            *wi = l->p0.xyz;
            return l->radiance.xyz;
        }
        *wi = uniform_cone(u, l->p0.xyz, l->p0.w);
        *pdf = cone_pdf(l->p0.w);
        return l->radiance.xyz;
    }
    if (l->kind == LIGHT_SPHERE) {
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
    /* rectangle */
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
