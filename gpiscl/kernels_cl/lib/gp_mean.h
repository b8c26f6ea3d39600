/* GP mean functions: signed distances (positive outside) with analytic gradients.
 * gpiscl/host/gp/means.py is the reference; gp_records.pack_mean flattens a mean tree
 * into the postfix MeanNode program run here:
 *   - leaves carry their composite world-to-local map and distance scale (transforms are
 *     folded in), so value = scale * prim(M x + t), gradient = scale * M^T grad prim;
 *   - ops pop two (value, gradient) entries and push one; GP_MEAN_STACK_DEPTH entries
 *     (8) cover any tree of up to 128 leaves, because the host emits the child needing the
 *     deeper stack first (flag GP_MEAN_FLAG_SWAPPED restores the operand order). The host
 *     rejects deeper trees; a malformed program here yields NaN, never a stack overrun.
 * A grid leaf is followed by its samples, stored inline as payload records (flags = their
 * count; see layout/gp_records.py): the evaluator and gp_mean_lipschitz jump over them.
 * Stack entries are float4: xyz = gradient, w = value, so blending and negation treat
 * value and gradient alike. Means are evaluated in float: they enter covariance-free
 * formulas (occupancy, conditioning right-hand sides) where float is ample.
 */
#ifndef GP_MEAN_SPACE
#define GP_MEAN_SPACE __global
#endif

/* length and direction; direction 0 at the origin (a valid subgradient of |v|) */
inline float gp_norm_dir3(float3 v, float3* d)
{
    float n = length(v);
    *d = n > 0.0f ? v / n : (float3)(0.0f);
    return n;
}

inline float gp_norm_dir2(float2 v, float2* d)
{
    float n = length(v);
    *d = n > 0.0f ? v / n : (float2)(0.0f);
    return n;
}

/* iq's sdBox; inside, ties between axes go to the first (x, then y), as on the host */
inline float gp_sd_box(float3 p, float3 extent, float3* g)
{
    float3 q = fabs(p) - extent;
    float3 dir;
    float out_len = gp_norm_dir3(fmax(q, (float3)(0.0f)), &dir);
    float qmax = fmax(q.x, fmax(q.y, q.z));
    if (!(qmax > 0.0f)) {
        if (q.x >= q.y && q.x >= q.z) dir = (float3)(1.0f, 0.0f, 0.0f);
        else if (q.y >= q.z) dir = (float3)(0.0f, 1.0f, 0.0f);
        else dir = (float3)(0.0f, 0.0f, 1.0f);
    }
    *g = copysign((float3)(1.0f), p) * dir;
    return out_len + fmin(qmax, 0.0f);
}

/* Where float j of a grid payload lies: its record's floats (GP_MEAN_GRID_PAYLOAD_FLOATS
 * of them, the record's int tail past them) and its index *k there. */
inline GP_MEAN_SPACE const float* gp_grid_place(GP_MEAN_SPACE const MeanNode* payload, int j,
                                                int* k)
{
    int r = j / GP_MEAN_GRID_PAYLOAD_FLOATS;
    *k = j - r * GP_MEAN_GRID_PAYLOAD_FLOATS;
    return (GP_MEAN_SPACE const float*)(payload + r);
}

/* The floats of the payload record after the one whose floats are f */
inline GP_MEAN_SPACE const float* gp_grid_next_record(GP_MEAN_SPACE const float* f)
{
    return (GP_MEAN_SPACE const float*)((GP_MEAN_SPACE const MeanNode*)f + 1);
}

inline float gp_grid_sample(GP_MEAN_SPACE const MeanNode* payload, int j)
{
    int k;
    return gp_grid_place(payload, j, &k)[k];
}

/* The float at (*f, *k) (gp_grid_place), then on to the next one: a run of consecutive
 * floats read with one index division. */
inline float gp_grid_run(GP_MEAN_SPACE const float** f, int* k)
{
    if (*k == GP_MEAN_GRID_PAYLOAD_FLOATS) {
        *f = gp_grid_next_record(*f);
        *k = 0;
    }
    return (*f)[(*k)++];
}

/* Samples j and j + 1, and j .. j + 3: one record lookup for the run (a vload where it
 * stays in the record; one that crosses into the next reads the rest there). The same
 * numbers as gp_grid_sample's, for fewer index divisions. */
inline float2 gp_grid_sample2(GP_MEAN_SPACE const MeanNode* payload, int j)
{
    int k;
    GP_MEAN_SPACE const float* f = gp_grid_place(payload, j, &k);
    if (k + 1 < GP_MEAN_GRID_PAYLOAD_FLOATS) return vload2(0, f + k);
    return (float2)(f[k], gp_grid_next_record(f)[0]);
}

