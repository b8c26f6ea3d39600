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

/* One manifold NEE sample at a vertex: a light chosen by the vertex's table (its pmf
 * sel), a listed sphere uniformly, a point y of the light by its area density (normal nl);
 * scale = count / (sel pdf_A). */
typedef struct {
    __global const Light* light;
    __global const Primitive* sphere;
    float3 y, nl;
    float scale;
} CausticChoice;

/* false where the chosen light has no area (its sample is 0) */
inline bool caustic_choose(__global const Primitive* prims, __global const Light* lights,
                           __global const LightChoice* table, int num_lights,
                           __global const int* spheres, int count, float4 u,
                           CausticChoice* ch)
{
    int li = light_choose(table, num_lights, u.x);
    ch->light = &lights[li];
    if (!LIGHT_IS_AREA(ch->light->kind)) return false;
    ch->sphere = &prims[spheres[min((int)(u.y * count), count - 1)]];
    float pdf_area = 0.0f;
    light_sample_point(ch->light->kind, ch->light, u.zw, &ch->y, &ch->nl, &pdf_area);
    ch->scale = count / (table[li].pmf * pdf_area);
    return pdf_area > 0.0f;
}

/* Russian roulette on a sample, in two stages (t: RenderParams.shadow_roulette, <= 0 turns
 * both off; each survivor is divided by its q, so any q > 0 keeps the estimate unbiased).
 * Away from the caustic itself a sample carries little, yet costs the root search, two
 * shadow rays and, near a GPIS, two flights: without roulette 91 % of the Cornell box's
 * samples carried less than t = 0.1 of the light point's direct scale.
 *
 * Before the root search: q = min(1, a R rho / t), a the vertex's albedo, R the sphere's,
 * rho the paraxial estimate of |d omega / d A| through the sphere over that of y seen
 * directly, m^2 |y - x|^2 / (D - r + v)^2: the sphere (focal length r / 2) images y, at L
 * from it, v = m L behind its surface at magnification m = (r / 2) / (L + r / 2), seen from x
 * at D from the centre. Oblique rays are imaged smaller: rho bounded the true ratio over
 * 20000 Cornell-box pairs (at most 0.99 of it). */
inline float caustic_survival_before(CausticChoice ch, __global const Material* materials,
                                     float3 x, float3 albedo, float t)
{
    float3 c = ch.sphere->p0.xyz;
    float r = ch.sphere->p0.w;
    float D = length(x - c), L = length(ch.y - c) - r;
    if (!(t > 0.0f) || !(L > 0.0f) || !(D > r)) return 1.0f;
    float m = 0.5f * r / (L + 0.5f * r);
    float3 v = ch.y - x;
    float g = D - r + m * L;
    float rho = m * m * dot(v, v) / (g * g);
    float R = max3(materials[ch.sphere->material].albedo.xyz);
    return fmin(1.0f, max3(albedo) * R * rho / t);
}

/* Once the weight c (already divided by the first q) is known: q = min(1, |c| / (t
 * |c_ref|)), c_ref the light point seen directly by a white Lambertian vertex facing it,
 * so a lost sample adds at most (t |c_ref|)^2 / 4 to its pixel's variance, as the
 * function-space mirrors' shadow roulette does (fs_random_normal.h). */
inline float caustic_survival_after(float3 c, float3 beta, CausticChoice ch, float3 x, float t)
{
    if (!(t > 0.0f) || !(max3(c) > 0.0f)) return 1.0f;
    float3 v = ch.y - x;
    float3 ref = beta * ch.light->radiance.xyz * (ch.scale * INV_PI_F / dot(v, v));
    return fmin(1.0f, max3(c) / (t * max3(ref)));
}

/* The chosen sample's weight at vertex x (shading normal n on the side of wo, a BSDF with
 * a density): f(x) R(p) Le(y) |d omega_x / d A_y| scale, R the sphere's reflectance (its
 * kind's own delta sample, so a conductor's Fresnel term too); p the reflection point and
 * np the sphere's normal there; 0 where there is no such path. */
inline float3 caustic_connect(CausticChoice ch, __global const Material* materials,
                              __global const Material* mat, float3 albedo, float3 x,
                              float3 n, float3 wo, float3* p, float3* np)
{
    __global const Primitive* s = ch.sphere;
    if (!caustic_reflection_point(s->p0.xyz, s->p0.w, x, ch.y, p, np))
        return (float3)(0.0f);
    float3 d = normalize(*p - x), r = normalize(ch.y - *p);
    float pdf;
    float3 f = material_eval(mat->kind, mat, albedo, n, wo, d, &pdf);
    if (!(max3(f) > 0.0f)) return (float3)(0.0f);
    __global const Material* sm = &materials[s->material];
    float3 l_out;
    float3 R = material_sample(sm->kind, sm, sm->albedo.xyz, *np, d, (float2)(0.0f), &l_out,
                               &pdf);
    float3 Le = light_area_radiance(ch.light->kind, ch.light, *p, ch.y, ch.nl, r, &pdf);
    return f * R * Le * (caustic_jacobian(x, *p, *np, s->p0.w, ch.y, ch.nl) * ch.scale);
}
