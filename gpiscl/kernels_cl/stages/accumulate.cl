/* From: the finished paths of a batch.  To: the film. One work-item per pixel adds its
 * paths in sample order, in double, so the image does not depend on batch size.
 * Non-finite path radiance is counted (COUNT_NAN_PATHS) and recorded as zero. */
__kernel void accumulate(ACCUMULATE_PARAMS)
{
    int pixel = get_global_id(0);
    if (pixel >= params->num_pixels) return;
    /* paths of this pixel in the batch: ids path_base + i with id % num_pixels == pixel */
    int first = pixel - params->path_base % params->num_pixels;
    if (first < 0) first += params->num_pixels;
    for (int i = first; i < params->num_paths; i += params->num_pixels) {
        float3 L = path_radiance[i].xyz;
        if (!is_finite3(L)) {
            atomic_inc(&counters[COUNT_NAN_PATHS]);
            L = (float3)(0.0f);
        }
        double3 Ld = convert_double3(L);
        double3 s = vload3(pixel, film_sum) + Ld;
        double3 q = vload3(pixel, film_sum_sq) + Ld * Ld;
        vstore3(s, pixel, film_sum);
        vstore3(q, pixel, film_sum_sq);
        film_count[pixel] += 1.0;
        if (params->aov) {   /* 12 doubles a pixel: the three float4s of aov.py */
            __global double* f = film_aov + 12 * (size_t)pixel;
            vstore4(vload4(0, f) + convert_double4(path_aov_position[i]), 0, f);
            vstore4(vload4(1, f) + convert_double4(path_aov_normal[i]), 1, f);
            vstore4(vload4(2, f) + convert_double4(path_aov_albedo[i]), 2, f);
        }
    }
}