inline float4 gp_grid_sample4(GP_MEAN_SPACE const MeanNode* payload, int j)
{
    int k;
    GP_MEAN_SPACE const float* f = gp_grid_place(payload, j, &k);
    if (k + 3 < GP_MEAN_GRID_PAYLOAD_FLOATS) return vload4(0, f + k);
    GP_MEAN_SPACE const float* g = gp_grid_next_record(f) - GP_MEAN_GRID_PAYLOAD_FLOATS;
    return (float4)(f[k], k + 1 < GP_MEAN_GRID_PAYLOAD_FLOATS ? f[k + 1] : g[k + 1],
                    k + 2 < GP_MEAN_GRID_PAYLOAD_FLOATS ? f[k + 2] : g[k + 2], g[k + 3]);
}

/* The eight samples of the cell whose lowest corner is sample b (sx, sy: the x and y
 * strides), component 4 dx + 2 dy + dz: .s0 = c000, .s1 = c001, ..., .s7 = c111. */
inline float8 gp_grid_corners(GP_MEAN_SPACE const MeanNode* payload, int b, int sx, int sy)
{
    return (float8)(gp_grid_sample2(payload, b), gp_grid_sample2(payload, b + sy),
                    gp_grid_sample2(payload, b + sx), gp_grid_sample2(payload, b + sx + sy));
}

/* Four samples of a cell face: b, b + o1, b + o2, b + o1 + o2 (gp_mean_monotone_reach's
 * walk reads the face it crosses into, in gp_grid_corners' component order). */
inline float4 gp_grid_quad(GP_MEAN_SPACE const MeanNode* payload, int b, int o1, int o2)
{
    if (o1 == 1) return (float4)(gp_grid_sample2(payload, b), gp_grid_sample2(payload, b + o2));
    return (float4)(gp_grid_sample(payload, b), gp_grid_sample(payload, b + o1),
                    gp_grid_sample(payload, b + o2), gp_grid_sample(payload, b + o1 + o2));
}

/* The trilinear cell of index coordinates u in a grid of `dims` samples per axis (x index
 * first): u clamped to the sample box, its cell (floor, the last cell at the far faces),
 * the weights t inside it, the first sample's index and the x and y strides. Shared by
 * grid means and grid colour fields so both index samples the same way. */
typedef struct { float3 c, t; int base, sx, sy; } GpGridCell;

inline GpGridCell gp_grid_cell(float3 dims, float3 u)
{
    float3 hi = dims - 1.0f;
    GpGridCell r;
    r.c = fmin(fmax(u, (float3)(0.0f)), hi);
    float3 cell = fmin(floor(r.c), hi - 1.0f);
    r.t = r.c - cell;
    int ny = (int)dims.y, nz = (int)dims.z;
    r.sx = ny * nz;
    r.sy = nz;
    r.base = ((int)cell.x * ny + (int)cell.y) * nz + (int)cell.z;
    return r;
}

/* The trilinear interpolant of the single-channel samples after grid record n at index
 * coordinates u, clamped to the sample box (the border value held outside), and its
 * gradient in index units: that of the same interpolant inside, 0 along an axis on
 * which u was clamped. *out = u - clamped u. Grid means and the kernel's grid fields
 * (fs_sampling.h) share it. */
inline float gp_grid_trilinear(GP_MEAN_SPACE const MeanNode* n, float3 u, float3* grad,
                               float3* out)
{
    GP_MEAN_SPACE const MeanNode* payload = n + 1;
    GpGridCell q = gp_grid_cell(n->p1.xyz, u);
    float3 t = q.t;
    float8 c = gp_grid_corners(payload, q.base, q.sx, q.sy);
    float x0 = mix(mix(c.s0, c.s1, t.z), mix(c.s2, c.s3, t.z), t.y);
    float x1 = mix(mix(c.s4, c.s5, t.z), mix(c.s6, c.s7, t.z), t.y);
    float gy = mix(mix(c.s2 - c.s0, c.s3 - c.s1, t.z), mix(c.s6 - c.s4, c.s7 - c.s5, t.z), t.x);
    float gz = mix(mix(c.s1 - c.s0, c.s3 - c.s2, t.y), mix(c.s5 - c.s4, c.s7 - c.s6, t.y), t.x);
    *out = u - q.c;
    *grad = select((float3)(x1 - x0, gy, gz), (float3)(0.0f), isnotequal(*out, (float3)(0.0f)));
    return mix(x0, x1, t.x);
}

/* A grid mean: the trilinear interpolant (one-sided gradient at faces, as
 * means.GridMean). Outside the sample box, with g the clamped point's value and d its
 * distance (p0.x = 1 / S converts voxels to the normalised samples' units):
 * sqrt(g^2 + d^2) where g >= 0, g + d where g < 0 (means.GridMean says why); either
 * keeps |gradient| <= 1 in these units (layout/gp_records.py). */
/* Cubic B-spline weights of the four taps around fraction t of a cell, and their
 * derivatives (means._bspline_weights). */
