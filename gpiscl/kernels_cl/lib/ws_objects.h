/* The weight-space GPIS objects of a scene as seen by one ray: shared by the hit stage and
 * the shadow stage so both see exactly the same realization and root rule. */

/* The batch's kept posterior weights (render/kriging_cache.py lays them out): per path,
 * tags_per_path tags and doubles_per_path values; table[k] = (tag index, value offset)
 * of object k within its path's share, or -1 (a prior object, or the cache off). */
typedef struct {
    __global uint4* tags;
    __global double* values;
    __global const int2* table;
    int tags_per_path, doubles_per_path;
} WsPostCache;

/* The struct made of the cache's stage kernel parameters (layout/stages.py WS_POST_CACHE) */
#define WS_POST_CACHE {post_tags, post_values, post_table, post_tags_per_path, \
    post_doubles_per_path}

/* Object k's slot of path p (batch index), or none. */
inline WsPostSlot ws_post_slot(WsPostCache C, int k, int p)
{
    int2 at = C.table[k];
    WsPostSlot S = {0, 0};
    if (at.x >= 0) {
        S.tag = C.tags + (size_t)p * C.tags_per_path + at.x;
        S.values = C.values + (size_t)p * C.doubles_per_path + at.y;
    }
    return S;
}

/* First crossing of object k's realization (path key `key`) along [t0, t1] clipped to its
 * proxy and its occupancy bounds, or T_INFINITY (also when k is not a weight-space
 * object). A posterior object (observations) conditions the path's realization on them
 * (ws_posterior.h), with the weights kept in slot S of the path. A search that cannot
 * decide is counted in COUNT_GPIS_FAILED and reported by the host as undecided. */
inline float ws_object_first_root(__global const GpisObject* gpis, int k,
                                  __global const GpKernel* kernels,
                                  __global const MeanNode* means, GpisTables T,
                                  __global const float* order_table, uint2 key, WsPostSlot S,
                                  float3 o, float3 d, float t0, float t1, float3* normal,
                                  __global int* counters)
{
    __global const GpisObject* g = &gpis[k];
    if (g->sampler != GPIS_SAMPLER_WEIGHT_SPACE || !gpis_proxy_clip(g, T.planes, o, d, &t0, &t1)
        || !gpis_occupancy_clip(g, means, gpis_occ_mask(T, k), o, d, &t0, &t1, 1))
        return T_INFINITY;
    int status = 0, evaluations;
    WsPostBlock B = ws_posterior_block(g, T.obs, T.doubles);
    /* two call sites: the prior's compiles to the search without any posterior code */
    float t = B.n ? ws_first_root_post(B, S, kernels[k], means + g->mean_first, g->mean_count,
                                       order_table + g->order_first, g->order_count,
                                       g->features, key, k, o, d, t0, t1, g->tolerance,
                                       normal, &status, &evaluations)
                  : ws_first_root(kernels[k], means + g->mean_first, g->mean_count,
                                  order_table + g->order_first, g->order_count, g->features,
                                  key, k, o, d, t0, t1, g->tolerance, normal, &status);
    if (status) atomic_inc(&counters[COUNT_GPIS_FAILED]);
    return t;
}
