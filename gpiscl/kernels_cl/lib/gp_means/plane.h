/* Plane: max(scale (n.y - d), min) with p0 = (d, scale, min), p1.xyz = unit normal
 * (gp/means.py Plane). */
inline float plane_mean(GP_MEAN_SPACE const MeanNode* n, float3 y, float4 p0, float4 p1,
                        float3* g)
{
    float v = p0.y * (dot(p1.xyz, y) - p0.x);
    if (v < p0.z) v = p0.z;          /* clamped: flat */
    else *g = p0.y * p1.xyz;
    return v;
}