inline void gp_bspline(float t, float* w, float* dw)
{
    float s = 1.0f - t, t2 = t * t, t3 = t2 * t;
    w[0] = s * s * s / 6.0f;
    w[1] = (3.0f * t3 - 6.0f * t2 + 4.0f) / 6.0f;
    w[2] = (-3.0f * t3 + 3.0f * t2 + 3.0f * t + 1.0f) / 6.0f;
    w[3] = t3 / 6.0f;
    dw[0] = -0.5f * s * s;
    dw[1] = 0.5f * (3.0f * t2 - 4.0f * t);
    dw[2] = 0.5f * (-3.0f * t2 + 2.0f * t + 1.0f);
    dw[3] = 0.5f * t2;
}

/* The cubic leaf's cell for index coordinates u: u clamped to the sample box (*c), the
 * fraction t in the cell, the strides of its coefficients and the first one's index */
inline int gp_cubic_cell(GP_MEAN_SPACE const MeanNode* n, float3 u, float3* c, float3* t,
                         int* sx, int* sy)
{
    float3 hi = n->p1.xyz - 1.0f;
    *c = fmin(fmax(u, (float3)(0.0f)), hi);
    float3 cell = fmin(floor(*c), hi - 1.0f);
    *t = *c - cell;
    *sy = (int)n->p1.z + 2;
    *sx = ((int)n->p1.y + 2) * *sy;
    return (int)cell.x * *sx + (int)cell.y * *sy + (int)cell.z;
}

/* The interpolating tricubic B-spline (a cubic grid leaf: its payload holds the
 * (n + 2)^3 coefficients, sample i at coefficient i + 1) at index coordinates u clamped
 * to the sample box, with its gradient in index units (0 along clamped axes) and
 * *out = u - clamped u, as gp_grid_trilinear; means.cubic_eval is the reference. */
inline float gp_grid_cubic(GP_MEAN_SPACE const MeanNode* n, float3 u, float3* grad,
                           float3* out)
{
    GP_MEAN_SPACE const MeanNode* payload = n + 1;
    float3 c, t;
    int sx, sy, base = gp_cubic_cell(n, u, &c, &t, &sx, &sy);
    float wx[4], wy[4], wz[4], dx[4], dy[4], dz[4];
    gp_bspline(t.x, wx, dx);
    gp_bspline(t.y, wy, dy);
    gp_bspline(t.z, wz, dz);
    float v = 0.0f;
    float3 g = (float3)(0.0f);
    for (int a = 0; a < 4; ++a) {
        float3 ga = (float3)(0.0f);
        float va = 0.0f;
        for (int b = 0; b < 4; ++b) {
            float vb = 0.0f, db = 0.0f;
            float4 q = gp_grid_sample4(payload, base + a * sx + b * sy);
            vb += wz[0] * q.x; db += dz[0] * q.x;
            vb += wz[1] * q.y; db += dz[1] * q.y;
            vb += wz[2] * q.z; db += dz[2] * q.z;
            vb += wz[3] * q.w; db += dz[3] * q.w;
            va += wy[b] * vb;
            ga += (float3)(0.0f, dy[b] * vb, wy[b] * db);
        }
        v += wx[a] * va;
        g += (float3)(dx[a] * va, wx[a] * ga.y, wx[a] * ga.z);
    }
    *out = u - c;
    *grad = select(g, (float3)(0.0f), isnotequal(*out, (float3)(0.0f)));
    return v;
}

inline float gp_mean_grid(GP_MEAN_SPACE const MeanNode* n, float3 u, float3* g)
{
    float3 out, dir, grad;
    float v = n->p0.y > 0.5f ? gp_grid_cubic(n, u, &grad, &out)
                             : gp_grid_trilinear(n, u, &grad, &out);
    float d = n->p0.x * gp_norm_dir3(out, &dir);
    if (!(d > 0.0f)) {
        *g = grad;
        return v;
    }
    if (v < 0.0f) {
        *g = grad + n->p0.x * dir;
        return v + d;
    }
    float r = sqrt(v * v + d * d);
    *g = (v * grad + d * n->p0.x * dir) / r;
    return r;
}

/* A leaf's affine map from world points to its own coordinates (a grid's: index space),
 * rows row0..row2 of the inverse transform; every reader of a leaf or a grid record maps
 * through it. */
inline float3 gp_leaf_local(GP_MEAN_SPACE const MeanNode* n, float3 x)
{
    return (float3)(dot(n->row0.xyz, x) + n->row0.w, dot(n->row1.xyz, x) + n->row1.w,
                    dot(n->row2.xyz, x) + n->row2.w);
}

/* Each primitive's value and local gradient (lib/gp_means/<name>.h, declared in
 * gpiscl/host/kinds/means.py): generated. */
/* @kinds gp_means leaves */

inline float gp_mean_leaf(GP_MEAN_SPACE const MeanNode* n, float3 x, float3* grad)
{
    float3 r0 = n->row0.xyz, r1 = n->row1.xyz, r2 = n->row2.xyz;
    float3 y = gp_leaf_local(n, x);
    float4 p0 = n->p0, p1 = n->p1;
    float3 g = (float3)(0.0f);
    float v = gp_mean_leaf_of(n->kind, n, y, p0, p1, &g);
    *grad = n->scale * (g.x * r0 + g.y * r1 + g.z * r2);
    return n->scale * v;
}

