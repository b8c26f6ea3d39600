/* From: shadow queue.  To: the light sample's contribution added to its path when
 * nothing opaque lies between the vertex and the light: for a two-segment record pair
 * (a manifold NEE sample, lib/caustics.h) the head adds it where neither segment is
 * blocked, by a GPIS stage (zeroed) or here. */
inline bool shadow_segment_clear(__global const BvhNode* nodes,
                                 __global const Primitive* prims,
                                 __global const Material* materials, float4 o, float4 d)
{
    /* stop short of the light's own surface (or the mirror sphere's) */
    float tmax = (d.w >= T_INFINITY) ? T_INFINITY : d.w * (1.0f - 1e-4f) - ray_epsilon(o.xyz);
    return trace_bvh(nodes, prims, materials, o.xyz, d.xyz, 0.0f, &tmax, 1) < 0;
}

__kernel void shadow_rays(SHADOW_RAYS_PARAMS)
{
    int i = get_global_id(0);
    if (i >= counters[COUNT_SHADOW]) return;
    float4 c = shadow_contribution[i];
    if (max3(c.xyz) <= 0.0f || c.w == SHADOW_TAIL) return;  /* blocked by a GPIS stage */
    if (!shadow_segment_clear(nodes, prims, materials, shadow_o[i], shadow_d[i])) return;
    if (c.w == SHADOW_HEAD && (max3(shadow_contribution[i + 1].xyz) <= 0.0f
                               || !shadow_segment_clear(nodes, prims, materials,
                                                        shadow_o[i + 1], shadow_d[i + 1])))
        return;
    int p = shadow_path[i];
    path_radiance[p] += (float4)(c.xyz, 0.0f);
}
