/* BVH traversal over all surface primitives (built by gpiscl/host/compile/bvh.py).
 * Inner nodes store their two children adjacently; a leaf lists primitives directly
 * (the host reorders the primitive array into leaf order). */

#define BVH_STACK_SIZE 64

inline int ray_box(float4 lo, float4 hi, float3 o, float3 inv_d, float tmin, float tmax)
{
    float3 t0 = (lo.xyz - o) * inv_d, t1 = (hi.xyz - o) * inv_d;
    float3 tn = fmin(t0, t1), tf = fmax(t0, t1);
    float enter = fmax(tmin, max3(tn));
    float leave = fmin(tmax, fmin(tf.x, fmin(tf.y, tf.z)));
    return enter <= leave;
}

/* Closest hit in (tmin, tmax). any_hit: stop at the first opaque hit (shadow rays);
 * pass-through (null-BSDF) primitives never occlude. Returns the primitive or -1. */
inline int trace_bvh(__global const BvhNode* nodes, __global const Primitive* prims,
                     __global const Material* materials, float3 o, float3 d,
                     float tmin, float* tmax, int any_hit)
{
    /* An inner root's children start at 1, so (count 0, first 0) marks an empty scene. */
    if (nodes[0].count == 0 && nodes[0].left_or_first == 0) return -1;
    float3 inv_d = 1.0f / d;
    int stack[BVH_STACK_SIZE];
    int top = 0, hit = -1;
    stack[top++] = 0;
    while (top > 0) {
        __global const BvhNode* node = &nodes[stack[--top]];
        if (!ray_box(node->lo, node->hi, o, inv_d, tmin, *tmax)) continue;
        if (node->count > 0) {
            for (int i = 0; i < node->count; ++i) {
                int pi = node->left_or_first + i;
                __global const Primitive* p = &prims[pi];
                if (any_hit && MATERIAL_IS_PASS_THROUGH(materials[p->material].kind)) continue;
                float t = intersect_primitive(p, o, d, tmin, *tmax);
                if (t < *tmax) {
                    *tmax = t;
                    hit = pi;
                    if (any_hit) return hit;
                }
            }
        } else if (top + 2 <= BVH_STACK_SIZE) {
            stack[top++] = node->left_or_first + 1;
            stack[top++] = node->left_or_first;
        }
    }
    return hit;
}
