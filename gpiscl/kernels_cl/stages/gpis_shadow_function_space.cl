/* From: shadow queue.  To: contributions zeroed where a free flight through a
 * function-space GPIS object, sampled under the object's memory model, crosses zero
 * between the vertex and the light.
 *
 * Shadow rays read the path's vertex record and ring and never write them: the
 * continuation ray from the same vertex (next iteration) is conditioned on exactly what
 * it would have been without NEE. A light sample that picked the vertex's normal itself
 * (a mirror at a function-space hit, fs_normal_pdf.h) conditions its shadow ray on the
 * gradient that normal implies: a private copy of the record carries it (grad, and
 * `implied` for the global model's ring rows, fs_begin).
 *
 * Why a 0/1 sample is unbiased: the NEE term of a vertex is E[c V], where c is the
 * light sample's contribution (fixed by the path prefix) and V the indicator that the
 * surface does not cross the segment. Under the memory model the law of the field along
 * that segment, given the path prefix, is the conditional law defined by the vertex
 * record; we draw V exactly from it (fresh random stream 1, independent of the
 * continuation's stream 0), so E[V | prefix] = T(prefix), the model's transmittance.
 * The pixel estimate is a sum of such terms, each linear in one V, so the correlation
 * that one shared realization would put between a shadow ray and the later path (weight
 * space has it, we do not) cannot change any expectation. Crossings are found by the
 * same adaptive march as free flight (fs_march.h), so the visibility agrees in law with
 * what a continuation ray along the same segment would see.
 *
 * A fixed number of work items stride over the shadow rays (one scratch slice each). */
__kernel void gpis_shadow_function_space(GPIS_SHADOW_FUNCTION_SPACE_PARAMS)
{
    int item = get_global_id(0), end = min(num_rays, counters[COUNT_SHADOW]);
    FsScratch S = fs_scratch(scratch, item);
    GpisTables T = GPIS_TABLES;
    for (int i = item; i < end; i += get_global_size(0)) {
        if (max3(shadow_contribution[i].xyz) <= 0.0f) continue;   /* blocked already */
        float4 o = shadow_o[i], d = shadow_d[i];
        int p = shadow_path[i];
        /* a pair's tail leaves a mirror sphere, where the path's record is none */
        int vk = (shadow_contribution[i].w == SHADOW_TAIL) ? -1 : vertex_object[p];
        FsVertex none = {0}, prev = vertex[p];
        float4 g = shadow_grad[i];
        if (g.w > 0.0f) {   /* a light sample that chose its own normal (fs_normal_pdf.h) */
            prev.grad = (float4)(g.xyz, 0.0f);
            prev.implied = 1;
        }
        __global const FsObs* ring = rings + (size_t)p * ring_stride;
        for (int k = 0; k < params->num_gpis; ++k) {
            FsRay r;
            FsParams prm;
            if (fs_object_flight(params, gpis, k, kernels, mean_nodes, T, o, d, d.w,
                                 path_pixel[p], path_sample[p], 1u, vk == k ? prev : none,
                                 ring, S, counters, &r, &prm).hit) {
                shadow_contribution[i] = (float4)(0.0f);
                break;
            }
        }
    }
}