/* iq's polynomial smooth minimum of (gradient, value) pairs; k <= 0 is the sharp min.
 * d/dh of the blend vanishes where h is unclamped, so blending gradients is exact. */
inline float4 gp_smooth_min(float4 a, float4 b, float k)
{
    if (!(k > 0.0f)) return a.w <= b.w ? a : b;
    float h = clamp(0.5f + 0.5f * (b.w - a.w) / k, 0.0f, 1.0f);
    float4 r = h * a + (1.0f - h) * b;
    r.w -= k * h * (1.0f - h);
    return r;
}

inline float gp_mean_eval(GP_MEAN_SPACE const MeanNode* nodes, int count, float3 x,
                          float3* grad)
{
    float4 stack[GP_MEAN_STACK_DEPTH];
    int top = 0;
    for (int i = 0; i < count; ++i) {
        GP_MEAN_SPACE const MeanNode* n = nodes + i;
        if (n->kind < GP_MEAN_FIRST_OP) {
            if (top >= GP_MEAN_STACK_DEPTH) { top = -1; break; }
            float3 g;
            float v = gp_mean_leaf(n, x, &g);
            stack[top++] = (float4)(g, v);
            if (n->kind == GP_MEAN_GRID) i += n->flags;
            continue;
        }
        if (top < 2 || n->kind == GP_MEAN_PAYLOAD) { top = -1; break; }
        float4 b = stack[--top], a = stack[top - 1];
        if (n->flags & GP_MEAN_FLAG_SWAPPED) { float4 t = a; a = b; b = t; }
        float4 r;
        if (n->kind == GP_MEAN_UNION) r = gp_smooth_min(a, b, n->k);
        else if (n->kind == GP_MEAN_INTERSECTION) r = -gp_smooth_min(-a, -b, n->k);
        else r = -gp_smooth_min(-a, b, n->k);      /* difference: smax(a, -b) */
        stack[top - 1] = r;
    }
    if (top != 1) {
        *grad = (float3)(NAN);
        return NAN;
    }
    *grad = stack[0].xyz;
    return stack[0].w;
}

/* gp_grid_trilinear's value alone (the same operations on the same samples) */
inline float gp_grid_trilinear_value(GP_MEAN_SPACE const MeanNode* n, float3 u, float3* out)
{
    GpGridCell q = gp_grid_cell(n->p1.xyz, u);
    float3 t = q.t;
    float8 c = gp_grid_corners(n + 1, q.base, q.sx, q.sy);
    float x0 = mix(mix(c.s0, c.s1, t.z), mix(c.s2, c.s3, t.z), t.y);
    float x1 = mix(mix(c.s4, c.s5, t.z), mix(c.s6, c.s7, t.z), t.y);
    *out = u - q.c;
    return mix(x0, x1, t.x);
}

/* gp_grid_cubic's value alone: the same weights and sums in the same order (the images
 * depend on the bits), without the derivative weights and the gradient's sums */
inline float gp_grid_cubic_value(GP_MEAN_SPACE const MeanNode* n, float3 u, float3* out)
{
    GP_MEAN_SPACE const MeanNode* payload = n + 1;
    float3 c, t;
    int sx, sy, base = gp_cubic_cell(n, u, &c, &t, &sx, &sy);
    float wx[4], wy[4], wz[4], dw[4];
    gp_bspline(t.x, wx, dw);
    gp_bspline(t.y, wy, dw);
    gp_bspline(t.z, wz, dw);
    float v = 0.0f;
    for (int a = 0; a < 4; ++a) {
        float va = 0.0f;
        for (int b = 0; b < 4; ++b) {
            float vb = 0.0f;
            float4 q = gp_grid_sample4(payload, base + a * sx + b * sy);
            vb += wz[0] * q.x;
            vb += wz[1] * q.y;
            vb += wz[2] * q.z;
            vb += wz[3] * q.w;
            va += wy[b] * vb;
        }
        v += wx[a] * va;
    }
    *out = u - c;
    return v;
}

/* A program of one grid leaf (the baked means, trilinear or cubic): gp_mean_eval's value
 * without the gradient and the interpreter, the same operations (gp_mean_leaf,
 * gp_mean_grid) */
inline float gp_mean_grid_leaf_value(GP_MEAN_SPACE const MeanNode* n, float3 x)
{
    float3 out, u = gp_leaf_local(n, x);
    float v = n->p0.y > 0.5f ? gp_grid_cubic_value(n, u, &out)
                             : gp_grid_trilinear_value(n, u, &out);
    float d = n->p0.x * length(out);
    if (d > 0.0f) v = v < 0.0f ? v + d : sqrt(v * v + d * d);
    return n->scale * v;
}

/* Whether a mean program is one grid leaf, trilinear or cubic (gp_mean_value's short way) */
inline int gp_mean_is_grid_leaf(GP_MEAN_SPACE const MeanNode* nodes, int count)
{
    return count > 0 && nodes[0].kind == GP_MEAN_GRID && count == 1 + nodes[0].flags
        && nodes[0].scale > 0.0f;
}

