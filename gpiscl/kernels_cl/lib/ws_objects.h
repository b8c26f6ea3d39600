/* The weight-space GPIS objects of a scene as seen by one ray: shared by the hit stage and
 * the shadow stage so both see exactly the same realization and root rule. */

/* First crossing of object k's realization (path key `key`) along [t0, t1] clipped to its
 * proxy and its occupancy bounds, or T_INFINITY (also when k is not a weight-space
 * object). A posterior object (observations) conditions the path's realization on them
 * (ws_posterior.h). A search that cannot decide is counted in COUNT_GPIS_FAILED and
 * reported by the host as undecided. */
inline float ws_object_first_root(__global const GpisObject* gpis, int k,
                                  __global const GpKernel* kernels,
                                  __global const MeanNode* means,
                                  __global const float* order_table, uint2 key, float3 o,
                                  float3 d, float t0, float t1, float3* normal,
                                  __global int* counters)
{
    __global const GpisObject* g = &gpis[k];
    if (g->sampler != GPIS_SAMPLER_WEIGHT_SPACE || !gpis_proxy_clip(g, means, o, d, &t0, &t1)
        || !gpis_occupancy_clip(g, means, o, d, &t0, &t1, 1))
        return T_INFINITY;
    int status = 0, evaluations;
    WsPostBlock B = ws_posterior_block(means, g->mean_first);
    /* two call sites: the prior's compiles to the search without any posterior code */
    float t = B.n ? ws_first_root_post(B, kernels[k], means + g->mean_first, g->mean_count,
                                       order_table + g->order_first, g->order_count,
                                       g->features, key, k, o, d, t0, t1, g->tolerance,
                                       normal, &status, &evaluations)
                  : ws_first_root(kernels[k], means + g->mean_first, g->mean_count,
                                  order_table + g->order_first, g->order_count, g->features,
                                  key, k, o, d, t0, t1, g->tolerance, normal, &status);
    if (status) atomic_inc(&counters[COUNT_GPIS_FAILED]);
    return t;
}
