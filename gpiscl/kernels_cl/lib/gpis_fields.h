/* Colour and emission fields of GPIS objects, evaluated at hit points by scatter.cl and
 * emission.cl. gpiscl/host/scene/colour_fields.py is the reference and packs each field into one
 * MeanNode record of the scene's field table (kinds GPIS_FIELD_*, generated from
 * gpiscl/host/kinds/colour_fields.py):
 * row0..row2 map world points to the field's coordinates y, p0 / p1 hold colours a / b;
 *   constant  p0.xyz
 *   checker   y = (x + offset) / scale; a where floor(y) has an even component sum, else b
 *   gradient  t = clamp(y.x, 0, 1); (1 - t) a + t b
 *   grid      y = index coordinates; p1.xyz = sample counts; flags payload records of
 *             interleaved RGB samples follow; trilinear, clamped to the sample box
 * Index 0 means "no field": the field table's record 0 is no field (compile/gpis.py). */

/* RGB sample j of a grid field's payload (interleaved floats, gp_grid_run's layout) */
inline float3 gpis_field_sample(__global const MeanNode* payload, int j)
{
    int k;
    __global const float* f = gp_grid_place(payload, 3 * j, &k);
    float r = gp_grid_run(&f, &k), g = gp_grid_run(&f, &k);
    return (float3)(r, g, gp_grid_run(&f, &k));
}

inline float3 gpis_field_grid(__global const MeanNode* n, float3 u)
{
    __global const MeanNode* payload = n + 1;
    GpGridCell q = gp_grid_cell(n->p1.xyz, u);
    float3 t = q.t;
    int b = q.base, sx = q.sx, nz = q.sy;
    float3 c000 = gpis_field_sample(payload, b), c001 = gpis_field_sample(payload, b + 1);
    float3 c010 = gpis_field_sample(payload, b + nz);
    float3 c011 = gpis_field_sample(payload, b + nz + 1);
    float3 c100 = gpis_field_sample(payload, b + sx);
    float3 c101 = gpis_field_sample(payload, b + sx + 1);
    float3 c110 = gpis_field_sample(payload, b + sx + nz);
    float3 c111 = gpis_field_sample(payload, b + sx + nz + 1);
    float3 x0 = mix(mix(c000, c001, t.z), mix(c010, c011, t.z), t.y);
    float3 x1 = mix(mix(c100, c101, t.z), mix(c110, c111, t.z), t.y);
    return mix(x0, x1, t.x);
}

/* RGB of field record f at world point x; `none` when f == 0 (no field) */
inline float3 gpis_field_eval(__global const MeanNode* nodes, int f, float3 x, float none)
{
    if (f <= 0) return (float3)(none);
    __global const MeanNode* n = nodes + f;
    float3 y = gp_leaf_local(n, x);
    switch (n->kind) {
    case GPIS_FIELD_CONSTANT:
        return n->p0.xyz;
    case GPIS_FIELD_CHECKER: {
        float3 c = floor(y);
        /* the parity of a sum of integers held exactly in float (|c| < 2^24) */
        float s = c.x + c.y + c.z;
        return (fabs(s - 2.0f * floor(0.5f * s)) > 0.5f) ? n->p1.xyz : n->p0.xyz;
    }
    case GPIS_FIELD_GRADIENT:
        return mix(n->p0.xyz, n->p1.xyz, clamp(y.x, 0.0f, 1.0f));
    case GPIS_FIELD_GRID:
        return gpis_field_grid(n, y);
    default:
        return (float3)(NAN);
    }
}
