/* From: shadow queue.  To: contributions zeroed where the path's weight-space
 * realization of a GPIS object crosses zero between the vertex and the light. */
__kernel void gpis_shadow_weight_space(__constant RenderParams* params, PATH_PARAMS(path),
                                       SHADOW_PARAMS(shadow), __global const GpisObject* gpis,
                                       __global const GpKernel* kernels,
                                       __global const MeanNode* means,
                                       __global const float* order_table,
                                       __global int* counters)
{
    int i = get_global_id(0);
    if (i >= counters[COUNT_SHADOW]) return;
    float4 o = shadow_o[i], d = shadow_d[i];
    int p = shadow_path[i];
    uint2 key = gpis_realization_key(params, path_pixel[p], path_sample[p]);
    for (int k = 0; k < params->num_gpis; ++k) {
        __global const GpisObject* g = &gpis[k];
        float t0 = o.w, t1 = d.w;
        if (g->sampler != GPIS_SAMPLER_WEIGHT_SPACE || !gpis_proxy_clip(g, o.xyz, d.xyz, &t0, &t1))
            continue;
        float3 n;
        int status = 0;
        float t = ws_first_root(kernels[k], means + g->mean_first, g->mean_count,
                                order_table + g->order_first, g->order_count, g->features, key, k,
                                o.xyz, d.xyz, t0, t1, g->tolerance, &n, &status);
        if (status) atomic_inc(&counters[COUNT_GPIS_FAILED]);
        if (t < T_INFINITY) {
            shadow_contribution[i] = (float4)(0.0f);
            return;
        }
    }
}
