/* Box of half extents p1.xyz with edges rounded by p0.x (gp/means.py RoundedBox). */
inline float rounded_box_mean(GP_MEAN_SPACE const MeanNode* n, float3 y, float4 p0, float4 p1,
                              float3* g)
{
    return gp_sd_box(y, p1.xyz - p0.x, g) - p0.x;
}
