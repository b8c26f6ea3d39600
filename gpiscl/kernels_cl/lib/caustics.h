/* Manifold next-event estimation through classical mirror spheres: light that reaches a
 * non-delta vertex x after one reflection off a mirror sphere (a caustic). BSDF sampling
 * finds such a path only when its reflected ray happens to meet the light, rarely and
 * then with a large weight (the default Cornell box's fireflies). Here a point y of an
 * area light is sampled and the reflection point p between x and y solved for. Seen from
 * two points outside a sphere, p is unique (docs/design/light-sampling.md, "Caustics
 * through mirror spheres"), so these samples replace BSDF sampling on exactly those paths
 * (CAUSTIC_REFLECTED: emission.cl gives them 0), a partition of path space without MIS.
 * Single precision: scene coordinates are O(1..100) and the root is bracketed. */

/* The root search's limit: the Illinois method (regula falsi that halves the weight of an
 * end kept twice) reaches |h| < 1e-6 in 4 steps (median), 11 (99th percentile) and at most
 * 16 over 5000 random pairs at 1.05-6 radii (docs/design/light-sampling.md). */
#define CAUSTIC_MAX_STEPS 20

inline float caustic_cross2(float2 a, float2 b) { return a.x * b.y - a.y * b.x; }

/* h below at the sphere's point r m(s), m(s) = normalize((1 - s) (1, 0) + s e): the arc from
 * the direction to x (1, 0) to e, that to y, without a cos or sin per step */
inline float caustic_h(float s, float2 e, float r, float2 x2, float2 y2, float2* m,
                       float2* ux, float2* uy)
{
    *m = normalize((float2)(1.0f - s + s * e.x, s * e.y));
    *ux = normalize(x2 - r * *m);
    *uy = normalize(y2 - r * *m);
    return caustic_cross2(*m, *ux) + caustic_cross2(*m, *uy);
}

/* The reflection point p on sphere (c, r) of the path x -> p -> y, and the sphere's unit
 * normal n there; false where there is none that both points see. In the plane of c, x
 * and y, the normal bisects the directions to x and to y: h = cross(n, ux) + cross(n, uy)
 * = 0 on the arc between the directions to x (h >= 0) and to y (h <= 0), which the search
 * keeps as its bracket. */
inline bool caustic_reflection_point(float3 c, float r, float3 x, float3 y, float3* p,
                                     float3* n)
{
    float3 cx = x - c, cy = y - c;
    float X = length(cx), Y = length(cy);
    if (!(X > r) || !(Y > r)) return false;
    float3 a = cx / X;
    float ya = dot(cy, a);
    float3 b = cy - ya * a;
    float yb = length(b);
    if (!(yb > 1e-6f * Y)) return false;   /* y behind or in front of x: grazing or p = c + r a, measure 0 */
    b /= yb;
    float2 x2 = (float2)(X, 0.0f), y2 = (float2)(ya, yb), e = y2 / Y, m, ux, uy;
    float lo = 0.0f, hi = 1.0f;
    float hlo = caustic_h(lo, e, r, x2, y2, &m, &ux, &uy);
    float hhi = caustic_h(hi, e, r, x2, y2, &m, &ux, &uy);
    float s = (hlo <= 0.0f) ? lo : hi;
    int side = 0;
    for (int i = 0; i < CAUSTIC_MAX_STEPS && hlo > 0.0f && hhi < 0.0f; ++i) {
        s = (lo * hhi - hi * hlo) / (hhi - hlo);
        float h = caustic_h(s, e, r, x2, y2, &m, &ux, &uy);
        if (fabs(h) < 1e-6f || hi - lo <= 1e-6f) break;
        if (h > 0.0f) {
            lo = s, hlo = h;
            if (side == 1) hhi *= 0.5f;
            side = 1;
        } else {
            hi = s, hhi = h;
            if (side == -1) hlo *= 0.5f;
            side = -1;
        }
    }
    caustic_h(s, e, r, x2, y2, &m, &ux, &uy);
    if (!(dot(m, ux) > 0.0f && dot(m, uy) > 0.0f)) return false;
    *n = m.x * a + m.y * b;
    *p = c + r * *n;
    return true;
}

/* |d omega_x / d A_y|: how the solid angle at x maps onto the light's area through the
 * reflection at p (sphere radius r, normal n), by ray differentials (Igehy 1999): a
 * direction d + e from x (e: two orthonormal directions across d) moves the hit on the
 * sphere by dP, its normal by dP / r and so the reflected direction by dr, and the point
 * where the reflected ray meets the light's tangent plane (normal nl, distance s from p)
 * by dY. Without the sphere this is |cos_l| / dist^2, the ordinary area-to-solid-angle
 * factor. */
