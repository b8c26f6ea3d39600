/* From: ray queue `in` (count known to the host).  To: each ray's closest hit, and its
 * index pushed to the hit or the escaped queue. */
__kernel void intersect(__constant RenderParams* params, int num_rays, RAY_PARAMS(in),
                        INDEX_PARAMS(hits), INDEX_PARAMS(escaped),
                        __global int* counters, __global const BvhNode* nodes,
                        __global const Primitive* prims, __global const Material* materials)
{
    int i = get_global_id(0);
    if (i >= num_rays) return;
    float4 o = in_o[i], d = in_d[i];
    float tmax = d.w;
    int prim = trace_bvh(nodes, prims, materials, o.xyz, d.xyz, o.w, &tmax, 0);
    in_hit_t[i] = tmax;
    in_hit_prim[i] = prim;
    if (prim >= 0) hits_ray[atomic_inc(&counters[COUNT_HITS])] = i;
    else escaped_ray[atomic_inc(&counters[COUNT_ESCAPED])] = i;
}
