/* Vendor quirks and numeric constants in one place. */
#pragma OPENCL EXTENSION cl_khr_fp64 : enable

#define PI_F 3.14159265358979f
#define INV_PI_F 0.318309886183791f
#define T_INFINITY 1e30f

/* Ray origins are pushed off surfaces by this fraction of their distance from the
 * world origin (plus an absolute floor), so float32 rounding never self-intersects. */
#define RAY_EPSILON_REL 2e-5f
#define RAY_EPSILON_ABS 1e-4f

inline float ray_epsilon(float3 p)
{
    return RAY_EPSILON_ABS + RAY_EPSILON_REL * fmax(fabs(p.x), fmax(fabs(p.y), fabs(p.z)));
}

inline float max3(float3 v) { return fmax(v.x, fmax(v.y, v.z)); }

inline int is_finite3(float3 v) { return isfinite(v.x) && isfinite(v.y) && isfinite(v.z); }

/* Orthonormal basis around a unit normal (Duff et al. 2017), branch-free. */
inline void make_frame(float3 n, float3* t, float3* b)
{
    float sign = copysign(1.0f, n.z);
    float a = -1.0f / (sign + n.z);
    float c = n.x * n.y * a;
    *t = (float3)(1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x);
    *b = (float3)(c, sign + n.y * n.y * a, -n.y);
}

inline float power_heuristic(float pdf_a, float pdf_b)
{
    /* as 1 / (1 + (b / a)^2): the squares of tiny or huge densities under- or overflow
     * (a function-space mirror's pdf near FLT_MIN squared to 0, and 0 / 0 made 2-40 paths
     * in 6e4 NaN at emission.cl under a small light) */
    if (!(pdf_a > 0.0f)) return 0.0f;
    float r = pdf_b / pdf_a;
    return isnan(r) ? 0.5f : 1.0f / (1.0f + r * r);
}
