/* Sampled mean: the grid leaf and its payload records (gp_mean.h gp_mean_grid; layout in
 * gpiscl/host/layout/gp_records.py). */
inline float grid_mean(GP_MEAN_SPACE const MeanNode* n, float3 y, float4 p0, float4 p1,
                       float3* g)
{
    return gp_mean_grid(n, y, g);
}
