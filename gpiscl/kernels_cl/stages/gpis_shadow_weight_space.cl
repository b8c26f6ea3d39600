/* From: shadow queue.  To: contributions zeroed where the path's weight-space
 * realization of a GPIS object crosses zero between the vertex and the light. A
 * posterior's weights come from, or go to, the path's kriging cache slot. */
__kernel void gpis_shadow_weight_space(GPIS_SHADOW_WEIGHT_SPACE_PARAMS)
{
    int i = get_global_id(0);
    if (i >= counters[COUNT_SHADOW]) return;
    float4 o = shadow_o[i], d = shadow_d[i];
    int p = shadow_path[i];
    uint2 key = gpis_realization_key(params, path_pixel[p], path_sample[p]);
    WsPostCache C = WS_POST_CACHE;
    GpisTables T = GPIS_TABLES;
    for (int k = 0; k < params->num_gpis; ++k) {
        float3 n;
        float t = ws_object_first_root(gpis, k, kernels, mean_nodes, T, order_table, key,
                                       ws_post_slot(C, k, p), o.xyz, d.xyz, o.w, d.w, &n,
                                       counters);
        if (t < T_INFINITY) {
            shadow_contribution[i] = (float4)(0.0f);
            return;
        }
    }
}