/* ... and trilinear (the cell walks' case: monotone stretch, variation, kinks) */
inline int gp_mean_is_trilinear_grid(GP_MEAN_SPACE const MeanNode* nodes, int count)
{
    return gp_mean_is_grid_leaf(nodes, count) && nodes[0].p0.y < 0.5f;
}

/* The mean's value alone: the occupancy marches, the far balls and every value row
 * evaluate it far more often than the gradient; a baked grid's takes the short way. */
inline float gp_mean_value(GP_MEAN_SPACE const MeanNode* nodes, int count, float3 x)
{
    if (gp_mean_is_grid_leaf(nodes, count))
        return gp_mean_grid_leaf_value(nodes, x);
    float3 g;
    return gp_mean_eval(nodes, count, x, &g);
}

/* a / B for counts 0 <= a < 2^21 and B >= 1 (an integer): floor((a + 1/2) / B) in float,
 * exact whatever the division's last ulps (a / B is a multiple of 1 / B, so the half keeps
 * the quotient 1 / (2B) from every integer). PoCL ran an int3 division as three integer
 * divisions, a sizeable part of a brick scan (gp_grid_slope_on). */
inline int3 gp_div_small(int3 a, float B)
{
    return convert_int3(floor((convert_float3(a) + 0.5f) / B));
}

/* A grid leaf's slope bound over the index-space box [lo, hi], in the leaf's sample units
 * (<= 1; gp_mean_lipschitz's 1 is the whole grid): the largest brick bound over the
 * bricks holding the cells any point of the box evaluates in (cell = floor of the clamped
 * point, the last cell at the far faces, as gp_grid_cell), and where the box leaves the
 * sample box, the outside continuation's slope sqrt(a^2 + (1/S)^2) (GridMean: at most
 * sqrt(a^2 + 1) in world units, a the face cells' bound). More than 27 bricks (a long
 * stretch, where the global bound costs little): 1. */
inline float gp_grid_slope_on(GP_MEAN_SPACE const MeanNode* n, float3 lo, float3 hi)
{
    int B = (int)n->p0.z;
    if (B <= 0) return 1.0f;
    float3 dims = n->p1.xyz, top = dims - 1.0f;
    float3 cl = fmin(fmax(lo, (float3)(0.0f)), top), ch = fmin(fmax(hi, (float3)(0.0f)), top);
    int3 c0 = convert_int3(fmin(floor(cl), top - 1.0f));
    int3 c1 = convert_int3(fmin(floor(ch), top - 1.0f));
    float Bf = (float)B;
    int3 b0 = gp_div_small(c0, Bf), b1 = gp_div_small(c1, Bf);
    int3 nb = gp_div_small(convert_int3(dims) - 2, Bf) + 1;   /* ceil((n - 1) / B) */
    int3 span = b1 - b0 + 1;
    if (span.x * span.y * span.z > 27) return 1.0f;
    int3 nd = convert_int3(dims) + (n->p0.y > 0.5f ? 2 : 0);   /* samples or coefficients */
    int first = nd.x * nd.y * nd.z;
    GP_MEAN_SPACE const MeanNode* payload = n + 1;
    float m = 0.0f;
    for (int i = b0.x; i <= b1.x; ++i)
        for (int j = b0.y; j <= b1.y; ++j) {
            int q;                                   /* a run along z (gp_grid_run) */
            GP_MEAN_SPACE const float* f =
                gp_grid_place(payload, first + (i * nb.y + j) * nb.z + b0.z, &q);
            /* max: the bounds are numbers (fmax's NaN test cost a compare a brick) */
            for (int k = b0.z; k <= b1.z; ++k) m = max(m, gp_grid_run(&f, &q));
        }
    if (any(lo < (float3)(0.0f)) || any(hi > top)) m = sqrt(m * m + n->p0.x * n->p0.x);
    return fmin(m, 1.0f);
}

/* Lipschitz constant of a packed mean program in world units: max over leaves of
 * |scale| ||M||_2 Lip(primitive) (smooth/sharp unions, intersections and differences never
 * exceed their children's). Distance primitives are 1-Lipschitz, a plane |scale|, a
 * constant 0; pack_mean's transform scale 1/||M^-1|| keeps scale ||M|| ~ 1 for rigid and
 * uniformly scaled transforms. ||M||_2^2 <= max row sum of |M M^T| (Gershgorin), exact for
 * scaled rotations. Used by the weight-space search and the occupancy bounds (per ray:
 * grid payloads are jumped over, so the cost is the number of leaves and ops). */
inline float gp_leaf_lipschitz(GP_MEAN_SPACE const MeanNode* n, float prim)
{
    float3 r0 = n->row0.xyz, r1 = n->row1.xyz, r2 = n->row2.xyz;
    float g01 = fabs(dot(r0, r1)), g02 = fabs(dot(r0, r2)), g12 = fabs(dot(r1, r2));
    float s2 = fmax(dot(r0, r0) + g01 + g02,
                    fmax(dot(r1, r1) + g01 + g12, dot(r2, r2) + g02 + g12));
    return fabs(n->scale) * sqrt(s2) * prim;
}

