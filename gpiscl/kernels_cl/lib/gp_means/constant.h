/* Constant mean: p0.x (gp/means.py Constant). */
inline float constant_mean(GP_MEAN_SPACE const MeanNode* n, float3 y, float4 p0, float4 p1,
                           float3* g)
{
    return p0.x;
}
