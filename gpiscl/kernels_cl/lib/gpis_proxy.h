/* GPIS proxies (box, sphere, convex mesh) are clipped here, not traced in the BVH: a GPIS
 * stage needs the interval a ray spends inside, not a surface to shade. */

/* The GPIS objects' side tables, which GpisObject indexes (layout/stages.py GPIS_TABLES) */
typedef struct {
    __global const float4* planes;      /* mesh proxies' face planes */
    __global const FsObs* obs;          /* posteriors' observations */
    __global const double* doubles;     /* posteriors' alpha, factor and noise */
    __global const uint* occ_cells;     /* occupancy cell masks, OCC_WORDS an object */
} GpisTables;

/* The struct made of the tables' stage kernel parameters */
#define GPIS_TABLES {proxy_planes, posterior_obs, posterior_doubles, occupancy_cells}

/* Where the ray o + t d enters and leaves the box [lo, hi] (slabs; either may be
 * infinite): the box proxies and the occupancy boxes. */
inline void gpis_slab(float3 lo, float3 hi, float3 o, float3 d, float* enter, float* leave)
{
    float3 inv = 1.0f / d;
    float3 a = (lo - o) * inv, b = (hi - o) * inv;
    float3 near = fmin(a, b), far = fmax(a, b);
    *enter = max3(near);
    *leave = fmin(far.x, fmin(far.y, far.z));
}

/* Clip [t0, t1] to the part of the ray inside the proxy; false if empty. A mesh proxy's
 * face planes (n, w: inside where n.x <= w) are all_planes[g->proxy_first] on
 * (scene/proxies.py). */
