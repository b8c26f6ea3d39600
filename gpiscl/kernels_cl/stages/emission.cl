/* From: hit queue.  To: radiance emitted by area lights that rays hit, weighted by MIS
 * against light sampling from the previous vertex (path_prev_pos.w: the BSDF sample's
 * density, 0 for a delta; a function-space mirror has one, fs_random_normal.h), or 0 where
 * the manifold NEE counted the path (CAUSTIC_REFLECTED, lib/caustics.h), and by GPIS
 * emission fields where rays meet a realization (never light-sampled, so with weight 1). */
__kernel void emission(EMISSION_PARAMS)
{
    int i = get_global_id(0);
    if (i >= counters[COUNT_HITS]) return;
    int r = hits_ray[i];
    int hp = in_hit_prim[r];
    if (hp < 0) {
        /* GPIS event: next-event estimation cannot sample an emission field (it is not a
         * light), so this BSDF-sampled hit is its only estimator: MIS weight 1 */
        int f = gpis[GPIS_HIT_BASE - hp].emission_field;
        if (f <= 0) return;
        int p = in_path[r];
        float3 x = in_o[r].xyz + in_hit_t[r] * in_d[r].xyz;
        float3 Le = gpis_field_eval(field_nodes, f, x, 0.0f);
        path_radiance[p] += (float4)(path_beta[p].xyz * Le, 0.0f);
        return;
    }
    __global const Primitive* prim = &prims[in_hit_prim[r]];
    if (prim->light < 0) return;
    int p = in_path[r];
    /* a path reflected to here by a mirror sphere from a vertex whose manifold NEE
     * sampled exactly these paths (lib/caustics.h): counted there */
    if (path_caustic[p] == CAUSTIC_REFLECTED) return;
    float3 o = in_o[r].xyz, d = in_d[r].xyz;
    float3 x = o + in_hit_t[r] * d;
    float4 prev = path_prev_pos[p];
    float pdf_light;
    float3 Le = light_area_radiance(lights[prim->light].kind, &lights[prim->light], prev.xyz,
                                    x, primitive_normal(prim, x), d, &pdf_light);
    /* the light strategy's density includes choosing this light (its pmf in the table
     * of the previous vertex, lights.h light_choice_at); after a
     * random-normal pairs vertex (fs_random_normal.h) it is that of its (normal, light)
     * pairs (fs_normal_pdf.h) */
    float sel = light_choice_at(light_choice, params->num_lights,
                                path_prev_env_nee[p])[prim->light].pmf;
    float w = (prev.w > 0.0f && params->nee)
                  ? power_heuristic(prev.w, fs_conductor_light_pdf(
                        pdf_light * sel, path_prev_n[p], path_prev_v[p], d))
                  : 1.0f;
    path_radiance[p] += (float4)(w * path_beta[p].xyz * Le, 0.0f);
}
