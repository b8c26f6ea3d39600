/* From: escaped queue.  To: radiance of the lights at infinity added to each path,
 * weighted by MIS against light sampling. The path ends here. */
__kernel void escaped_rays(ESCAPED_RAYS_PARAMS)
{
    int i = get_global_id(0);
    if (i >= counters[COUNT_ESCAPED]) return;
    int r = escaped_ray[i];
    int p = in_path[r];
    EnvMap m = {env_texels, env_marginal, env_conditional, params->env_width,
                params->env_height};
    float3 d = in_d[r].xyz;
    float pdf_bsdf = path_prev_pos[p].w;
    float3 L = (float3)(0.0f);
    for (int k = 0; k < params->num_lights; ++k) {
        float pdf_light;
        float3 Le = light_radiance(lights[k].kind, &lights[k], m, d, &pdf_light);
        /* the density the previous vertex's NEE gave d (ENV_NEE_*, lights.h): a vertex
         * may leave environments to BSDF sampling, or sample a constant one by the cosine
         * hemisphere about its normal; times the light's choice probability. After a
         * random-normal pairs vertex the light strategy samples pairs (normal, light)
         * (fs_normal_pdf.h) */
        int env_nee = path_prev_env_nee[p];
        if (env_nee == ENV_NEE_ABOVE && lights[k].kind == LIGHT_ENVIRONMENT)
            pdf_light = environment_pdf_above(path_prev_n[p].xyz, d);
        int env = LIGHT_IS_ENVIRONMENT(lights[k].kind);
        float w = (pdf_bsdf > 0.0f && params->nee && (env_nee != ENV_NEE_NONE || !env))
                      ? power_heuristic(pdf_bsdf, fs_conductor_light_pdf(
                            pdf_light * light_choice_at(light_choice, params->num_lights,
                                                        env_nee)[k].pmf, path_prev_n[p],
                            path_prev_v[p], d))
                      : 1.0f;
        L += w * Le;
    }
    path_radiance[p] += (float4)(path_beta[p].xyz * L, 0.0f);
}
