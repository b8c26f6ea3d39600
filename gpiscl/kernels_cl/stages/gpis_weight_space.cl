/* From: ray queue `in` with surface hits.  To: hits moved to the first zero crossing of
 * the path's weight-space realization of any GPIS object, with its analytic normal. A
 * posterior's weights come from, or go to, the path's kriging cache slot. */
__kernel void gpis_weight_space(GPIS_WEIGHT_SPACE_PARAMS)
{
    int i = get_global_id(0);
    if (i >= num_rays) return;
    float4 o = in_o[i], d = in_d[i];
    int p = in_path[i];
    uint2 key = gpis_realization_key(params, path_pixel[p], path_sample[p]);
    float t_hit = in_hit_t[i];
    int hit = -1;
    float3 n_hit = (float3)(0.0f);
    WsPostCache C = WS_POST_CACHE;
    GpisTables T = GPIS_TABLES;
    for (int k = 0; k < params->num_gpis; ++k) {
        float3 n;
        float t = ws_object_first_root(gpis, k, kernels, mean_nodes, T, order_table, key,
                                       ws_post_slot(C, k, p), o.xyz, d.xyz, o.w, t_hit, &n,
                                       counters);
        if (t < t_hit) {
            t_hit = t;
            hit = k;
            n_hit = n;
        }
    }
    if (hit >= 0) {
        in_hit_t[i] = t_hit;
        in_hit_prim[i] = GPIS_HIT_BASE - hit;
        in_hit_n[i] = (float4)(n_hit, 0.0f);
    }
}
