/* Fresnel reflectance of a conductor, shared by the kinds that reflect off a metal
 * (mirror.h with a conductor, rough_conductor.h); joined before every material file
 * (kinds/materials.py, the table's shared device file). */

/* exact unpolarised reflectance of eta + i k for incidence cosine c (PBRT's FrConductor) */
inline float3 fresnel_conductor(float c, float3 eta, float3 k)
{
    c = clamp(c, 0.0f, 1.0f);
    float c2 = c * c, s2 = 1.0f - c2;
    float3 t0 = eta * eta - k * k - s2;
    float3 a2b2 = sqrt(t0 * t0 + 4.0f * eta * eta * k * k);
    float3 a = sqrt(fmax(0.5f * (a2b2 + t0), 0.0f));
    float3 rs = (a2b2 + c2 - 2.0f * a * c) / (a2b2 + c2 + 2.0f * a * c);
    float3 t1 = c2 * a2b2 + s2 * s2, t2 = 2.0f * a * c * s2;
    float3 rp = rs * (t1 - t2) / (t1 + t2);
    return 0.5f * (rs + rp);
}
