/* From: shadow queue.  To: the light sample's contribution added to its path when
 * nothing opaque lies between the vertex and the light. */
__kernel void shadow_rays(SHADOW_RAYS_PARAMS)
{
    int i = get_global_id(0);
    if (i >= counters[COUNT_SHADOW]) return;
    if (max3(shadow_contribution[i].xyz) <= 0.0f) return;  /* blocked by a GPIS stage */
    float4 o = shadow_o[i], d = shadow_d[i];
    /* stop short of the light's own surface */
    float tmax = (d.w >= T_INFINITY) ? T_INFINITY : d.w * (1.0f - 1e-4f) - ray_epsilon(o.xyz);
    if (trace_bvh(nodes, prims, materials, o.xyz, d.xyz, 0.0f, &tmax, 1) >= 0) return;
    int p = shadow_path[i];
    path_radiance[p] += shadow_contribution[i];
}