inline float gp_leaf_prim_lipschitz(GP_MEAN_SPACE const MeanNode* n)
{
    return n->kind == GP_MEAN_CONSTANT ? 0.0f : n->kind == GP_MEAN_PLANE ? fabs(n->p0.y) : 1.0f;
}

inline float gp_mean_lipschitz(GP_MEAN_SPACE const MeanNode* nodes, int count)
{
    float lip = 0.0f;
    for (int i = 0; i < count; ++i) {
        GP_MEAN_SPACE const MeanNode* n = nodes + i;
        if (n->kind >= GP_MEAN_FIRST_OP) continue;
        if (n->kind == GP_MEAN_GRID) i += n->flags;   /* payload: not leaves, same result */
        lip = fmax(lip, gp_leaf_lipschitz(n, gp_leaf_prim_lipschitz(n)));
    }
    return lip;
}

/* Whether a mean program has grid leaves (gp_mean_lipschitz_on then pays). */
inline int gp_mean_has_grid(GP_MEAN_SPACE const MeanNode* nodes, int count)
{
    for (int i = 0; i < count; ++i) {
        if (nodes[i].kind == GP_MEAN_GRID) return 1;   /* the first leaf before any payload */
    }
    return 0;
}

/* Whether the occupancy marches take a brick scan (gp_mean_lipschitz_on) a step: only for
 * a grid leaf whose global slope bound is loose (p0.w, layout/gp_records.py
 * loose_slope_bound); elsewhere the scan costs more than its longer steps save. */
inline int gp_mean_march_scans(GP_MEAN_SPACE const MeanNode* nodes, int count)
{
    for (int i = 0; i < count; ++i) {
        GP_MEAN_SPACE const MeanNode* n = nodes + i;
        if (n->kind == GP_MEAN_GRID) {
            if (n->p0.w > 0.5f) return 1;
            i += n->flags;                       /* past its payload */
        }
    }
    return 0;
}

/* gp_mean_lipschitz over the segment [p, q] only: grid leaves contribute their bound
 * over the segment's cells (gp_grid_slope_on; an affine map takes the segment to a
 * segment, so the end points' index box holds it, padded for rounding). Any interval
 * of a ray may use it in place of the global bound. */
inline float gp_mean_lipschitz_on(GP_MEAN_SPACE const MeanNode* nodes, int count, float3 p,
                                  float3 q)
{
    float lip = 0.0f;
    for (int i = 0; i < count; ++i) {
        GP_MEAN_SPACE const MeanNode* n = nodes + i;
        if (n->kind >= GP_MEAN_FIRST_OP) continue;
        float prim = gp_leaf_prim_lipschitz(n);
        if (n->kind == GP_MEAN_GRID) {
            float3 up = gp_leaf_local(n, p), uq = gp_leaf_local(n, q);
            float3 pad = 1e-3f + 4.0f * FLT_EPSILON * fmax(fabs(up), fabs(uq));
            prim = gp_grid_slope_on(n, fmin(up, uq) - pad, fmax(up, uq) + pad);
            i += n->flags;
        }
        lip = fmax(lip, gp_leaf_lipschitz(n, prim));
    }
    return lip;
}


/* The trilinear cells a segment crosses, in order (Amanatides and Woo), of a
 * one-trilinear-grid-leaf mean program (gp_mean_is_trilinear_grid), in index space:
 * fractions t of the segment where the current cell is entered and left (tout), tend where
 * the segment leaves the sample box (the outside continuation is not walked), and the
 * cell's eight samples (gp_grid_corners' order). A step across a face keeps the four
 * samples the cells share and reads the other four (gp_grid_quad). A cell the segment only
 * grazes within rounding may be skipped: it spans ~1e-6 voxels of the segment. */
typedef struct {
    GP_MEAN_SPACE const MeanNode* payload;
    float3 tnext, tstep;
    int3 c, last, step;
    int base, sx, nz;
    float t, tout, tend;
    float8 s;
} GpCellWalk;

