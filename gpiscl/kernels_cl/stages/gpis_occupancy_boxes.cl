/* Render preparation (host: render/occupancy_boxes.py): the occupancy cells of every GPIS
 * object with an occupancy bound, on a lattice of OCC_CELLS^3 cells over its proxy's
 * bounds (gpis_occ_lattice): a bit per cell in `cells` (OCC_WORDS words an object), and
 * the index range of the cells set in `boxes` (the lowest in .s012, the highest in
 * .s345). A cell is left clear when its centre's mean, less the march's rounding
 * allowance (gpis_proxy.h) and the global slope bound times 1.001 half diagonals, is
 * above the level: then so is every point within that distance of the centre, which
 * takes in the whole cell and whatever the traversal's float arithmetic may place in it
 * (gpis_occupancy_cells). One work item per (object, cell). */

__kernel void gpis_occupancy_boxes(GPIS_OCCUPANCY_BOXES_PARAMS)
{
    int n3 = OCC_CELLS * OCC_CELLS * OCC_CELLS, id = get_global_id(0);
    if (id >= num_gpis * n3) return;
    int k = id / n3, c = id % n3;
    __global const GpisObject* g = gpis + k;
    if (!(g->occupancy_level > 0.0f)) return;
    float3 lo, h;
    gpis_occ_lattice(g, &lo, &h);
    int3 i = (int3)(c / (OCC_CELLS * OCC_CELLS), (c / OCC_CELLS) % OCC_CELLS, c % OCC_CELLS);
    float3 x = lo + (convert_float3(i) + 0.5f) * h;
    __global const MeanNode* mean = mean_nodes + g->mean_first;
    float mu = gp_mean_value(mean, g->mean_count, x);
    float lip = gp_mean_lipschitz(mean, g->mean_count);
    float round = 8.0f * FLT_EPSILON * (fabs(mu) + lip * (fabs(x.x) + fabs(x.y) + fabs(x.z)));
    /* NaN: set (clip nothing there), as the march stops at a NaN */
    if (mu - g->occupancy_level - round - lip * 0.5005f * length(h) > 0.0f) return;
    atomic_or(cells + (size_t)k * OCC_WORDS + (c >> 5), 1u << (c & 31));   /* 32 bits a word */
    __global int* b = (__global int*)(boxes + k);
    atomic_min(b + 0, i.x);
    atomic_min(b + 1, i.y);
    atomic_min(b + 2, i.z);
    atomic_max(b + 3, i.x);
    atomic_max(b + 4, i.y);
    atomic_max(b + 5, i.z);
}
