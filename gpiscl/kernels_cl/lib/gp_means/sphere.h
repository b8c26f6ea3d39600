/* Sphere of radius p0.x (gp/means.py Sphere). */
inline float sphere_mean(GP_MEAN_SPACE const MeanNode* n, float3 y, float4 p0, float4 p1,
                         float3* g)
{
    return gp_norm_dir3(y, g) - p0.x;
}