inline float caustic_jacobian(float3 x, float3 p, float3 n, float r, float3 y, float3 nl)
{
    float3 d = p - x;
    float t = length(d);
    d /= t;
    float dn = dot(d, n);
    float3 rr = d - 2.0f * dn * n;
    float s = length(y - p), rl = dot(rr, nl);
    if (dn == 0.0f || rl == 0.0f) return 0.0f;
    float3 e[2];
    make_frame(d, &e[0], &e[1]);
    float3 dy[2];
    for (int k = 0; k < 2; ++k) {
        float3 dp = t * e[k] - (t * dot(e[k], n) / dn) * d;
        float3 dnrm = dp / r;
        float3 dr = e[k] - 2.0f * ((dot(e[k], n) + dot(d, dnrm)) * n + dn * dnrm);
        float3 q = dp + s * dr;
        dy[k] = q - (dot(q, nl) / rl) * rr;
    }
    float area = length(cross(dy[0], dy[1]));
    return (area > 0.0f) ? 1.0f / area : 0.0f;
}

/* Whether primitive hp is one of the spheres the manifold NEE reflects lights off (the
 * list compile/scene.py makes: classical mirror spheres that are no light). */
inline bool caustic_listed(__global const int* spheres, int count, int hp)
{
    for (int i = 0; i < count; ++i)
        if (spheres[i] == hp) return true;
    return false;
}

/* One manifold NEE sample at vertex x (shading normal n on the side of wo, a BSDF with a
 * density): a light chosen by the vertex's table (its pmf sel), a listed sphere uniformly,
 * a point y of the light by its area density, then the reflection point p. Returns the
 * path's weight f(x) R(p) Le(y) |d omega_x / d A_y| / (sel pdf_A / count), R the sphere's
 * reflectance (its kind's own delta sample, so a conductor's Fresnel term too), and the
 * two segments' ends p (with the sphere's normal np) and y; 0 where there is no such path.
 * ref: the scale the roulette compares it with (caustic_survival). */
inline float3 caustic_sample(__global const Primitive* prims, __global const Material* materials,
                             __global const Light* lights, __global const LightChoice* table,
                             int num_lights, __global const int* spheres, int count,
                             __global const Material* mat, float3 albedo, float3 x, float3 n,
                             float3 wo, float4 u, float3* p, float3* np, float3* y,
                             float3* ref)
{
    int li = light_choose(table, num_lights, u.x);
    __global const Light* l = &lights[li];
    if (!LIGHT_IS_AREA(l->kind)) return (float3)(0.0f);
    __global const Primitive* s = &prims[spheres[min((int)(u.y * count), count - 1)]];
    float3 nl;
    float pdf_area = 0.0f;
    light_sample_point(l->kind, l, u.zw, y, &nl, &pdf_area);
    if (!(pdf_area > 0.0f) || !caustic_reflection_point(s->p0.xyz, s->p0.w, x, *y, p, np))
        return (float3)(0.0f);
    float3 d = normalize(*p - x), r = normalize(*y - *p);
    float pdf;
    float3 f = material_eval(mat->kind, mat, albedo, n, wo, d, &pdf);
    if (!(max3(f) > 0.0f)) return (float3)(0.0f);
    __global const Material* sm = &materials[s->material];
    float3 l_out;
    float3 R = material_sample(sm->kind, sm, sm->albedo.xyz, *np, d, (float2)(0.0f), &l_out,
                               &pdf);
    float3 Le = light_area_radiance(l->kind, l, *p, *y, nl, r, &pdf);
    float J = caustic_jacobian(x, *p, *np, s->p0.w, *y, nl);
    float scale = count / (table[li].pmf * pdf_area);
    float3 v = *y - x;
    *ref = Le * (scale * INV_PI_F / dot(v, v));
    return f * R * Le * (J * scale);
}

/* Russian roulette on a manifold NEE sample: its two segments cost two shadow rays and,
 * near a GPIS, two flights, and away from the caustic itself (the floor under the sphere)
 * it carries little. It survives with q = min(1, |c| / (t |c_ref|)) and then carries c / q;
 * c_ref is the same light point seen directly by a white Lambertian vertex facing it, the
 * scale of this vertex's direct light, so a lost sample adds at most (t |c_ref|)^2 / 4 to
 * its pixel's variance, as the function-space shadow roulette does (fs_random_normal.h);
 * t: RenderParams.shadow_roulette, <= 0 turns it off. */
inline float caustic_survival(float3 c, float3 c_ref, float t)
{
    if (!(t > 0.0f)) return 1.0f;
    return fmin(1.0f, max3(c) / (t * max3(c_ref)));
}
