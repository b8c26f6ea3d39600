/* From: hit queue.  To: for each surface hit, a shadow ray towards a sampled light
 * (next-event estimation, MIS-weighted) and a continuation ray in ray queue `out`.
 * Null (pass-through) surfaces forward the ray unchanged and switch the medium. */
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
        albedo = mat->albedo.xyz * gpis_field_eval(mean_nodes, g->color_field, x, 1.0f);
        ng = in_hit_n[r].xyz;
        eps = 0.0f;
        if (!(dot(ng, wo) < 0.0f)) {  /* a crossing's gradient must face the ray */
            atomic_inc(&counters[COUNT_KILLED]);
            return;
        }
    }

    if (mat->kind == MATERIAL_NULL) {
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
    /* a function-space GPIS hit knows the law its normal was drawn from, so a mirror
     * there is not a delta BSDF: its direction density is the normal's through the half
     * vector (fs_normal_pdf.h), and it gets next-event estimation and MIS. Weight space
     * has no such density (the realization fixes the normal): its mirror stays delta,
     * and so does a function-space hit whose sampler reports no law (law_s = 0: a free
     * flight that does not fill FsResult.law_*). */
    int fs_hit = hp < 0 && gpis[GPIS_HIT_BASE - hp].sampler == GPIS_SAMPLER_FUNCTION_SPACE
                 && params->fs_nee && in_hit_law_m[r].w < 0.0f;
    int fs_mirror = fs_hit && mat->kind == MATERIAL_MIRROR;
    /* a rough conductor there samples pairs (normal, light) with MIS (fs_normal_pdf.h) */
    int fs_conductor = fs_hit && mat->kind == MATERIAL_ROUGH_CONDUCTOR;
    float p_n0 = 0.0f;   /* fs_conductor: p_Omega of the sampled normal */
    FsNormalLaw law = fs_normal_law(in_hit_law_m[r], in_hit_law_a[r], in_hit_law_b[r]);
    if (mat->kind == MATERIAL_DIFFUSE || mat->kind == MATERIAL_ROUGH_CONDUCTOR || fs_mirror) {
        /* --- next-event estimation --- */
        if (params->nee && params->num_lights > 0) {
            float4 ul = rng4(params->seed, pixel, sample, bounce, DIM_LIGHT);
            int li = min((int)(ul.x * params->num_lights), params->num_lights - 1);
            EnvMap m = {env_texels, env_marginal, env_conditional, params->env_width,
                        params->env_height};
            float3 wl;
            float dist, pdf_light;
            float3 Le = sample_light(&lights[li], m, xo, ul.yz, &wl, &dist, &pdf_light);
            /* a function-space mirror samples only lights of small extent, where BSDF
             * sampling is poor: environments stay with BSDF sampling (escaped_rays.cl
             * gives them weight 1 after such a vertex), which keeps the mirror's white
             * furnace exactly 1 per path */
            if (fs_mirror && (lights[li].kind == LIGHT_ENVIRONMENT
                              || lights[li].kind == LIGHT_ENVIRONMENT_MAP))
                Le = (float3)(0.0f);
            float pdf_f;
            float3 f;
            float4 grad = (float4)(0.0f);   /* the shadow ray keeps the vertex's normal */
            if (fs_mirror) {
                /* the light sample picks the normal: the half vector h, whose gradient
                 * the shadow ray conditions on */
                float3 h;
                pdf_f = fs_mirror_pdf(law, wo, wl, &h);
                f = albedo * pdf_f;
                if (pdf_f > 0.0f) grad = (float4)(fs_implied_gradient(law, wo, h), 1.0f);
            } else {
                f = bsdf_eval(mat, albedo, n, -wo, wl, &pdf_f);
            }
            /* the light strategy's density includes choosing light li (1 / num_lights),
             * as the BSDF strategy's weight in emission.cl and escaped_rays.cl does:
             * the two weights of one direction must sum to 1 */
            float w = (pdf_light > 0.0f)
                          ? power_heuristic(pdf_light / params->num_lights, pdf_f) : 1.0f;
            float inv_pdf = (pdf_light > 0.0f) ? 1.0f / pdf_light : 1.0f;
            if (fs_conductor && pdf_light > 0.0f) {
                /* strategy A (the sampled normal) or B (a normal about the half
                 * vector), each with probability 1/2; all densities relative to the
                 * light's pdf_L, i.e. p_AB / p_L = (p_Omega(nn) + q(nn | l)) / 2 */
                float3 v = -wo, h = normalize(v + wl), nn = n;
                if (ul.w >= 0.5f) {
                    nn = fs_lobe_normal_sample(h, mat->roughness,
                                               rng4(params->seed, pixel, sample, bounce,
                                                    DIM_BSDF).zw);
                    if (dot(nn, wo) < 0.0f)
                        grad = (float4)(fs_implied_gradient(law, wo, nn), 1.0f);
                }
                float p_nn = fs_normal_pdf(law, wo, nn);
                f = rough_conductor_eval(albedo, mat->eta.xyz, mat->k.xyz, mat->roughness, nn,
                                         v, wl, &pdf_f);
                float p_ab = 0.5f * (p_nn + fs_lobe_normal_pdf(nn, h, mat->roughness));
                /* F / p_AB w_AB with F = p_Omega(nn) fcos Le: w_AB from p_AB against
                 * p_C = p_Omega(nn) p_c(l | nn), both in units of pdf_L */
                float pl = pdf_light / params->num_lights;
                w = (p_ab > 0.0f) ? power_heuristic(pl * p_ab, p_nn * pdf_f) : 0.0f;
                f *= (p_ab > 0.0f) ? p_nn / p_ab : 0.0f;
            }
            float3 c = beta * f * Le * (w * inv_pdf * params->num_lights);
            if (max3(c) > 0.0f) {
                int k = atomic_inc(&counters[COUNT_SHADOW]);
                shadow_o[k] = (float4)(xo, 0.0f);
                shadow_d[k] = (float4)(wl, dist);
                shadow_contribution[k] = (float4)(c, 0.0f);
                shadow_path[k] = p;
                shadow_grad[k] = grad;
            }
        }
        /* --- BSDF sampling --- */
        float4 ub = rng4(params->seed, pixel, sample, bounce, DIM_BSDF);
        if (mat->kind == MATERIAL_DIFFUSE) {   /* cosine-weighted: f cos / pdf = albedo */
            wi = cosine_hemisphere(ub.xy, n, &pdf_bsdf);
            beta *= albedo;
        } else if (fs_mirror) {
            /* the reflection about the sampled normal: weight albedo, and its density
             * for MIS (FLT_MIN where it underflows: there light sampling takes it all) */
            float3 h;
            wi = wo - 2.0f * dot(wo, n) * n;
            pdf_bsdf = fmax(fs_mirror_pdf(law, wo, wi, &h), FLT_MIN);
            beta *= albedo;
        } else {
            beta *= rough_conductor_sample(albedo, mat->eta.xyz, mat->k.xyz, mat->roughness,
                                           n, -wo, ub.xy, &wi, &pdf_bsdf);
            if (!(max3(beta) > 0.0f)) return;   /* reflected below the surface */
            /* C's MIS weight at a light needs p_Omega(n0) (fs_conductor_light_pdf) */
            if (fs_conductor) p_n0 = fmax(fs_normal_pdf(law, wo, n), FLT_MIN);
        }
    } else {
        wi = wo - 2.0f * dot(wo, n) * n;
        pdf_bsdf = 0.0f;
        beta *= albedo;
    }

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
    path_prev_env_nee[p] = !fs_mirror;
    path_prev_n[p] = (float4)(n, p_n0);
    path_prev_v[p] = (float4)(-wo, mat->roughness);
    int k = atomic_inc(&counters[COUNT_RAYS_OUT]);
    out_o[k] = (float4)(xo, 0.0f);
    out_d[k] = (float4)(wi, T_INFINITY);
    out_path[k] = p;
}
