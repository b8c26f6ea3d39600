/* Ray-primitive intersection and surface normals, float32: scene coordinates are
 * O(1..100) and hit points are re-offset by ray_epsilon, so single precision suffices. */

/* Nearest t in (tmin, tmax) where the ray meets the primitive, or T_INFINITY. */
inline float intersect_primitive(__global const Primitive* p, float3 o, float3 d,
                                 float tmin, float tmax)
{
    float t = T_INFINITY;
    if (p->kind == PRIM_SPHERE) {
        float3 oc = o - p->p0.xyz;
        float r = p->p0.w;
        float b = dot(oc, d);
        float c = dot(oc, oc) - r * r;
        float disc = b * b - c;
        if (disc < 0.0f) return T_INFINITY;
        float s = sqrt(disc);
        float t0 = -b - s, t1 = -b + s;
        t = (t0 > tmin) ? t0 : t1;
    } else if (p->kind == PRIM_TRIANGLE) {
        /* Moller-Trumbore */
        float3 e1 = p->p1.xyz - p->p0.xyz, e2 = p->p2.xyz - p->p0.xyz;
        float3 pv = cross(d, e2);
        float det = dot(e1, pv);
        if (fabs(det) < 1e-20f) return T_INFINITY;
        float inv = 1.0f / det;
        float3 tv = o - p->p0.xyz;
        float u = dot(tv, pv) * inv;
        if (u < 0.0f || u > 1.0f) return T_INFINITY;
        float3 qv = cross(tv, e1);
        float v = dot(d, qv) * inv;
        if (v < 0.0f || u + v > 1.0f) return T_INFINITY;
        t = dot(e2, qv) * inv;
    } else {
        /* rectangle (corner p0, edges p1, p2) and disk (centre p0.xyz, normal p1) */
        float3 n = (p->kind == PRIM_RECTANGLE) ? cross(p->p1.xyz, p->p2.xyz) : p->p1.xyz;
        float denom = dot(n, d);
        if (fabs(denom) < 1e-20f) return T_INFINITY;
        t = dot(p->p0.xyz - o, n) / denom;
        float3 h = o + t * d - p->p0.xyz;
        if (p->kind == PRIM_RECTANGLE) {
            float a = dot(h, p->p1.xyz) / dot(p->p1.xyz, p->p1.xyz);
            float b = dot(h, p->p2.xyz) / dot(p->p2.xyz, p->p2.xyz);
            if (a < 0.0f || a > 1.0f || b < 0.0f || b > 1.0f) return T_INFINITY;
        } else if (dot(h, h) > p->p0.w * p->p0.w) {
            return T_INFINITY;
        }
    }
    return (t > tmin && t < tmax) ? t : T_INFINITY;
}

/* Geometric normal at a point on the primitive (unit, not flipped towards the ray). */
inline float3 primitive_normal(__global const Primitive* p, float3 x)
{
    if (p->kind == PRIM_SPHERE) return normalize(x - p->p0.xyz);
    if (p->kind == PRIM_TRIANGLE)
        return normalize(cross(p->p1.xyz - p->p0.xyz, p->p2.xyz - p->p0.xyz));
    if (p->kind == PRIM_RECTANGLE) return normalize(cross(p->p1.xyz, p->p2.xyz));
    return p->p1.xyz;
}