inline int gpis_proxy_clip(__global const GpisObject* g, __global const float4* all_planes,
                           float3 o, float3 d, float* t0, float* t1)
{
    float enter, leave;
    if (g->proxy_kind == GPIS_PROXY_MESH) {
        __global const float4* planes = all_planes + g->proxy_first;
        enter = -T_INFINITY;
        leave = T_INFINITY;
        for (int j = 0; j < g->proxy_count; ++j) {
            float4 p = planes[j];
            float dn = dot(p.xyz, d), gap = p.w - dot(p.xyz, o);
            if (dn > 0.0f) leave = fmin(leave, gap / dn);
            else if (dn < 0.0f) enter = fmax(enter, gap / dn);
            else if (gap < 0.0f) return 0;     /* parallel to a face, outside it */
        }
    } else if (g->proxy_kind == GPIS_PROXY_BOX) {
        gpis_slab(g->proxy_p0.xyz, g->proxy_p1.xyz, o, d, &enter, &leave);
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

/* Occupancy bounds: P(f(x) <= 0) = Phi(-mu(x) / sigma(x)) < eps wherever
 * mu(x) > z sigma_max (z = Phi^-1(1 - eps), sigma_max = the largest sigma(x) over the proxy),
 * so only the stretch between the first and last points of [t0, t1] with
 * mu <= g->occupancy_level (= z sigma_max, host) needs sampling. Each end is sphere traced
 * towards the other on g(t) = mu(x(t)) - level: mu is L-Lipschitz (gp_mean_lipschitz), so
 * g stays >= 0 over a step of g / (L |d|), and no point with occupancy >= eps is ever
 * skipped; rounding of the float mean is taken off each step (allowance as ws_tents).
 * First, where the render has set them (GpisObject occ_p0.w, render/occupancy_boxes.py),
 * the object's occupancy box and cells clip both ends: outside the set cells the mean
 * exceeds the level, which a march through a loose proxy's empty part proved step by step.
 * A march stops at a step below g->occupancy_step (world length, compile/gpis.py
 * occupancy_step: a fraction of the length scale, where clipping finer saves less
 * sampling than the march costs, and for function space no more than the far balls of
 * fs_mean_step would trace after it) or after OCC_MAX_STEPS steps: clipping less is always
 * allowed.
 * Bias: a realization with f < 0 only where the occupancy is < eps (a skipped end) is not
 * seen. Per length l of skipped ray (SE) Rice's rate of crossings below z sigma bounds
 * that probability by about z eps / sqrt(2 pi) = 1.5 eps at the default eps = 1e-4
 * (scene/gpis.py), plus eps at a clipped start.
 * clip_start = 0 keeps t0: a function-space ray leaving a vertex of this object is
 * conditioned there (memory models) and must start at it. A clipped start is a fresh
 * start like the proxy boundary (function space: its truncated-normal start condition;
 * weight space: a ray starting inside must first come out), but where the occupancy is
 * < eps, so the truncation changes the law by < eps there, unlike at the proxy. */
#define OCC_MAX_STEPS 32
/* The marches' mean evaluations, counted only in the function-space program's FS_PROFILE
 * build (fs_objects.h; tools/profile_grid_scenes.py): no argument at all otherwise. */
#ifdef FS_PROFILE
#define OCC_PROF_PARAM , int* occ_evals
#define OCC_PROF_ARG(p) , p
#define OCC_PROF_COUNT (++*occ_evals)
#else
#define OCC_PROF_PARAM
#define OCC_PROF_ARG(p)
#define OCC_PROF_COUNT
#endif

inline float gpis_occupancy_march(__global const MeanNode* mean, int count, float3 o, float3 d,
                                  float t, float t_stop, float level, float lt, float min_step
                                  OCC_PROF_PARAM)
{
    float dir = t_stop >= t ? 1.0f : -1.0f, dl = length(d), lip = lt / dl;
    int local_lip = gp_mean_march_scans(mean, count);
    for (int s = 0; s < OCC_MAX_STEPS; ++s) {
        float3 x = o + t * d;
        float mu = gp_mean_value(mean, count, x);
        OCC_PROF_COUNT;
        float round = 8.0f * FLT_EPSILON * (fabs(mu) + lip * (fabs(x.x) + fabs(x.y) + fabs(x.z)));
        float g = mu - level - round;
        if (!(g > 0.0f)) break;              /* also NaN: stop, clip nothing more */
        if (!(lt > 0.0f)) return t_stop;     /* constant mean above the level everywhere */
        float step = g / lt;
        if (local_lip) {
            /* the bound over the cells of a step 4 times as long: if it certifies it,
             * take it; otherwise g / (its bound) certifies a step inside that stretch,
             * never shorter than the global one */
            float far = fmin(4.0f * step, fabs(t_stop - t));
            float l4 = gp_mean_lipschitz_on(mean, count, x, o + (t + dir * far) * d) * dl;
            step = l4 > 0.0f ? fmin(far, fmax(step, g / l4)) : far;
        }
        if (step < min_step) break;
        t += dir * step;
        if (dir * (t - t_stop) >= 0.0f) return t_stop;
    }
    return t;
}

/* The occupancy lattice of an object: OCC_CELLS^3 cells of size h from lo over its
 * proxy's bounds (a mesh proxy's p0 / p1 are its bounding box). */
inline void gpis_occ_lattice(__global const GpisObject* g, float3* lo, float3* h)
{
    float3 a = g->proxy_p0.xyz, b = g->proxy_p1.xyz;
    if (g->proxy_kind == GPIS_PROXY_SPHERE) {
        a = g->proxy_p0.xyz - g->proxy_p0.w;
        b = g->proxy_p0.xyz + g->proxy_p0.w;
    }
    *lo = a;
    *h = (b - a) / (float)OCC_CELLS;
}

/* s (>= 0) where x(s) = p + s dd crosses the next face of cell index c along one axis */
inline float gpis_occ_face(float p, float dd, float lo, float h, int c)
{
    if (dd > 0.0f) return (lo + (float)(c + 1) * h - p) / dd;
    if (dd < 0.0f) return (lo + (float)c * h - p) / dd;
    return INFINITY;
}

/* Walk the lattice from *ta towards tb (dir = +1: tb > *ta; -1: tb < *ta) to the first
 * cell set in the mask (gpis_occupancy_boxes.cl) and move *ta to where the walk enters
 * it, less 0.2% of the shortest cell crossing (the faces' float sums drift by ~1e-5 of
 * the walk, and the mask covers what lies that close to a set cell). 0: no set cell up
 * to tb or the lattice's edge. A walk longer than it can be keeps *ta. */
inline int gpis_occ_walk(__global const uint* mask, float3 lo, float3 h, float3 o, float3 d,
                         float* ta, float tb, float dir)
{
    float3 dd = dir * d, p = o + *ta * d;
    int3 i = clamp(convert_int3(floor((p - lo) / h)), 0, OCC_CELLS - 1);
    int3 st = (int3)(dd.x > 0.0f ? 1 : -1, dd.y > 0.0f ? 1 : -1, dd.z > 0.0f ? 1 : -1);
    float3 cross = h / fabs(dd);                /* s per cell along each axis */
    float3 next = (float3)(gpis_occ_face(p.x, dd.x, lo.x, h.x, i.x),
                           gpis_occ_face(p.y, dd.y, lo.y, h.y, i.y),
                           gpis_occ_face(p.z, dd.z, lo.z, h.z, i.z));
    float len = dir * (tb - *ta), s = 0.0f, pad = 2e-3f * fmin(cross.x, fmin(cross.y, cross.z));
    for (int n = 0; n < 3 * OCC_CELLS + 3; ++n) {
        int c = (i.x * OCC_CELLS + i.y) * OCC_CELLS + i.z;
        if ((mask[c >> 5] >> (c & 31)) & 1u) {
            *ta += dir * fmax(s - pad, 0.0f);
            return 1;
        }
        s = fmin(next.x, fmin(next.y, next.z));
        if (!(s < len)) return 0;
        if (next.x == s) { i.x += st.x; next.x += cross.x; }
        else if (next.y == s) { i.y += st.y; next.y += cross.y; }
        else { i.z += st.z; next.z += cross.z; }
        if (any(i < 0) || any(i >= OCC_CELLS)) return 0;
    }
    return 1;
}

/* Object k's occupancy cells in the side table (OCC_WORDS words an object) */
inline __global const uint* gpis_occ_mask(GpisTables T, int k)
{
    return T.occ_cells + (size_t)k * OCC_WORDS;
}

/* Clip [t0, t1] (inside the proxy) to the stretch where the occupancy can reach eps;
 * false if none. mask: the object's occupancy cells (gpis_occ_mask), read only where
 * occ_p0.w is set. */
inline int gpis_occupancy_clip(__global const GpisObject* g, __global const MeanNode* means,
                               __global const uint* mask, float3 o, float3 d, float* t0,
                               float* t1, int clip_start OCC_PROF_PARAM)
{
    if (!(g->occupancy_level > 0.0f)) return 1;
    if (g->occ_p0.w > 0.0f) {
        /* the occupancy box and cells (render/occupancy_boxes.py): the mean exceeds the
         * level outside the set cells, so the box's slab, then walks from either end to
         * the first set cell, clip as the marches would (t0 only where they may) */
        float enter, leave;
        gpis_slab(g->occ_p0.xyz, g->occ_p1.xyz, o, d, &enter, &leave);
        if (clip_start) *t0 = fmax(*t0, enter);
        *t1 = fmin(*t1, leave);
        if (!(*t0 < *t1) || !(enter < leave)) return 0;
        float3 cl, ch;
        gpis_occ_lattice(g, &cl, &ch);
        if (clip_start && !gpis_occ_walk(mask, cl, ch, o, d, t0, *t1, 1.0f)) return 0;
        if (!gpis_occ_walk(mask, cl, ch, o, d, t1, *t0, -1.0f)) return 0;
        if (!(*t0 < *t1)) return 0;
    }
    __global const MeanNode* mean = means + g->mean_first;
    float dl = length(d), lt = gp_mean_lipschitz(mean, g->mean_count) * dl;
    float level = g->occupancy_level, min_step = g->occupancy_step / dl;
    if (clip_start) {
        *t0 = gpis_occupancy_march(mean, g->mean_count, o, d, *t0, *t1, level, lt, min_step
                                   OCC_PROF_ARG(occ_evals));
        if (!(*t0 < *t1)) return 0;
    }
    *t1 = gpis_occupancy_march(mean, g->mean_count, o, d, *t1, *t0, level, lt, min_step
                                   OCC_PROF_ARG(occ_evals));
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
