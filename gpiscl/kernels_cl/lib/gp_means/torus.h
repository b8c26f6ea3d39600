/* Torus around y, major radius p0.x, minor p0.y (gp/means.py Torus). */
inline float torus_mean(GP_MEAN_SPACE const MeanNode* n, float3 y, float4 p0, float4 p1,
                        float3* g)
{
    float2 radial, qd;
    float rho = gp_norm_dir2(y.xz, &radial);
    float v = gp_norm_dir2((float2)(rho - p0.x, y.y), &qd) - p0.y;
    *g = (float3)(qd.x * radial.x, qd.y, qd.x * radial.y);
    return v;
}
