/* From: ray queue `in` with surface (and weight-space) hits.  To: hits moved to the
 * first zero crossing sampled along the ray inside a function-space GPIS proxy, with the
 * sampled normal (hit_prim = GPIS_HIT_BASE - k) and the law it was drawn from; the path's vertex record (FsVertex, and
 * for the global model its ring of observations) becomes that hit, or "none" when the
 * ray's final hit is anything else.
 *
 * Memory lives only between consecutive GPIS vertices of one object: any other event (a
 * surface, a null surface, another object's hit, leaving the proxy) resets it, so a ray
 * that does not start at this path's last vertex of object k meets k with the fresh
 * start condition. Every ray of a path at wavefront iteration b leaves from the event of
 * iteration b - 1, which is why one record per path suffices (camera rays: b = 0).
 *
 * Scratch: two slices per work item, so that the winning object's rows survive while
 * later objects on the same ray are sampled (the global model copies them into the
 * ring). The host launches a fixed number of work items that stride over the rays
 * [0, num_rays), so the scratch is sized to the items launched, not to the batch; random
 * numbers are keyed by pixel, sample, bounce and dimension, never by the item (rng.h). */
__kernel void gpis_function_space(GPIS_FUNCTION_SPACE_PARAMS)
{
    int item = get_global_id(0);
    GpisTables T = GPIS_TABLES;
    for (int i = item; i < num_rays; i += get_global_size(0)) {
        float4 o = in_o[i], d = in_d[i];
        int p = in_path[i];
        int vk = params->bounce == 0 ? -1 : vertex_object[p];
        FsVertex none = {0}, prev = vertex[p];
        __global FsObs* ring = rings + (size_t)p * ring_stride;
        float t_hit = in_hit_t[i];
        int best = -1, slot = 0;
        FsResult best_res;
        FsRay best_ray;
        FsParams best_prm;
        for (int k = 0; k < params->num_gpis; ++k) {
            FsRay r;
            FsParams prm;
            FsResult res = fs_object_flight(params, gpis, k, kernels, mean_nodes, T, o, d, t_hit,
                                            path_pixel[p], path_sample[p], 0u,
                                            vk == k ? prev : none, ring,
                                            fs_scratch(scratch, 2 * item + slot), counters, &r,
                                            &prm);
            if (res.hit && (float)res.t < t_hit) {
                t_hit = (float)res.t;
                best = k;
                best_res = res;
                best_ray = r;
                best_prm = prm;
                slot ^= 1;
            }
        }
        if (best < 0) {
            vertex_object[p] = -1;
            continue;
        }
        in_hit_t[i] = t_hit;
        in_hit_prim[i] = GPIS_HIT_BASE - best;
        in_hit_n[i] = (float4)(convert_float3(normalize(best_res.grad)), 0.0f);
        /* the normal's law, for next-event estimation and MIS (fs_normal_pdf.h) */
        in_hit_law_m[i] = (float4)(convert_float3(best_res.law_m), (float)best_res.law_s);
        in_hit_law_a[i] = (float4)(convert_float3(best_res.law_a), 0.0f);
        in_hit_law_b[i] = (float4)(convert_float3(best_res.law_b), 0.0f);
        vertex[p] = fs_vertex_at_hit(best_prm, best_ray, best_res, vk == best ? prev : none,
                                     ring, fs_scratch(scratch, 2 * item + (slot ^ 1)));
        vertex_object[p] = best;
    }
}
