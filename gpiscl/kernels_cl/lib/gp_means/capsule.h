/* Capsule from a = p0.xyz to b = p1.xyz, radius p0.w (gp/means.py Capsule). */
inline float capsule_mean(GP_MEAN_SPACE const MeanNode* n, float3 y, float4 p0, float4 p1,
                          float3* g)
{
    float3 pa = y - p0.xyz, ba = p1.xyz - p0.xyz;
    /* the closest-point parameter is stationary: it adds no gradient term */
    float bb = dot(ba, ba);      /* a == b degenerates to a sphere */
    float h = clamp(dot(pa, ba) / (bb > 0.0f ? bb : 1.0f), 0.0f, 1.0f);
    return gp_norm_dir3(pa - h * ba, g) - p0.w;
}
