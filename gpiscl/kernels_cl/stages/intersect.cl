/* From: ray queue `in` (count known to the host).  To: each ray's closest surface hit
 * (hit_t, hit_prim; -1 when it escapes). GPIS stages may then move hits closer. */
__kernel void intersect(INTERSECT_PARAMS)
{
    int i = get_global_id(0);
    if (i >= num_rays) return;
    float4 o = in_o[i], d = in_d[i];
    float tmax = d.w;
    in_hit_prim[i] = trace_bvh(nodes, prims, materials, o.xyz, d.xyz, o.w, &tmax, 0);
    in_hit_t[i] = tmax;
}