/* The walk's first cell, the one holding p; 0 where p lies outside the sample box. */
inline int gp_cell_walk_begin(GP_MEAN_SPACE const MeanNode* n, float3 p, float3 q,
                              GpCellWalk* w)
{
    float3 a = gp_leaf_local(n, p), b = gp_leaf_local(n, q);
    float3 top = n->p1.xyz - 1.0f, d = b - a;
    if (any(a < (float3)(0.0f)) || any(a > top)) return 0;
    float3 face = select((float3)(0.0f), top, d > (float3)(0.0f));
    float3 texit = select((face - a) / d, (float3)(INFINITY), d == (float3)(0.0f));
    w->tend = fmin(1.0f, fmin(texit.x, fmin(texit.y, texit.z)));
    w->payload = n + 1;
    int ny = (int)n->p1.y;
    w->nz = (int)n->p1.z;
    w->sx = ny * w->nz;
    w->c = convert_int3(fmin(floor(a), top - 1.0f));
    w->last = convert_int3(fmin(floor(fmin(fmax(a + w->tend * d, (float3)(0.0f)), top)),
                                top - 1.0f));
    w->step = select((int3)(-1), (int3)(1), d > (float3)(0.0f));
    float3 next = select((float3)(0.0f), (float3)(1.0f), d > (float3)(0.0f));
    w->tnext = select((convert_float3(w->c) + next - a) / d, (float3)(INFINITY),
                      d == (float3)(0.0f));
    w->tstep = select(1.0f / fabs(d), (float3)(INFINITY), d == (float3)(0.0f));
    w->t = 0.0f;
    w->tout = fmin(fmin(w->tnext.x, fmin(w->tnext.y, w->tnext.z)), w->tend);
    w->base = (w->c.x * ny + w->c.y) * w->nz + w->c.z;
    w->s = gp_grid_corners(w->payload, w->base, w->sx, w->nz);
    return 1;
}

/* The lesser and the greater of two numbers, infinities included (a crossing time along an
 * axis the ray does not move on is INFINITY; a running range starts at +-INFINITY): OpenCL's
 * min and max leave infinite arguments undefined, and fmin / fmax pay for a NaN rule these
 * numbers never need (a compare and a blend each on PoCL). */
inline float gp_lesser(float a, float b) { return b < a ? b : a; }
inline float gp_greater(float a, float b) { return b > a ? b : a; }

/* On to the next cell, across the nearest face; 0 at the segment's or the box's end. */
inline int gp_cell_walk_next(GpCellWalk* w)
{
    if (w->tout >= w->tend) return 0;
    GP_MEAN_SPACE const MeanNode* payload = w->payload;
    int sx = w->sx, nz = w->nz;
    if (w->tnext.x <= w->tnext.y && w->tnext.x <= w->tnext.z) {
        if (w->c.x == w->last.x) return 0;
        w->c.x += w->step.x; w->tnext.x += w->tstep.x;
        w->base += w->step.x * sx;
        if (w->step.x > 0) { w->s.s0123 = w->s.s4567; w->s.s4567 = gp_grid_quad(payload, w->base + sx, 1, nz); }
        else { w->s.s4567 = w->s.s0123; w->s.s0123 = gp_grid_quad(payload, w->base, 1, nz); }
    } else if (w->tnext.y <= w->tnext.z) {
        if (w->c.y == w->last.y) return 0;
        w->c.y += w->step.y; w->tnext.y += w->tstep.y;
        w->base += w->step.y * nz;
        if (w->step.y > 0) { w->s.s0145 = w->s.s2367; w->s.s2367 = gp_grid_quad(payload, w->base + nz, 1, sx); }
        else { w->s.s2367 = w->s.s0145; w->s.s0145 = gp_grid_quad(payload, w->base, 1, sx); }
    } else {
        if (w->c.z == w->last.z) return 0;
        w->c.z += w->step.z; w->tnext.z += w->tstep.z;
        w->base += w->step.z;
        if (w->step.z > 0) { w->s.s0246 = w->s.s1357; w->s.s1357 = gp_grid_quad(payload, w->base + 1, nz, sx); }
        else { w->s.s1357 = w->s.s0246; w->s.s0246 = gp_grid_quad(payload, w->base, nz, sx); }
    }
    w->t = w->tout;
    w->tout = gp_lesser(gp_lesser(w->tnext.x, gp_lesser(w->tnext.y, w->tnext.z)), w->tend);
    return 1;
}

/* The ranges of a cell's four edge differences along x, y and z (samples s in
 * gp_grid_corners' order): each partial derivative of the trilinear interpolant, in index
 * units, is a bilinear blend of its axis's four. min / max, not fmin / fmax: the samples
 * are numbers, and fmin's NaN rule was a compare and a blend per call on PoCL, a good
 * part of a walk's time (docs/design/grid-means.md, "The knob against knob_no_csg"). */
inline void gp_cell_edge_ranges(float8 s, float3* lo, float3* hi)
{
    float4 ex = s.s4567 - s.s0123, ey = s.s2367 - s.s0145, ez = s.s1357 - s.s0246;
    *lo = (float3)(min(min(ex.x, ex.y), min(ex.z, ex.w)),
                   min(min(ey.x, ey.y), min(ey.z, ey.w)),
                   min(min(ez.x, ez.y), min(ez.z, ez.w)));
    *hi = (float3)(max(max(ex.x, ex.y), max(ex.z, ex.w)),
                   max(max(ey.x, ey.y), max(ey.z, ey.w)),
                   max(max(ez.x, ez.y), max(ez.z, ez.w)));
}

/* The range (min, max) of a trilinear cell's slope along d (index units per unit of a
 * segment; samples s in gp_grid_corners' order): sum_i d_i [lo_i, hi_i] of its edge
 * differences. The cell walks' certificates (monotone stretch, kinks, sigma's rates). */
