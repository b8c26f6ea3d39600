/* Render preparation (host: render/occupancy_boxes.py): the occupancy box of every GPIS
 * object with an occupancy bound, as the index range of the lattice cells (cells^3 over
 * the proxy's bounding box) where the prior mean may reach occupancy_level: the lowest
 * indices in .s012, the highest in .s345. A cell is left out when its centre's mean,
 * less the march's rounding allowance (gpis_proxy.h) and the global slope bound times
 * the half diagonal, is above the level: then so is every point of the cell, and the
 * occupancy marches would skip all of it. One work item per (object, cell). */

__kernel void gpis_occupancy_boxes(GPIS_OCCUPANCY_BOXES_PARAMS)
{
    int n3 = cells * cells * cells, id = get_global_id(0);
    if (id >= num_gpis * n3) return;
    int k = id / n3, c = id % n3;
    __global const GpisObject* g = gpis + k;
    if (!(g->occupancy_level > 0.0f)) return;
    float3 lo = g->proxy_p0.xyz, hi = g->proxy_p1.xyz;
    if (g->proxy_kind == GPIS_PROXY_SPHERE) {
        lo = g->proxy_p0.xyz - g->proxy_p0.w;
        hi = g->proxy_p0.xyz + g->proxy_p0.w;
    }
    int3 i = (int3)(c / (cells * cells), (c / cells) % cells, c % cells);
    float3 h = (hi - lo) / (float)cells;
    float3 x = lo + (convert_float3(i) + 0.5f) * h;
    __global const MeanNode* mean = mean_nodes + g->mean_first;
    float mu = gp_mean_value(mean, g->mean_count, x);
    float lip = gp_mean_lipschitz(mean, g->mean_count);
    float round = 8.0f * FLT_EPSILON * (fabs(mu) + lip * (fabs(x.x) + fabs(x.y) + fabs(x.z)));
    /* NaN: kept (clip nothing there), as the march stops at a NaN */
    if (mu - g->occupancy_level - round - lip * 0.5f * length(h) > 0.0f) return;
    __global int* b = (__global int*)(boxes + k);
    atomic_min(b + 0, i.x);
    atomic_min(b + 1, i.y);
    atomic_min(b + 2, i.z);
    atomic_max(b + 3, i.x);
    atomic_max(b + 4, i.y);
    atomic_max(b + 5, i.z);
}
