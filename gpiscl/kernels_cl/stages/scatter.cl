/* From: hit queue.  To: for each surface hit, a shadow ray towards a sampled light
 * (next-event estimation, MIS-weighted), a manifold NEE sample's two shadow segments
 * where the scene lists mirror spheres (lib/caustics.h), and a continuation ray in ray
 * queue `out`. Null (pass-through) surfaces forward the ray unchanged and switch the
 * medium. */
__kernel void scatter(SCATTER_PARAMS)
{
    int i = get_global_id(0);
    if (i >= counters[COUNT_HITS]) return;
    int r = hits_ray[i];
    int p = in_path[r];
    int hp = in_hit_prim[r];
    float3 wo = in_d[r].xyz;
    float3 x = in_o[r].xyz + in_hit_t[r] * wo;
    float3 ng;
    float eps;
    __global const Primitive* prim = 0;
    __global const Material* mat;
    float3 albedo;
    if (hp >= 0) {
        prim = &prims[hp];
        mat = &materials[prim->material];
        ng = primitive_normal(prim, x);
        eps = ray_epsilon(x);
        albedo = mat->albedo.xyz;
    } else {
        /* GPIS event: the stage sampled the normal. Rays leave from the root itself: the
         * one-sided hit rule (only f >= 0 -> f < 0 counts) needs no offset. */
        __global const GpisObject* g = &gpis[GPIS_HIT_BASE - hp];
        mat = &materials[g->material];
        /* the object's colour field scales the micro-BSDF albedo where the path hit */
        albedo = mat->albedo.xyz * gpis_field_eval(field_nodes, g->color_field, x, 1.0f);
        ng = in_hit_n[r].xyz;
        eps = 0.0f;
        if (!(dot(ng, wo) < 0.0f)) {  /* a crossing's gradient must face the ray */
            atomic_inc(&counters[COUNT_KILLED]);
            return;
        }
    }

    if (MATERIAL_IS_PASS_THROUGH(mat->kind)) {
        if (prim && prim->medium >= 0) path_medium[p] = (dot(wo, ng) < 0.0f) ? prim->medium : -1;
        int k = atomic_inc(&counters[COUNT_RAYS_OUT]);
        out_o[k] = (float4)(x, eps);
        out_d[k] = (float4)(wo, T_INFINITY);
        out_path[k] = p;
        return;
    }

    if (params->aov && path_depth[p] == 0) {
        /* the path's first scattering event: the guides a denoiser takes (aov.py). Until
         * then prev_pos holds the camera position, so its w-less distance is the depth. */
        path_aov_position[p] = (float4)(x, length(x - path_prev_pos[p].xyz));
        path_aov_normal[p] = (float4)((dot(ng, wo) < 0.0f) ? ng : -ng, 1.0f);
        path_aov_albedo[p] = (float4)(albedo, 0.0f);
    }

    int depth = path_depth[p];
    float3 beta = path_beta[p].xyz;
    if (max3(albedo) <= 0.0f) return;
    if (depth >= params->max_depth) {   /* ended by the bounce limit: a bias, reported */
        atomic_inc(&counters[COUNT_DEPTH_CUT]);
        return;
    }
    int pixel = path_pixel[p], sample = path_sample[p], bounce = params->bounce;
    float3 n = (dot(ng, wo) < 0.0f) ? ng : -ng;  /* shading normal on the side of wo */
    float3 xo = x + eps * n;                      /* origin for rays leaving that side */

    float3 wi;
    float pdf_bsdf;
    /* a function-space GPIS hit knows the law its normal was drawn from, which the
     * material's random_normal mode may use (fs_random_normal.h); a sampler that reports
     * no law (law_s = 0: a free flight that does not fill FsResult.law_*) gives none */
    int fs_hit = hp < 0 && gpis[GPIS_HIT_BASE - hp].sampler == GPIS_SAMPLER_FUNCTION_SPACE
                 && params->fs_nee && in_hit_law_m[r].w < 0.0f;
    int rn = fs_random_normal_mode(mat->kind, fs_hit);
    float p_n0 = 0.0f;   /* RANDOM_NORMAL_PAIRS: p_Omega of the sampled normal */
    FsNormalLaw law = fs_normal_law(in_hit_law_m[r], in_hit_law_a[r], in_hit_law_b[r]);
    float4 ub = rng4(params->seed, pixel, sample, bounce, DIM_BSDF);
    /* --- next-event estimation --- */
    /* environments: left to BSDF sampling where the mode says so (escaped_rays.cl gives
     * them weight 1 after such a vertex); a constant one by the cosine hemisphere where
     * the BSDF vanishes below n (diffuse, rough conductor at a fixed normal) */
    int above = rn == RANDOM_NORMAL_SAMPLED && (mat->kind == MATERIAL_DIFFUSE
                                                || mat->kind == MATERIAL_ROUGH_CONDUCTOR);
    int env_nee = !fs_random_normal_env_nee(rn) ? ENV_NEE_NONE
                  : above ? ENV_NEE_ABOVE : ENV_NEE_OWN;
    if (fs_random_normal_has_density(mat->kind, rn) && params->nee && params->num_lights > 0) {
        float4 ul = rng4(params->seed, pixel, sample, bounce, DIM_LIGHT);
        __global const LightChoice* table = light_choice_at(light_choice, params->num_lights,
                                                            env_nee);
        int li = light_choose(table, params->num_lights, ul.x);
        float sel = table[li].pmf;   /* the probability of choosing light li */
        EnvMap m = {env_texels, env_marginal, env_conditional, params->env_width,
                    params->env_height};
        float3 wl;
        float dist, pdf_light;
        float3 Le = (env_nee == ENV_NEE_ABOVE && lights[li].kind == LIGHT_ENVIRONMENT)
            ? environment_sample_above(&lights[li], n, ul.yz, &wl, &dist, &pdf_light)
            : light_sample(lights[li].kind, &lights[li], m, xo, ul.yz, &wl, &dist,
                           &pdf_light);
        if (env_nee == ENV_NEE_NONE && LIGHT_IS_ENVIRONMENT(lights[li].kind))
            Le = (float3)(0.0f);
        float pdf_f;
        float4 grad = (float4)(0.0f);   /* the shadow ray keeps the vertex's normal */
        float3 f = fs_random_normal_eval(rn, mat, law, albedo, n, wo, wl, &pdf_f, &grad);
        /* the light strategy's density includes choosing light li (sel), as the BSDF
         * strategy's weight in emission.cl and escaped_rays.cl does: the two weights of
         * one direction must sum to 1 */
        float w = (pdf_light > 0.0f) ? power_heuristic(pdf_light * sel, pdf_f) : 1.0f;
        float inv_pdf = (pdf_light > 0.0f) ? 1.0f / pdf_light : 1.0f;
        if (rn == RANDOM_NORMAL_PAIRS && pdf_light > 0.0f)
            f = fs_random_normal_pairs(mat, law, albedo, n, wo, wl, pdf_light * sel, ul.w,
                                       ub.zw, &pdf_f, &grad, &w);
        float3 c = beta * f * Le * (w * inv_pdf / sel);
        /* a light sample that picks the normal pays a function-space shadow flight:
         * roulette where it carries little (fs_random_normal.h) */
        float q = fs_random_normal_shadow_survival(rn, c, beta * Le * (INV_PI_F * inv_pdf / sel),
                                                   params->shadow_roulette);
        if (q < 1.0f)
            c = (rng4(params->seed, pixel, sample, bounce, DIM_SHADOW_ROULETTE).x < q)
                ? c / q : (float3)(0.0f);
        if (max3(c) > 0.0f) {
            int k = atomic_inc(&counters[COUNT_SHADOW]);
            shadow_o[k] = (float4)(xo, 0.0f);
            shadow_d[k] = (float4)(wl, dist);
            shadow_contribution[k] = (float4)(c, 0.0f);
            shadow_path[k] = p;
            shadow_grad[k] = grad;
        }
    }
    /* --- manifold NEE: area lights seen in the listed mirror spheres (caustics.h). The
     * state says the continuation's paths x -> such a sphere -> area light were counted
     * here; it is set before any sample, for every vertex that takes one, so that the
     * partition does not depend on random outcomes. */
    int caustic = CAUSTIC_NONE;
    if (params->num_caustic_spheres == 0) {
        /* no listed spheres: no manifold NEE, and no path counted by one */
    } else if (params->nee && rn == RANDOM_NORMAL_SAMPLED && !MATERIAL_IS_DELTA(mat->kind)
               && depth + 1 < params->max_depth) {
        caustic = CAUSTIC_VERTEX;
        CausticChoice ch;
        float3 cp, cn, c = (float3)(0.0f);
        float4 ur = rng4(params->seed, pixel, sample, bounce, DIM_CAUSTIC_ROULETTE);
        if (caustic_choose(prims, lights,
                           light_choice_at(light_choice, params->num_lights, env_nee),
                           params->num_lights, caustic_spheres, params->num_caustic_spheres,
                           rng4(params->seed, pixel, sample, bounce, DIM_CAUSTIC), &ch)) {
            float q = caustic_survival_before(ch, materials, xo, albedo, params->shadow_roulette);
            if (ur.x < q)
                c = beta * caustic_connect(ch, materials, mat, albedo, xo, n, wo, &cp, &cn) / q;
            q = caustic_survival_after(c, beta, ch, xo, params->shadow_roulette);
            c = (ur.y < q) ? c / q : (float3)(0.0f);
        }
        if (max3(c) > 0.0f) {
            int k = atomic_add(&counters[COUNT_SHADOW], 2);
            float3 po = cp + ray_epsilon(cp) * cn;   /* the sphere's outside */
            float3 d0 = cp - xo, d1 = ch.y - po;
            float t0 = length(d0), t1 = length(d1);
            shadow_o[k] = (float4)(xo, 0.0f);
            shadow_d[k] = (float4)(d0 / t0, t0);
            shadow_contribution[k] = (float4)(c, SHADOW_HEAD);
            shadow_o[k + 1] = (float4)(po, 0.0f);
            shadow_d[k + 1] = (float4)(d1 / t1, t1);
            shadow_contribution[k + 1] = (float4)(c, SHADOW_TAIL);
            shadow_path[k] = shadow_path[k + 1] = p;
            shadow_grad[k] = shadow_grad[k + 1] = (float4)(0.0f);
        }
    } else if (hp >= 0 && path_caustic[p] == CAUSTIC_VERTEX && dot(wo, ng) < 0.0f
               && caustic_listed(caustic_spheres, params->num_caustic_spheres, hp)) {
        /* from outside only: a vertex inside a sphere (concave side, several roots) has no
         * manifold sample there, so its paths stay with BSDF sampling */
        caustic = CAUSTIC_REFLECTED;
    }
    /* --- BSDF sampling --- */
    beta *= fs_random_normal_sample(rn, mat, law, albedo, n, wo, ub.xy, &wi, &pdf_bsdf, &p_n0);
    if (!(max3(beta) > 0.0f)) return;   /* e.g. reflected below the surface */

    /* --- Russian roulette --- */
    depth += 1;
    if (depth >= params->rr_start_depth) {
        float q = fmin(max3(beta), params->rr_max_survival);
        float u = rng4(params->seed, pixel, sample, bounce, DIM_ROULETTE).x;
        if (u >= q) return;
        beta /= q;
    }
    path_beta[p] = (float4)(beta, 0.0f);
    path_depth[p] = depth;
    path_prev_pos[p] = (float4)(x, pdf_bsdf);
    path_prev_env_nee[p] = env_nee;
    path_caustic[p] = caustic;
    path_prev_n[p] = (float4)(n, p_n0);
    path_prev_v[p] = (float4)(-wo, mat->roughness);
    int k = atomic_inc(&counters[COUNT_RAYS_OUT]);
    out_o[k] = (float4)(xo, 0.0f);
    out_d[k] = (float4)(wi, T_INFINITY);
    out_path[k] = p;
}