inline float2 gp_cell_slope_range(float8 s, float3 d)
{
    float3 lo, hi;
    gp_cell_edge_ranges(s, &lo, &hi);
    float3 s0 = d * lo, s1 = d * hi;
    return (float2)(dot(min(s0, s1), (float3)(1.0f)), dot(max(s0, s1), (float3)(1.0f)));
}

/* How far along the segment [p, q] (a fraction in [0, 1]) a one-trilinear-grid-leaf mean
 * program is certified monotone with a slope along `dir` (per unit of dir) of one sign and
 * magnitude >= thr: cell by cell (GpCellWalk), the slope lies in sum_i dir_i [min, max]
 * of the cell's edge differences (index space). The walk stops at the first cell whose
 * range breaks the bound, at the sample box's faces, and where the mean, m_p at p, heads
 * for its zero set, once it is certified past it by `band` (its bound accumulated cell by
 * cell: the step then ends on the far side anyway, with a short bracket for the root
 * search). */
inline float gp_mean_monotone_reach(GP_MEAN_SPACE const MeanNode* n, float3 p, float3 q,
                                    float3 dir, float thr, float m_p, float band)
{
    GpCellWalk w;
    if (!gp_cell_walk_begin(n, p, q, &w)) return 0.0f;
    float3 r0 = n->row0.xyz, r1 = n->row1.xyz, r2 = n->row2.xyz;
    /* index-space slope per unit of the segment's fraction, in the samples' units */
    float3 u = (float3)(dot(r0, dir), dot(r1, dir), dot(r2, dir)) * length(q - p);
    float inv = 1.0f / n->scale;
    thr *= length(q - p) * inv;
    float v = m_p * inv;
    band *= inv;
    int sign = 0;
    do {
        float2 r = gp_cell_slope_range(w.s, u);
        float smin = r.x, smax = r.y;
        if (sign == 0) sign = smin >= thr ? 1 : (smax <= -thr ? -1 : 0);
        if (!(sign > 0 ? smin >= thr : (sign < 0 && smax <= -thr))) return w.t;
        /* the bound of the mean at the cell's exit: the least change, in the slope's sign */
        v += (sign > 0 ? smin : smax) * (w.tout - w.t);
        if (sign * m_p < 0.0f && (sign > 0 ? v >= band : v <= -band)) return w.tout;
    } while (gp_cell_walk_next(&w));
    return w.tend;
}

/* The first face (a fraction of the segment [p, q] in (0, 1]; 1: none) where the slope
 * along the segment of a one-trilinear-grid-leaf mean program jumps by `jump` (world
 * units per segment) or more: the midpoint of each cell's slope range (gp_cell_edge_ranges)
 * against the last cell's. fs_mean_step ends a try there (FS_MEAN_KINK). Past the sample
 * box nothing stops it. */
inline float gp_mean_kink_reach(GP_MEAN_SPACE const MeanNode* n, float3 p, float3 q,
                                float jump)
{
    GpCellWalk w;
    if (!gp_cell_walk_begin(n, p, q, &w)) return 1.0f;
    float3 r0 = n->row0.xyz, r1 = n->row1.xyz, r2 = n->row2.xyz;
    float3 u = (float3)(dot(r0, q - p), dot(r1, q - p), dot(r2, q - p));
    jump /= n->scale;
    float mid = NAN;
    do {
        float2 r = gp_cell_slope_range(w.s, u);
        float m = 0.5f * (r.y + r.x);
        if (w.t > 0.0f && fabs(m - mid) >= jump) return w.t;
        mid = m;
    } while (gp_cell_walk_next(&w));
    return 1.0f;
}

/* How far along the segment [p, q] (a fraction in [0, 1]) a one-trilinear-grid-leaf mean
 * program is certified to change by less than `budget` (world units): its total variation
 * there, bounded cell by cell (GpCellWalk) by the largest |edge difference| along each axis
 * times the segment's run along it. The same bound as fs_mean_cap's Lipschitz one, taken
 * along the ray instead of over a box: longer for rays that run along the surface. Past the
 * sample box's faces nothing is certified (tend). */
inline float gp_mean_variation_reach(GP_MEAN_SPACE const MeanNode* n, float3 p, float3 q,
                                     float budget)
{
    GpCellWalk w;
    if (!gp_cell_walk_begin(n, p, q, &w)) return 0.0f;
    float3 r0 = n->row0.xyz, r1 = n->row1.xyz, r2 = n->row2.xyz;
    /* index-space run per unit of the segment's fraction */
    float3 run = fabs((float3)(dot(r0, q - p), dot(r1, q - p), dot(r2, q - p)));
    float left = budget / n->scale;
    do {
        float3 lo, hi;
        gp_cell_edge_ranges(w.s, &lo, &hi);
        float rate = dot(run, max(fabs(lo), fabs(hi)));
        float use = rate * (w.tout - w.t);
        if (use >= left) return w.t + left / rate;
        left -= use;
    } while (gp_cell_walk_next(&w));
    return w.tend;
}
