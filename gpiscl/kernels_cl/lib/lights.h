/* What every light kind shares (the kinds themselves: lights/<name>.h, one file each,
 * declared in gpiscl/host/kinds/lights.py, which generates the light_* dispatch).
 * All pdfs are per unit solid angle at the receiving point; delta lights (point,
 * zero-radius sun) return pdf 0 and are never hit. The light interface:
 *   <kind>_sample(l, m, x, u, &wi, &dist, &pdf)   every kind: radiance (intensity or
 *       irradiance for delta lights) arriving at x from direction wi, dist the distance
 *       (T_INFINITY at infinity), pdf the solid-angle density (0: a delta light)
 *   <kind>_radiance(l, m, d, &pdf)   kinds at_infinity: radiance along an escaped ray d
 *   <kind>_area_radiance(l, from, x, n, d, &pdf)   area kinds: radiance leaving surface
 *       point x (normal n) towards -d, seen from `from`
 *   <kind>_sample_point(l, u, &y, &n, &pdf_area)   area kinds: a point y of the light with
 *       its unit normal n, by a density per unit area (the manifold NEE, caustics.h)
 *
 * Each kind's file says what its Light record's fields mean. Cones are described by
 * 1 - cos(half-angle) throughout: a float32 cos of a 0.1 degree sun keeps one digit of
 * 1 - cos, which made it visibly too bright (docs/design/light-sampling.md, 'Cones');
 * kinds/lights.py packs it as 2 sin^2(r / 2). */

typedef struct {
    __global const float4* texels;   /* H*W radiance */
    __global const float* marginal;  /* H+1 */
    __global const float* conditional; /* H*(W+1) */
    int width, height;
} EnvMap;

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

/* Is unit d inside the cone around unit axis with 1 - cos(half-angle) = omc?
 * |d - axis|^2 = 2 (1 - cos), which float32 resolves for tiny cones; a dot does not. */
inline bool in_cone(float3 d, float3 axis, float omc)
{
    float3 e = d - axis;
    return dot(e, e) <= 2.0f * omc;
}


/* The light next-event estimation picks, by the scene's alias table (LightChoice records,
 * gpiscl/host/compile/light_selection.py): light i with probability choice[i].pmf, in
 * proportion to its power estimate; u uniform in [0, 1). */
inline int light_choose(__global const LightChoice* choice, int n, float u)
{
    float s = u * n;
    int i = min((int)s, n - 1);
    return (s - i < choice[i].threshold) ? i : choice[i].alias;
}

/* How a vertex's light sampling treats environments (path_prev_env_nee, so that an
 * escaped ray's MIS weight uses the density NEE used): left to BSDF sampling; sampled
 * by the kind's own density; or, a constant environment at a vertex whose BSDF vanishes
 * below its normal (path_prev_n), by the cosine-weighted hemisphere about that normal
 * (environment_sample_above, lights/environment.h). */
#define ENV_NEE_NONE 0
#define ENV_NEE_OWN 1
#define ENV_NEE_ABOVE 2

/* The choice table of a vertex (light_selection.py): n records for vertices whose BSDF
 * lobe is wide, then n for those that leave environments to BSDF sampling (ENV_NEE_NONE:
 * a function-space mirror, whose lobe is narrow, so that BSDF sampling already finds the
 * wide lights and its light samples go to the small ones). */
inline __global const LightChoice* light_choice_at(__global const LightChoice* choice, int n,
                                                   int env_nee)
{
    return choice + ((env_nee == ENV_NEE_NONE) ? n : 0);
}
