/* From: a batch of path ids.  To: one camera ray per path in ray queue `out`,
 * fresh path state. Path id i of the batch is (sample, pixel) = divmod(path_base + i,
 * num_pixels) offset by sample_base. */
__kernel void generate_camera_rays(GENERATE_CAMERA_RAYS_PARAMS)
{
    int i = get_global_id(0);
    if (i >= params->num_paths) return;
    int id = params->path_base + i;
    int pixel = id % params->num_pixels;
    int sample = params->sample_base + id / params->num_pixels;
    float4 u = rng4(params->seed, pixel, sample, 0, DIM_CAMERA);
    float px = (pixel % camera->width) + u.x;
    float py = (pixel / camera->width) + u.y;
    float sx = 2.0f * px / camera->width - 1.0f;
    float sy = 1.0f - 2.0f * py / camera->height;
    float3 d = normalize(camera->forward.xyz + sx * camera->right.xyz + sy * camera->up.xyz);

    path_pixel[i] = pixel;
    path_sample[i] = sample;
    path_beta[i] = (float4)(1.0f, 1.0f, 1.0f, 0.0f);
    path_radiance[i] = (float4)(0.0f);
    path_prev_pos[i] = (float4)(camera->position.xyz, 0.0f);  /* pdf 0: seen directly */
    path_depth[i] = 0;
    path_caustic[i] = CAUSTIC_NONE;
    path_medium[i] = -1;
    if (params->aov) {   /* without AOVs these fields hold one element (integrator.py) */
        path_aov_position[i] = (float4)(0.0f);   /* no hit yet: adds nothing to the film */
        path_aov_normal[i] = (float4)(0.0f);
        path_aov_albedo[i] = (float4)(0.0f);
    }
    out_o[i] = (float4)(camera->position.xyz, 0.0f);
    out_d[i] = (float4)(d, T_INFINITY);
    out_path[i] = i;
}
